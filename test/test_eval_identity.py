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


"""Identity metrics on hand-built sequences: IDF1/IDP/IDR, switches per minute, fragments."""

import json

from mv3dpose_ros import cli
from mv3dpose_ros.eval.identity import (duplicate_rate, frame_period, identity_summary,
                                        sequence_duration)
from mv3dpose_ros.eval.mot import evaluate_mot, MOTEvaluator
from mv3dpose_ros.eval.sequence import evaluate_run, load_ground_truth, read_hypotheses
from mv3dpose_ros.io.tracks_jsonl import poses_to_line
import numpy as np
import pytest

NONE = np.zeros((0, 2, 3))


def _person(x: float) -> np.ndarray:
    return np.array([[x, 0.0, 1.0], [x, 0.0, 0.5]])


G1, G2 = _person(0), _person(3)
BOTH = np.stack([G1, G2])


def test_idf1_is_the_global_optimum_not_the_greedy_mapping():
    # GT 1 is followed by hyp 10 in frames 0-3, then by hyp 20 in frames 4-6; GT 2 is missed in
    # frames 0-3, then followed by hyp 10. Pair counts: (1,10)=4, (1,20)=3, (2,10)=3, (2,20)=0.
    # Greedy takes (1,10) first and ends at IDTP 4; the optimum (1,20)+(2,10) gives IDTP 6.
    frames = [([1, 2], BOTH, [10], G1[None])] * 4 + [([1, 2], BOTH, [20, 10], BOTH)] * 3
    r = evaluate_mot(frames)
    assert r.num_objects == 14                       # GT detections; hypotheses: 7 + 3 = 10
    assert r.idf1 == pytest.approx(2 * 6 / (14 + 10))
    assert r.idp == pytest.approx(6 / 10)
    assert r.idr == pytest.approx(6 / 14)
    assert r.id_switches == 1                        # GT 1: 10 -> 20; GT 2 had no id before
    assert r.fragmentations == 0                     # GT 2 missed only before its first match


def test_id_switches_per_minute_from_stamps_or_fps():
    frames = [([1], G1[None], [10], G1[None])] * 3 + [([1], G1[None], [20], G1[None])] * 4
    # stamps with a gap (two evaluated stretches): the median step, 0.5 s, is the period
    stamps = [0.0, 0.5, 1.0, 10.0, 10.5, 11.0, 11.5]
    r = evaluate_mot([f + (t,) for f, t in zip(frames, stamps)])
    assert r.id_switches == 1 and r.duration_s == pytest.approx(3.5)
    assert r.id_switches_per_min == pytest.approx(60 / 3.5)
    r = evaluate_mot(frames, fps=30)                 # 7 frames at 30 Hz, no stamps needed
    assert r.id_switches_per_min == pytest.approx(60 * 30 / 7)
    r = evaluate_mot(frames)
    assert np.isnan(r.id_switches_per_min) and r.as_dict()['id_switches_per_min'] is None
    assert frame_period([3.0, 1.0, 2.0, 2.0, None, float('nan')]) == 1.0
    assert np.isnan(frame_period([1.0]))
    assert sequence_duration([0.0, 0.5, 1.0, 9.0], 4) == 2.0 and sequence_duration([], 6, 2.0) == 3
    assert np.isnan(sequence_duration([0.0, 0.5], 0))
    with pytest.raises(ValueError):
        MOTEvaluator(fps=0)


def test_fragmentations_count_tracked_untracked_tracked():
    # GT 1: tracked 0-1, lost 2, tracked 3, lost 4-5, tracked 6, lost 7 (never back): 2
    # GT 2: tracked by 20 in 0-2, by 30 from 3 on: a switch without a gap, no fragmentation
    tracked1 = [True, True, False, True, False, False, True, False]
    frames = []
    for k, t1 in enumerate(tracked1):
        ids, poses = ([10], [G1]) if t1 else ([], [])
        ids, poses = ids + [20 if k < 3 else 30], poses + [G2]
        frames.append(([1, 2], BOTH, ids, np.stack(poses)))
    r = evaluate_mot(frames)
    assert r.fragmentations == 2
    assert r.id_switches == 1
    assert r.misses == 4


