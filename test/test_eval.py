# Copyright 2026 The mv3dpose_ros Authors
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.


"""Metrics on hand-computed cases: PCP3D, MPJPE with matching, CLEAR MOT / IDF1."""

from mv3dpose_ros.eval.mot import evaluate_mot, MOTEvaluator
from mv3dpose_ros.eval.mpjpe import match_poses, mpjpe, pose_distances
from mv3dpose_ros.eval.pcp import evaluate_pcp, pcp_correct
import numpy as np
import pytest


def shelf_pose(x0: float = 0.0, y0: float = 0.0) -> np.ndarray:
    """Return a standing shelf14 person at (x0, y0) with simple round part lengths (m)."""
    p = np.array([
        [-0.1, 0, 0.0], [-0.1, 0, 0.5], [-0.1, 0, 1.0],     # R ankle, knee, hip
        [0.1, 0, 1.0], [0.1, 0, 0.5], [0.1, 0, 0.0],        # L hip, knee, ankle
        [-0.2, 0, 0.9], [-0.2, 0, 1.2], [-0.2, 0, 1.5],     # R wrist, elbow, shoulder
        [0.2, 0, 1.5], [0.2, 0, 1.2], [0.2, 0, 0.9],        # L shoulder, elbow, wrist
        [0.0, 0, 1.6], [0.0, 0, 1.8],                       # neck (bottom head), top head
    ])
    return p + np.array([x0, y0, 0.0])


def test_pcp_part_rule_is_mean_of_endpoint_errors_against_half_length():
    gt = shelf_pose()
    pred = gt.copy()
    # right lower leg (ankle-knee, length 0.5): endpoint errors 0.25 and 0.25, mean = 0.5 * 0.5
    pred[0, 2] += 0.25
    pred[1, 1] += 0.25
    ok = pcp_correct(pred, gt)
    assert ok[0]                          # exactly at the limit counts as correct
    assert ok[1]                          # right upper leg: (0.25 + 0) / 2 <= 0.25
    assert ok.sum() == 10
    assert not pcp_correct(pred, gt, alpha=0.49)[0]


def test_pcp_hand_computed_parts():
    gt = shelf_pose()
    pred = gt.copy()
    pred[0, 0] += 0.31                    # lower leg: (0.31 + 0) / 2 = 0.155 <= 0.25: correct
    assert pcp_correct(pred, gt)[0]
    pred[1, 1] += 0.2                     # lower leg: (0.31 + 0.2) / 2 = 0.255 > 0.25: wrong
    ok = pcp_correct(pred, gt)
    assert not ok[0]
    assert ok[1]                          # upper leg: (0.2 + 0) / 2 = 0.1 <= 0.25
    # head: length 0.2 -> limit 0.1; top head off by 0.25 -> mean 0.125: wrong
    pred = gt.copy()
    pred[13, 2] += 0.25
    ok = pcp_correct(pred, gt)
    assert not ok[8] and ok[9]
    # torso uses the hip midpoint: both hips shifted +0.3 in y, their midpoint moves 0.3,
    # torso length 0.6 -> limit 0.3, mean error 0.15: correct; the legs' hip ends move 0.3 too
    pred = gt.copy()
    pred[2:4, 1] += 0.3
    ok = pcp_correct(pred, gt)
    assert ok[9]
    pred[12, 1] += 0.35                   # neck: torso mean (0.3 + 0.35) / 2 = 0.325 > 0.3
    assert not pcp_correct(pred, gt)[9]
    # a missing endpoint makes the part wrong
    pred = gt.copy()
    pred[6] = np.nan
    ok = pcp_correct(pred, gt)
    assert not ok[4] and ok.sum() == 9
    assert pcp_correct(pred, gt, variant='8').shape == (8,)


def test_evaluate_pcp_per_actor_nearest_and_missing():
    a, b = shelf_pose(0, 0), shelf_pose(3, 0)
    bad = a.copy()
    bad[6:8, 0] += 1.0                    # breaks right lower + upper arm of actor 0
    frames = [
        (np.stack([bad, b]), {0: a, 1: b}),   # actor 0: 8/10, actor 1: 10/10
        (np.stack([a]), {0: a, 1: b}),        # actor 1 nearest is a (3 m away): 0/10 correct
        (np.zeros((0, 14, 3)), {0: a}),       # no predictions: actor 0 gets 0/10
    ]
    res = evaluate_pcp(frames)
    assert res.actor_ids == [0, 1]
    np.testing.assert_allclose(res.per_actor, [(8 + 10 + 0) / 30, (10 + 0) / 20])
    assert res.average == pytest.approx(((18 / 30) + 0.5) / 2)
    # recall@0.5m: frame 1 both (bad pose is 0.2 m mean from a), frame 2 actor 0 only
    assert res.recall == pytest.approx(3 / 5)
    np.testing.assert_allclose(res.per_group['Upper arms'], [(1 + 2 + 0) / 6, (2 + 0) / 4])
    assert res.frames == 3
    # 8-limb variant of the first frame: actor 0 6/8
    res8 = evaluate_pcp(frames[:1], variant='8')
    np.testing.assert_allclose(res8.per_actor, [6 / 8, 1.0])
    assert 'Head' not in res8.per_group
    assert 'PCP' in res.table()


def test_evaluate_pcp_hungarian_is_one_to_one():
    a, b = shelf_pose(0, 0), shelf_pose(0.3, 0)
    # one prediction sits on a: 'nearest' gives it to both actors, hungarian to one only
    frames = [(a[None], {0: a, 1: b})]
    near = evaluate_pcp(frames)
    hung = evaluate_pcp(frames, matching='hungarian')
    assert near.per_actor[0] == 1.0 and near.per_actor[1] > 0
    assert hung.per_actor[0] == 1.0 and hung.per_actor[1] == 0.0


