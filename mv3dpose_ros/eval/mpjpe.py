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

"""
Mean per-joint position error (MPJPE) and the pose distances other metrics share.

Poses are ``[N, J, 3]`` arrays in metres with NaN for missing joints; ground truth and
prediction must be in the same joint layout (convert first with
``mv3dpose_ros.core.skeleton.convert_poses``). A distance between two poses is the mean
Euclidean distance over the joints valid in both; pairs without a shared joint are ``inf``.
"""

from dataclasses import dataclass, field
from typing import Iterable, Optional, Sequence, Tuple

import numpy as np
from scipy.optimize import linear_sum_assignment


def pose_distances(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """
    Return ``[N, M]`` mean joint distances (m) between poses ``a [N,J,3]`` and ``b [M,J,3]``.

    Only joints valid (finite) in both poses count; pairs with none in common get ``inf``.
    """
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    if a.size == 0 or b.size == 0:
        return np.zeros((a.shape[0] if a.ndim == 3 else 0, b.shape[0] if b.ndim == 3 else 0))
    if a.shape[1:] != b.shape[1:]:
        raise ValueError(f'pose arrays differ in layout: {a.shape[1:]} vs {b.shape[1:]}')
    d = np.linalg.norm(a[:, None] - b[None], axis=-1)        # [N, M, J], NaN if either missing
    valid = np.isfinite(d)
    count = valid.sum(-1)
    total = np.where(valid, d, 0.0).sum(-1)
    with np.errstate(invalid='ignore', divide='ignore'):
        return np.where(count > 0, total / np.maximum(count, 1), np.inf)


def pose_roots(poses: np.ndarray, root_joints: Optional[Sequence[int]] = None) -> np.ndarray:
    """
    Return ``[N, 3]`` root points of ``[N, J, 3]`` poses, NaN where a root is undefined.

    The root is the mean of ``root_joints`` (all of them must be valid, e.g. both hips, so a
    root never jumps to one hip), or without them the centroid of the valid joints.
    """
    poses = np.asarray(poses, dtype=float)
    sel = poses[:, list(root_joints)] if root_joints else poses
    valid = np.isfinite(sel).all(-1)
    count = valid.sum(-1)
    total = np.where(valid[..., None], sel, 0.0).sum(-2)
    if root_joints:
        return np.where((count == len(root_joints))[:, None], total / len(root_joints), np.nan)
    return np.where((count > 0)[:, None], total / np.maximum(count, 1)[:, None], np.nan)


def match_poses(pred: np.ndarray, gt: np.ndarray,
                max_distance_m: float = np.inf) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    Match predictions to ground-truth people one-to-one (Hungarian on mean joint distance).

    Returns ``(pred_index, gt_index, distance_m)`` of the accepted pairs, those with a
    distance ``<= max_distance_m``; pairs without a shared joint are never matched.
    """
    cost = pose_distances(pred, gt)
    if cost.size == 0:
        empty = np.zeros(0, dtype=int)
        return empty, empty, np.zeros(0)
    finite = np.isfinite(cost)
    big = (cost[finite].max() + 1.0) * 1e3 if finite.any() else 1.0
    rows, cols = linear_sum_assignment(np.where(finite, cost, big))
    d = cost[rows, cols]
    keep = np.isfinite(d) & (d <= max_distance_m)
    return rows[keep], cols[keep], d[keep]


@dataclass
class MPJPEResult:
    """MPJPE over a set of frames; ``mpjpe_m`` is NaN when nothing was matched."""

    mpjpe_m: float                  # mean over matched people of their mean joint error
    per_joint_m: np.ndarray         # [J] mean error per joint over matched people (NaN: never)
    matched: int                    # ground-truth people matched to a prediction
    total_gt: int                   # ground-truth people seen
    false_positives: int            # predictions left unmatched
    errors_m: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(0))

    @property
    def recall(self) -> float:
        """Fraction of ground-truth people matched within the distance threshold."""
        return self.matched / self.total_gt if self.total_gt else float('nan')


def mpjpe(frames: Iterable[Tuple[np.ndarray, np.ndarray]], match: bool = True,
          max_distance_m: float = 0.5, num_joints: Optional[int] = None) -> MPJPEResult:
    """
    Compute MPJPE over ``(pred [P,J,3], gt [G,J,3])`` pairs, one pair per frame.

    With ``match`` predictions are assigned to ground-truth people per frame by the Hungarian
    algorithm and pairs farther than ``max_distance_m`` count as misses (recall) rather than
    errors; without it ``pred[i]`` is compared to ``gt[i]`` (same number of people required).
    """
    per_person = []
    joint_sum = None
    joint_cnt = None
    total_gt = 0
    false_pos = 0
    for pred, gt in frames:
        pred = np.asarray(pred, dtype=float)
        gt = np.asarray(gt, dtype=float)
        j = gt.shape[-2] if gt.ndim == 3 and gt.shape[0] else (
            pred.shape[-2] if pred.ndim == 3 and pred.shape[0] else num_joints)
        if j is None:
            total_gt += len(gt)
            false_pos += len(pred)
            continue
        pred = pred.reshape(-1, j, 3)
        gt = gt.reshape(-1, j, 3)
        if joint_sum is None:
            joint_sum, joint_cnt = np.zeros(j), np.zeros(j, dtype=int)
        total_gt += len(gt)
        if match:
            pi, gi, _ = match_poses(pred, gt, max_distance_m)
        else:
            if len(pred) != len(gt):
                raise ValueError(f'unmatched MPJPE needs as many predictions as people '
                                 f'({len(pred)} vs {len(gt)})')
            pi = gi = np.arange(len(gt))
        false_pos += len(pred) - len(pi)
        if len(pi) == 0:
            continue
        err = np.linalg.norm(pred[pi] - gt[gi], axis=-1)     # [K, J]
        ok = np.isfinite(err)
        joint_sum += np.where(ok, err, 0.0).sum(0)
        joint_cnt += ok.sum(0)
        has = ok.any(-1)
        per_person.extend((np.where(ok, err, 0.0).sum(-1)[has] / ok.sum(-1)[has]).tolist())
    errors = np.asarray(per_person)
    if joint_sum is None:
        per_joint = np.full(num_joints or 0, np.nan)
    else:
        with np.errstate(invalid='ignore', divide='ignore'):
            per_joint = np.where(joint_cnt > 0, joint_sum / np.maximum(joint_cnt, 1), np.nan)
    return MPJPEResult(mpjpe_m=float(errors.mean()) if errors.size else float('nan'),
                       per_joint_m=per_joint, matched=int(errors.size), total_gt=total_gt,
                       false_positives=false_pos, errors_m=errors)
