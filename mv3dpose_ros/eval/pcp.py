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
PCP3D (percentage of correct parts) on the Shelf/Campus 14-joint skeleton.

The protocol is the one used by Belagiannis et al., Chen et al. and VoxelPose /
Faster-VoxelPose for Campus and Shelf, checked against their ``evaluate`` code:

- joints (``shelf14``): 0 R-ankle, 1 R-knee, 2 R-hip, 3 L-hip, 4 L-knee, 5 L-ankle, 6 R-wrist,
  7 R-elbow, 8 R-shoulder, 9 L-shoulder, 10 L-elbow, 11 L-wrist, 12 bottom-head (neck),
  13 top-head;
- 10 parts: lower legs (ankle-knee), upper legs (knee-hip), lower arms (wrist-elbow), upper
  arms (elbow-shoulder), head (bottom-head to top-head) and torso (the midpoint of the two hips
  to bottom-head); the 8-limb variant drops head and torso;
- a part is correct when the mean of its two endpoint errors is at most ``alpha`` (0.5) times
  the ground-truth part length;
- each annotated ground-truth person of a frame is compared with the prediction of smallest
  MPJPE (not exclusive, as in VoxelPose); PCP is computed per actor and averaged over actors.

Differences, on purpose: a ground-truth person in a frame without any prediction counts all
its parts as wrong (Faster-VoxelPose skips such frames, which inflates PCP), a prediction
part with a missing (NaN) endpoint is wrong, and a part whose ground-truth endpoints are not
annotated is not counted at all (never the case on Campus/Shelf).
"""

from dataclasses import dataclass
from typing import Dict, Iterable, List, Mapping, Sequence, Tuple

from mv3dpose_ros.eval.mpjpe import match_poses, pose_distances
import numpy as np

_HIP_MID = 14   # index of the synthetic hip midpoint appended to the 14 joints

# (name, group, joint a, joint b) on shelf14 + hip midpoint; order as in VoxelPose.
PCP_PARTS: Tuple[Tuple[str, str, int, int], ...] = (
    ('right_lower_leg', 'Lower legs', 0, 1),
    ('right_upper_leg', 'Upper legs', 1, 2),
    ('left_upper_leg', 'Upper legs', 3, 4),
    ('left_lower_leg', 'Lower legs', 4, 5),
    ('right_lower_arm', 'Lower arms', 6, 7),
    ('right_upper_arm', 'Upper arms', 7, 8),
    ('left_upper_arm', 'Upper arms', 9, 10),
    ('left_lower_arm', 'Lower arms', 10, 11),
    ('head', 'Head', 12, 13),
    ('torso', 'Torso', _HIP_MID, 12),
)
PCP_VARIANTS: Dict[str, Tuple[int, ...]] = {
    '10': tuple(range(10)),   # standard: 8 limbs + head + torso
    '8': tuple(range(8)),     # limbs only
}
PART_GROUPS = ('Upper arms', 'Lower arms', 'Upper legs', 'Lower legs', 'Head', 'Torso')


def _with_hip_mid(poses: np.ndarray) -> np.ndarray:
    poses = np.asarray(poses, dtype=float)
    if poses.shape[-2:] != (14, 3):
        raise ValueError(f'PCP needs shelf14 poses [..., 14, 3], got {poses.shape}')
    hip = 0.5 * (poses[..., 2, :] + poses[..., 3, :])
    return np.concatenate([poses, hip[..., None, :]], axis=-2)


def pcp_correct(pred: np.ndarray, gt: np.ndarray, alpha: float = 0.5,
                variant: str = '10') -> np.ndarray:
    """
    Return a boolean ``[..., parts]`` array: is each part of ``pred`` correct w.r.t. ``gt``.

    ``pred`` and ``gt`` are ``[..., 14, 3]`` shelf14 poses in the same units (broadcast).
    """
    if variant not in PCP_VARIANTS:
        raise ValueError(f'unknown PCP variant {variant!r}; known: {sorted(PCP_VARIANTS)}')
    idx = PCP_VARIANTS[variant]
    a = np.array([PCP_PARTS[i][2] for i in idx])
    b = np.array([PCP_PARTS[i][3] for i in idx])
    p = _with_hip_mid(pred)
    g = _with_hip_mid(gt)
    err = np.linalg.norm(p - g, axis=-1)                      # [..., 15]
    length = np.linalg.norm(g[..., a, :] - g[..., b, :], axis=-1)
    mean_err = 0.5 * (err[..., a] + err[..., b])
    with np.errstate(invalid='ignore'):
        return np.isfinite(mean_err) & (mean_err <= alpha * length)


def _gt_parts_valid(gt: np.ndarray, variant: str) -> np.ndarray:
    """Return ``[..., parts]``: are both ground-truth endpoints of each part known."""
    idx = PCP_VARIANTS[variant]
    g = np.isfinite(_with_hip_mid(gt)).all(-1)
    return np.stack([g[..., PCP_PARTS[i][2]] & g[..., PCP_PARTS[i][3]] for i in idx], -1)


@dataclass
class PCPResult:
    """PCP per actor and part group, plus the detection recall at ``recall_threshold_m``."""

    actor_ids: List[int]
    per_actor: np.ndarray            # [A] PCP of each actor (NaN if never annotated)
    per_group: Dict[str, np.ndarray]  # group name -> [A] PCP of that group per actor
    recall: float                    # GT people whose nearest prediction has MPJPE < threshold
    frames: int
    variant: str
    recall_threshold_label: str = '0.5m'

    @property
    def average(self) -> float:
        """Mean PCP over actors (the figure papers report as 'Average')."""
        v = self.per_actor[np.isfinite(self.per_actor)]
        return float(v.mean()) if v.size else float('nan')

    def table(self) -> str:
        """Format as a small text table, one column per actor."""
        head = ' ' * 12 + ''.join(f'{"actor " + str(a):>10}' for a in self.actor_ids)
        lines = [f'PCP ({self.variant} parts) over {self.frames} frames', head + f'{"avg":>10}']
        rows = [('PCP', self.per_actor)] + [(g, v) for g, v in self.per_group.items()]
        for name, vals in rows:
            fin = vals[np.isfinite(vals)]
            avg = fin.mean() if fin.size else float('nan')
            lines.append(f'{name:<12}' + ''.join(f'{100 * v:10.1f}' for v in vals)
                         + f'{100 * avg:10.1f}')
        lines.append(f'recall@{self.recall_threshold_label}: {100 * self.recall:.1f}')
        return '\n'.join(lines)


def evaluate_pcp(frames: Iterable[Tuple[np.ndarray, Mapping[int, np.ndarray]]],
                 alpha: float = 0.5, variant: str = '10', matching: str = 'nearest',
                 recall_threshold_m: float = 0.5,
                 actor_ids: Sequence[int] = ()) -> PCPResult:
    """
    Compute PCP over frames of ``(pred [P,14,3], {actor_id: gt [14,3]})`` in metres.

    ``matching='nearest'`` follows VoxelPose (each GT person takes the prediction of least
    MPJPE, a prediction may serve two people); ``'hungarian'`` assigns one-to-one.
    """
    if matching not in ('nearest', 'hungarian'):
        raise ValueError(f"matching must be 'nearest' or 'hungarian', not {matching!r}")
    groups = [PCP_PARTS[i][1] for i in PCP_VARIANTS[variant]]
    correct: Dict[int, np.ndarray] = {}
    total: Dict[int, np.ndarray] = {}
    hit = seen = n_frames = 0
    for pred, gt in frames:
        n_frames += 1
        ids = sorted(gt)
        if not ids:
            continue
        g = np.stack([np.asarray(gt[i], dtype=float) for i in ids])
        p = np.asarray(pred, dtype=float).reshape(-1, 14, 3)
        choice = np.full(len(ids), -1)
        if len(p):
            dist = pose_distances(p, g)                            # [P, G]
            if matching == 'nearest':
                choice = np.where(np.isfinite(dist).any(0), np.argmin(dist, axis=0), -1)
            else:
                pi, gi, _ = match_poses(p, g)
                choice[gi] = pi
            best = np.array([dist[c, k] if c >= 0 else np.inf for k, c in enumerate(choice)])
            hit += int(np.sum(best < recall_threshold_m))
        seen += len(ids)
        valid = _gt_parts_valid(g, variant)                            # [G, parts]
        for k, aid in enumerate(ids):
            ok = (pcp_correct(p[choice[k]], g[k], alpha, variant) if choice[k] >= 0
                  else np.zeros(len(groups), dtype=bool))
            correct[aid] = correct.get(aid, 0) + (ok & valid[k]).astype(int)
            total[aid] = total.get(aid, 0) + valid[k].astype(int)
    actors = sorted(set(actor_ids) | set(total))
    zero = np.zeros(len(groups), dtype=int)
    c = np.array([correct.get(a, zero) for a in actors]).reshape(len(actors), len(groups))
    n = np.array([total.get(a, zero) for a in actors]).reshape(len(actors), len(groups))

    def ratio(num: np.ndarray, den: np.ndarray) -> np.ndarray:
        with np.errstate(invalid='ignore', divide='ignore'):
            return np.where(den > 0, num / np.maximum(den, 1), np.nan)

    per_group = {}
    for name in PART_GROUPS:
        cols = [i for i, gname in enumerate(groups) if gname == name]
        if cols:
            per_group[name] = ratio(c[:, cols].sum(1), n[:, cols].sum(1))
    return PCPResult(actor_ids=list(actors), per_actor=ratio(c.sum(1), n.sum(1)),
                     per_group=per_group, recall=hit / seen if seen else float('nan'),
                     frames=n_frames, variant=variant,
                     recall_threshold_label=f'{recall_threshold_m:g}m')