def test_pose_distances_and_matching():
    a = np.zeros((2, 3, 3))
    a[1] += [1.0, 0, 0]
    b = np.zeros((3, 3, 3))
    b[0] += [1.1, 0, 0]
    b[1] += [0, 0.2, 0]
    b[2] = np.nan
    d = pose_distances(a, b)
    np.testing.assert_allclose(d[:, :2], [[1.1, 0.2], [0.1, np.hypot(1, 0.2)]])
    assert np.isinf(d[:, 2]).all()
    pi, gi, dist = match_poses(a, b)
    assert sorted(zip(pi, gi)) == [(0, 1), (1, 0)]
    np.testing.assert_allclose(sorted(dist), [0.1, 0.2])
    pi, gi, _ = match_poses(a, b, max_distance_m=0.15)
    assert list(zip(pi, gi)) == [(1, 0)]
    assert pose_distances(np.zeros((0, 3, 3)), b).shape == (0, 3)


def test_mpjpe_matched_partial_joints_and_false_positives():
    gt = np.zeros((2, 2, 3))
    gt[1] += [2.0, 0, 0]
    pred = gt[::-1].copy()                 # order swapped: matching must undo it
    pred[0, 0, 2] += 0.03                  # person 1 (at x=2): joint errors 0.03, 0
    pred[1, 1] = np.nan                    # person 0: joint 1 missing, joint 0 exact
    far = np.full((1, 2, 3), 10.0)         # false positive
    res = mpjpe([(np.concatenate([pred, far]), gt)])
    assert res.matched == 2 and res.total_gt == 2 and res.false_positives == 1
    np.testing.assert_allclose(sorted(res.errors_m), [0.0, 0.015])
    assert res.mpjpe_m == pytest.approx(0.0075)
    np.testing.assert_allclose(res.per_joint_m, [0.015, 0.0])
    assert res.recall == 1.0
    # a person beyond the threshold is a miss, not an error
    res = mpjpe([(gt + [0.6, 0, 0], gt)], max_distance_m=0.5)
    assert res.matched == 0 and np.isnan(res.mpjpe_m) and res.false_positives == 2
    # unmatched mode compares in order
    res = mpjpe([(gt + [0.1, 0, 0], gt)], match=False)
    assert res.mpjpe_m == pytest.approx(0.1)
    with pytest.raises(ValueError):
        mpjpe([(gt[:1], gt)], match=False)


def _person(x: float) -> np.ndarray:
    return np.array([[x, 0.0, 1.0], [x, 0.0, 0.5]])


def test_mot_hand_computed_switch_fp_fn():
    # 4 frames, 2 GT people (ids 1, 2) at x=0 and x=3.
    ev = MOTEvaluator(threshold_m=0.5)
    g = np.stack([_person(0), _person(3)])
    ev.update([1, 2], g, [10, 20], g + 0.1)            # 2 matches
    ev.update([1, 2], g, [10, 20], g + 0.1)            # 2 matches
    ev.update([1, 2], g, [10, 30], g)                  # GT 2 switches 20 -> 30
    ev.update([1, 2], g, [10, 40], np.stack([_person(0), _person(9)]))  # FN for 2, FP 40
    r = ev.result()
    assert r.num_objects == 8 and r.frames == 4
    assert r.id_switches == 1 and r.false_positives == 1 and r.misses == 1
    assert r.mota == pytest.approx(1 - 3 / 8)
    # IDF1: best one-to-one id mapping 1-10 (4 frames), 2-20 (2 frames): IDTP = 6,
    # IDF1 = 2 IDTP / (GT dets + hyp dets) = 12 / (8 + 8)
    assert r.idf1 == pytest.approx(12 / 16)
    assert r.num_matches == 6           # motmetrics counts the switched pair apart
    assert r.motp_m == pytest.approx(4 * np.sqrt(3) * 0.1 / 7)


def test_mot_root_distance_and_threshold():
    g = _person(0)[None]
    h = _person(0)[None].copy()
    h[0, 1] += [0.0, 0.0, 0.8]             # lower joint far off: mean-joint distance 0.4
    r = evaluate_mot([([1], g, [5], h)], threshold_m=0.3)
    assert r.misses == 1 and r.false_positives == 1
    r = evaluate_mot([([1], g, [5], h)], threshold_m=0.3, distance='root', root_joints=[0])
    assert r.misses == 0 and r.mota == 1.0
    # empty frames are fine, hypotheses only are false positives
    r = evaluate_mot([([], np.zeros((0, 2, 3)), [5], h)])
    assert r.false_positives == 1
    with pytest.raises(ValueError):
        MOTEvaluator(distance='iou')
    with pytest.raises(ValueError):
        evaluate_mot([([1, 1], np.stack([g[0], g[0]]), [], np.zeros((0, 2, 3)))])


def test_pcp_skips_parts_without_ground_truth():
    gt = shelf_pose()
    gt[13] = np.nan                        # top of head not annotated: head part not counted
    pred = shelf_pose()
    pred[6, 0] += 1.0                      # right lower arm wrong
    res = evaluate_pcp([(pred[None], {0: gt})])
    assert res.per_actor[0] == pytest.approx(8 / 9)
    assert np.isnan(res.per_group['Head'][0])
    assert res.per_group['Lower arms'][0] == pytest.approx(0.5)
