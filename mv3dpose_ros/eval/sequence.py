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
Score a whole tracking run against ground truth: PCP, MPJPE, CLEAR MOT and identity in one pass.

Ground truth comes from Campus/Shelf ``actorsGT.mat`` (``shelf14``), a Panoptic
``hdPose3d_stage1_coco19`` folder (``panoptic19``) or a tracks JSON Lines file (any layout,
e.g. written by ``sim.export``). Hypotheses are tracks JSON Lines as ``mv3dpose track`` writes
them. For MPJPE and MOT, predictions are mapped to the ground-truth layout by joint name and
only joints both layouts have count (no derived joints); for PCP both sides are converted to
``shelf14`` with ``core.skeleton.convert_poses``, which derives the head joints a layout lacks
(as VoxelPose does for COCO output).

Identity figures come in two kinds: against the ground truth (IDF1/IDP/IDR, ID switches per
minute, fragmentations, duplicates near a person: :mod:`.mot`) and from the hypotheses alone
(:func:`.identity.identity_summary` with the number of ground-truth people, the figures a live
run without annotation can be given, here computed on the same frames so both can be
compared). Per-minute figures need the stamps of the tracks lines or a frame rate.
"""

from dataclasses import dataclass, field
import os
from typing import Dict, Iterable, List, Mapping, Optional, Sequence, Tuple

from mv3dpose_ros.core.skeleton import convert_poses, get_layout
from mv3dpose_ros.core.types import TrackState
from mv3dpose_ros.eval.identity import identity_summary, IdentitySummary
from mv3dpose_ros.eval.mot import MOTEvaluator, MOTResult
from mv3dpose_ros.eval.mpjpe import mpjpe, MPJPEResult
from mv3dpose_ros.eval.pcp import evaluate_pcp, PCPResult
import numpy as np

FORMATS = ('campus', 'shelf', 'panoptic', 'tracks')

# frame -> (ids [N], poses [N, J, 3] metres, NaN = missing)
PoseFrames = Dict[int, Tuple[np.ndarray, np.ndarray]]


@dataclass
class GroundTruth:
    """Ground-truth people per frame in one layout."""

    layout: str
    frames: PoseFrames
    default_frames: Optional[np.ndarray] = None    # the dataset's evaluation frames
    notes: List[str] = field(default_factory=list)


def _campus_file(path: str) -> str:
    if os.path.isdir(path):
        cand = os.path.join(path, 'actorsGT.mat')
        if not os.path.isfile(cand):
            raise FileNotFoundError(f'{path}: no actorsGT.mat in this folder')
        return cand
    return path


def _panoptic_folder(path: str) -> str:
    if os.path.isdir(path):
        sub = os.path.join(path, 'hdPose3d_stage1_coco19')
        if os.path.isdir(sub):
            return sub
        return path
    raise FileNotFoundError(f'{path}: Panoptic ground truth must be a folder of '
                            f'body3DScene_*.json files')


def load_ground_truth(path: str, fmt: str) -> GroundTruth:
    """Load ground truth of format ``campus``/``shelf``, ``panoptic`` or ``tracks``."""
    if fmt in ('campus', 'shelf'):
        from mv3dpose_ros.io.datasets import CAMPUS_TEST_FRAMES, load_campus_gt
        gt = load_campus_gt(_campus_file(path))
        frames = {}
        for k, f in enumerate(gt.frames):
            ok = np.isfinite(gt.poses[k]).all(axis=(-1, -2))
            frames[int(f)] = (np.flatnonzero(ok), gt.poses[k][ok])
        default = CAMPUS_TEST_FRAMES if fmt == 'campus' else None
        return GroundTruth(gt.layout, frames, default)
    if fmt == 'panoptic':
        from mv3dpose_ros.io.datasets import load_panoptic_gt
        gt = load_panoptic_gt(_panoptic_folder(path))
        frames = {}
        for f, bodies in zip(gt.frames, gt.bodies):
            ids = np.array([i for i, _ in bodies], dtype=int)
            poses = np.array([j[:, :3] for _, j in bodies]).reshape(len(ids), 19, 3)
            frames[int(f)] = (ids, poses)
        return GroundTruth(gt.layout, frames, None,
                           [f'skipped {p}: {r}' for p, r in gt.skipped])
    if fmt == 'tracks':
        issues: List[str] = []
        layout, frames = read_hypotheses(path, None, issues)
        if layout is None:
            raise ValueError(f'{path}: no layout in the ground-truth tracks file')
        return GroundTruth(layout, frames, None, issues)
    raise ValueError(f'unknown ground-truth format {fmt!r}; known: {", ".join(FORMATS)}')


def read_hypotheses(path: str, states: Optional[Iterable[TrackState]] = (TrackState.CONFIRMED,),
                    issues: Optional[List[str]] = None,
                    stamps: Optional[Dict[int, float]] = None
                    ) -> Tuple[Optional[str], PoseFrames]:
    """
    Read a tracks JSON Lines file: ``(layout, frame -> (ids, poses))``, keeping ``states``.

    ``states=None`` keeps every state except DELETED tombstones. Lines of another layout
    than the first are reported and skipped. A ``stamps`` dict is filled with the stamps
    (s) of the lines that carry one, by frame (for the per-minute figures).
    """
    from mv3dpose_ros.io.tracks_jsonl import read_tracks

    keep = None if states is None else set(states)
    layout = None
    frames: PoseFrames = {}
    issues = issues if issues is not None else []
    for fr in read_tracks(path, issues):
        if fr.layout is not None:
            if layout is None:
                layout = fr.layout
            elif fr.layout != layout:
                issues.append(f'{path}: frame {fr.frame}: layout {fr.layout!r} differs from '
                              f'{layout!r}; skipped')
                continue
        tracks = [t for t in fr.tracks if t.state != TrackState.DELETED
                  and (keep is None or t.state in keep)]
        n_j = get_layout(layout).num_joints if layout else (
            len(tracks[0].joints) if tracks else 0)
        bad = [t.id for t in tracks if len(t.joints) != n_j]
        if bad:
            issues.append(f'{path}: frame {fr.frame}: tracks {bad} do not have {n_j} joints; '
                          f'skipped')
            tracks = [t for t in tracks if len(t.joints) == n_j]
        ids = np.array([t.id for t in tracks], dtype=int)
        poses = np.array([t.joints for t in tracks]).reshape(len(tracks), n_j, 3)
        frames[fr.frame] = (ids, poses)
        if stamps is not None and fr.stamp is not None:
            stamps[fr.frame] = float(fr.stamp)
    return layout, frames


@dataclass
class EvalReport:
    """All scores of one run (``None`` where a metric was not computable)."""

    frames: int
    pcp: Optional[PCPResult]
    pcp8: Optional[PCPResult]
    mpjpe: MPJPEResult
    mot: MOTResult
    notes: List[str] = field(default_factory=list)
    identity: Optional[IdentitySummary] = None      # from the hypotheses alone

    def as_dict(self) -> dict:
        """Return the headline figures as a JSON-friendly dict."""
        def f(x):
            return None if x is None or not np.isfinite(x) else float(x)

        out = {'frames': self.frames, 'mpjpe_m': f(self.mpjpe.mpjpe_m),
               'mpjpe_recall': f(self.mpjpe.recall), 'mot': self.mot.as_dict(),
               'identity': None if self.identity is None else self.identity.as_dict()}
        for name, p in (('pcp', self.pcp), ('pcp8', self.pcp8)):
            if p is not None:
                out[name] = {'average': f(p.average),
                             'per_actor': {str(a): f(v)
                                           for a, v in zip(p.actor_ids, p.per_actor)},
                             'per_group': {g: f(np.nanmean(v)) if np.isfinite(v).any()
                                           else None for g, v in p.per_group.items()},
                             'recall': f(p.recall)}
        return out

    def text(self) -> str:
        """Format the report for a terminal."""
        lines = [f'evaluated {self.frames} frames']
        if self.pcp is not None:
            lines.append(self.pcp.table())
        if self.pcp8 is not None:
            lines.append(f'PCP (8 limbs) average: {100 * self.pcp8.average:.1f}')
        m = self.mpjpe
        lines.append(f'MPJPE {1000 * m.mpjpe_m:.1f} mm over {m.matched} matched people '
                     f'(recall {100 * m.recall:.1f} % of {m.total_gt}, '
                     f'{m.false_positives} unmatched predictions)')
        lines.append(self.mot.summary())
        if self.identity is not None:
            lines.append(self.identity.summary())
        lines += [f'note: {n}' for n in self.notes]
        return '\n'.join(lines)


def _to(poses: np.ndarray, src: str, dst: str, derive: bool = True) -> np.ndarray:
    """
    Convert plain ``[N, J, 3]`` poses between layouts (no confidence channel).

    Without ``derive`` joints ``src`` does not have by name stay NaN instead of being
    computed from others (a derived neck is not the annotated neck, so scoring it would add
    a systematic error that is not the tracker's).
    """
    dst_l = get_layout(dst)
    if len(poses) == 0:
        return np.zeros((0, dst_l.num_joints, 3))
    if src == dst:
        return poses
    out = convert_poses(poses, src, dst, has_confidence=False)
    if not derive:
        src_l = get_layout(src)
        out[:, [not src_l.has(n) for n in dst_l.joint_names]] = np.nan
    return out


def evaluate_run(hyp_layout: str, hyps: PoseFrames, gt: GroundTruth,
                 frames: Optional[Sequence[int]] = None, frame_offset: int = 0,
                 threshold_m: float = 0.5, mot_distance: str = 'mean_joint',
                 alpha: float = 0.5, pcp_matching: str = 'nearest',
                 stamps: Optional[Mapping[int, float]] = None, fps: Optional[float] = None,
                 duplicate_radius_m: float = 0.3) -> EvalReport:
    """
    Score hypotheses against ground truth over ``frames``.

    ``frames`` defaults to the dataset's evaluation frames, else every ground-truth frame.
    The hypotheses of GT frame ``f`` are those of tracks frame ``f + frame_offset``.
    ``stamps`` (tracks frame -> s, see :func:`read_hypotheses`) or ``fps`` (tracks frame
    ``n`` at ``n / fps`` s, which wins) time the frames for the per-minute figures and the
    warm-up of the identity summary; without either the summary is left out, with a note.
    ``duplicate_radius_m`` is the identity summary's duplicate distance.
    """
    if frames is None:
        frames = gt.default_frames if gt.default_frames is not None else sorted(gt.frames)
    frames = [int(f) for f in frames if int(f) in gt.frames]
    notes = list(gt.notes)
    glay = get_layout(gt.layout)
    hlay = get_layout(hyp_layout)
    root = glay.root_joints if mot_distance == 'root' else None
    mot = MOTEvaluator(threshold_m, mot_distance, root, fps)
    stamps = {} if stamps is None else stamps
    messages = []
    mp_pairs, pcp_frames = [], []
    empty = np.zeros((0, hlay.num_joints, 3))
    for f in frames:
        gid, gpose = gt.frames[f]
        hid, hpose = hyps.get(f + frame_offset, (np.zeros(0, dtype=int), empty))
        h_in_g = _to(hpose, hlay.name, glay.name, derive=False)
        hf = f + frame_offset
        stamp = hf / fps if fps else stamps.get(hf)
        mot.update(gid, gpose, hid, h_in_g, stamp)
        if hf in hyps:
            messages.append((stamp, list(zip(hid, hpose))))
        mp_pairs.append((h_in_g, gpose))
        pcp_frames.append((_to(hpose, hlay.name, 'shelf14'),
                           {int(i): p for i, p in zip(gid, _to(gpose, glay.name, 'shelf14'))}))
    missing = [f for f in frames if f + frame_offset not in hyps]
    if missing:
        notes.append(f'{len(missing)} of {len(frames)} evaluated frames have no line in the '
                     f'tracks file (counted as no predictions)')
    actor_ids = sorted({int(i) for f in frames for i in gt.frames[f][0]})
    pcp = evaluate_pcp(pcp_frames, alpha, '10', pcp_matching, threshold_m, actor_ids)
    pcp8 = evaluate_pcp(pcp_frames, alpha, '8', pcp_matching, threshold_m, actor_ids)
    if glay.name != 'shelf14':
        notes.append(f'PCP: ground truth converted from {glay.name} to shelf14 (head joints '
                     f'derived as in core.skeleton)')
    identity = None
    if any(s is None for s, _ in messages):
        notes.append('identity without GT left out: the tracks lines carry no stamp (give a '
                     'frame rate); ID switches per minute likewise')
    else:
        identity = identity_summary(messages, len(actor_ids), radius_m=duplicate_radius_m)
    return EvalReport(frames=len(frames), pcp=pcp, pcp8=pcp8,
                      mpjpe=mpjpe(mp_pairs, True, threshold_m, glay.num_joints),
                      mot=mot.result(), notes=notes, identity=identity)