def test_duplicates_against_ground_truth():
    near = np.stack([G1 + [0.1, 0, 0], G1 - [0.1, 0, 0], G2])
    far = np.stack([G1, G1 + [0.6, 0, 0], G2])          # second one beyond the 0.5 m threshold
    r = evaluate_mot([([1, 2], BOTH, [10, 11, 20], near), ([1, 2], BOTH, [10, 11, 20], far),
                      ([1, 2], BOTH, [10, 20], BOTH)])
    assert r.duplicates == 1
    assert r.duplicate_rate == pytest.approx(1 / 6)
    assert 'duplicates 1' in r.summary() and 'IDP' in r.summary()
    assert evaluate_mot([([1], G1[None], [], NONE)]).duplicates == 0


def test_duplicate_rate_without_ground_truth():
    frames = [
        (0.0, [(1, G1), (2, G1 + [0.2, 0, 0]), (3, G2)]),      # 1 and 2 are one person twice
        (0.1, [(1, G1), (3, G2)]),
        (0.2, []),
    ]
    assert duplicate_rate(frames) == pytest.approx(2 / 5)
    assert duplicate_rate(frames, radius_m=0.1) == 0.0
    assert np.isnan(duplicate_rate([(0.0, [])]))
    # roots [3] work too
    assert duplicate_rate([(0.0, [(1, np.zeros(3)), (2, [0.25, 0, 0])])]) == 1.0
    # 'root' compares centroids: the same joints in another order are far joint by joint
    a = np.array([[0.0, 0, 0], [0, 0, 1.0]])
    assert duplicate_rate([(0.0, [(1, a), (2, a[::-1])])]) == 0.0
    assert duplicate_rate([(0.0, [(1, a), (2, a[::-1])])], distance='root') == 1.0
    with pytest.raises(ValueError):
        duplicate_rate([(0.0, [(1, a), (2, np.zeros(3))])])
    with pytest.raises(ValueError):
        duplicate_rate(frames, distance='iou')


def test_identity_summary_on_a_hand_built_live_run():
    # 10 Hz for 3 s, 2 people (roots). Person A: id 1, absent in messages 25 and 27.
    # Person B: id 2 in 0-19 but absent 10-11, then id 3 from message 20 (2.0 s: late).
    # Message 5 also has id 4 next to A: over count and a duplicate pair.
    a, b = np.zeros(3), np.array([3.0, 0, 0])
    frames = []
    for k in range(30):
        sk = [] if k in (25, 27) else [(1, a)]
        if k < 20 and k not in (10, 11):
            sk.append((2, b))
        elif k >= 20:
            sk.append((3, b))
        if k == 5:
            sk.append((4, a + [0.1, 0, 0]))
        frames.append((0.1 * k, sk))
    s = identity_summary(iter(frames), people=2)
    assert s.messages == 30 and s.skeletons == 28 + 18 + 10 + 1
    assert s.distinct_ids == 4 and s.top_ids == [1, 2]
    assert s.top_share == pytest.approx((28 + 18) / 57)
    assert s.returns == 3 and s.returning_ids == 2       # id 1 twice, id 2 once
    assert s.late_ids == 1                               # id 3; id 4 came at 0.5 s
    assert s.duration_s == pytest.approx(3.0)
    assert s.late_ids_per_min == pytest.approx(20.0)
    assert s.over_count_messages == 1 and s.over_count_rate == pytest.approx(1 / 30)
    assert s.duplicates == 2 and s.duplicate_rate == pytest.approx(2 / 57)
    assert s.duplicate_rate == pytest.approx(duplicate_rate(frames))
    assert 'identity without GT (2 people): 4 ids' in s.summary()
    json.dumps(s.as_dict(), allow_nan=False)
    # a perfect run
    # a perfect run in two stretches 10 s apart: the gap is no time and no return
    ok = identity_summary([(0.1 * k + 10 * (k >= 10), [(7, a), (8, b)]) for k in range(20)],
                          people=2)
    assert (ok.distinct_ids, ok.top_share, ok.returns, ok.late_ids, ok.over_count_messages,
            ok.duplicates) == (2, 1.0, 0, 0, 0, 0)
    assert ok.duration_s == pytest.approx(2.0)
    empty = identity_summary([], people=2)
    assert empty.messages == 0 and np.isnan(empty.top_share)
    json.dumps(empty.as_dict(), allow_nan=False)
    with pytest.raises(ValueError):
        identity_summary(frames, people=-1)
    with pytest.raises(ValueError):
        identity_summary([(float('nan'), [])], people=1)


def _write(path, frames, stamped=True):
    with open(path, 'w') as f:
        for frame, (ids, poses) in frames.items():
            f.write(poses_to_line(frame, ids, poses, 'coco17',
                                  frame / 30 if stamped else None) + '\n')


def test_eval_command_prints_and_writes_the_identity_figures(tmp_path, capsys):
    rng = np.random.default_rng(3)
    body = rng.normal(scale=0.2, size=(17, 3)) + [0, 0, 1.0]
    pa, pb = body, body + [3.0, 0, 0]
    gt, hyp = {}, {}
    for f in range(60):                       # 2 s at 30 Hz
        gt[f] = ([0, 1], np.stack([pa, pb]))
        ids, poses = [1], [pa]
        if not 40 <= f < 45:                  # B lost for 5 frames: a fragmentation
            ids.append(2 if f < 36 else 3)    # B switches 2 -> 3 at 1.2 s: a late id
            poses.append(pb)
        if 10 <= f < 15:                      # a second skeleton on A: duplicates
            ids.append(9)
            poses.append(pa + [0.05, 0, 0])
        hyp[f] = (ids, np.stack(poses))
    _write(tmp_path / 'gt.jsonl', gt)
    _write(tmp_path / 'hyp.jsonl', hyp)
    js = str(tmp_path / 'f.json')
    args = ['eval', '--tracks', str(tmp_path / 'hyp.jsonl'), '--gt', str(tmp_path / 'gt.jsonl'),
            '--format', 'tracks', '--json', js]
    assert cli.main(args) == 0
    text = capsys.readouterr().out
    assert 'IDP 80.0  IDR 80.0  fragmentations 1  duplicates 5' in text
    assert '(30.00/min)' in text and 'identity without GT (2 people): 4 ids' in text
    fig = json.load(open(js))
    mot, ident = fig['mot'], fig['identity']
    # stamps are stored to the microsecond: 1/30 s is 0.033333 s
    assert mot['id_switches'] == 1
    assert mot['id_switches_per_min'] == pytest.approx(30.0, rel=1e-4)
    assert mot['idf1'] == pytest.approx(0.8) and mot['fragmentations'] == 1
    assert mot['duplicates'] == 5 and mot['duplicate_rate'] == pytest.approx(5 / 120)
    assert mot['mota'] == pytest.approx(1 - 11 / 120)
    assert ident['distinct_ids'] == 4 and ident['top_share'] == pytest.approx(96 / 120)
    assert ident['returns'] == 1 and ident['late_ids'] == 1
    assert ident['over_count_messages'] == 5 and ident['duplicates'] == 10
    # --fps wins over the stamps: 60 frames at 15 Hz are 4 s
    assert cli.main(args + ['--fps', '15']) == 0
    assert json.load(open(js))['mot']['id_switches_per_min'] == pytest.approx(15.0)
    assert cli.main(args + ['--fps', 'nan']) == 2
    # without stamps nor fps: no per-minute figure and no identity summary, with a note
    _write(tmp_path / 'bare.jsonl', hyp, stamped=False)
    layout, frames = read_hypotheses(str(tmp_path / 'bare.jsonl'))
    rep = evaluate_run(layout, frames, load_ground_truth(str(tmp_path / 'gt.jsonl'), 'tracks'))
    assert rep.identity is None and any('no stamp' in n for n in rep.notes)
    assert rep.as_dict()['mot']['id_switches_per_min'] is None
    assert rep.mot.id_switches == 1
