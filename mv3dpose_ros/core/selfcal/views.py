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
The input of self-calibration: keypoints per camera and frame, normalised, and checked.

What the estimation needs before any geometry: confident joints undistorted to normalised
coordinates (``normalise_views``), people followed from frame to frame in each view
(``track_2d``), and a refusal with the reason when the recording cannot fix a rig
(``check_views``: too few people or frames, people who barely move); and the knobs every
step reads (``Settings``) with the error every step raises (``SelfCalError``).
"""

from dataclasses import dataclass, field
from typing import Dict, Iterable, List, Mapping, Optional, Tuple

from mv3dpose_ros.core.geometry.camera import Camera
from mv3dpose_ros.core.skeleton import get_layout
import numpy as np
from scipy.optimize import linear_sum_assignment


class SelfCalError(ValueError):
    """Input the rig cannot be calibrated from; the message says what and why."""


@dataclass
class Settings:
    """Knobs of the estimation (defaults fit 25-60 fps detections of OpenPose-like models)."""

    min_confidence: float = 0.3     # joints below are not used
    min_joints: int = 6             # people with fewer confident joints are not used
    track_gate: float = 0.35        # 2D tracklets: median joint step / person height
    match_gate: float = 0.05        # person match: median Sampson distance / person height
    match_gate_min_px: float = 4.0  # ... but never stricter than this
    hypotheses: int = 8             # longest tracklets per view tried as pair hypotheses
    probe_frames: int = 40          # frames a hypothesis is scored on before the best's all
    min_pair_frames: int = 10       # person matches a camera pair needs to be used
    min_frames: int = 10            # frames with people in at least two cameras
    loss_px: float = 3.0            # robust loss scale of the bundle adjustment
    outlier_px: float = 25.0        # observations dropped before the last adjustment
    max_points: int = 20000         # joints kept for the adjustment (evenly over frames)
    init_points: int = 3000         # ... and while cameras are being placed
    odd_ratio: float = 4.0          # a camera this many times further off the others'
    odd_px: float = 25.0            # ... triangulations than the rest and this far: unplaced
    bumped_ratio: float = 4.0       # refine: a camera whose image moves this many times more
    bumped_px: float = 8.0          # ... than the others' and this far, fitted to the others'
    #                                 triangulations, is re-placed and adjusted alone
    seed: int = 0


@dataclass
class Views:
    """Per camera and frame the people as ``[P, J, 3]``: normalised x, y and confidence."""

    cameras: List[str]
    frames: List[int]
    people: Dict[str, List[np.ndarray]]
    focal: Dict[str, float]
    tracks: Dict[str, List[np.ndarray]] = field(default_factory=dict)


def normalise_views(sequence: Iterable[Tuple[int, Mapping[str, np.ndarray]]],
                    intrinsics: Mapping[str, Camera], layout: str,
                    settings: Optional[Settings] = None) -> Views:
    """
    Undistort every frame's keypoints (pixels + confidence) with the cameras' intrinsics.

    Joints under ``min_confidence`` get confidence 0; people with fewer than ``min_joints``
    joints left are dropped.
    """
    s = settings or Settings()
    num = get_layout(layout).num_joints
    names = list(intrinsics)
    people: Dict[str, List[np.ndarray]] = {c: [] for c in names}
    frames: List[int] = []
    for frame, views in sequence:
        frames.append(int(frame))
        for c in names:
            p = np.asarray(views.get(c, np.zeros((0, num, 3))), dtype=float).reshape(-1, num, 3)
            conf = np.where(p[..., 2] >= s.min_confidence, p[..., 2], 0.0)
            xy = intrinsics[c].undistort(np.where(conf[..., None] > 0, p[..., :2], np.nan))
            out = np.concatenate([xy, conf[..., None]], axis=-1)
            out[conf == 0] = [np.nan, np.nan, 0.0]
            people[c].append(out[(conf > 0).sum(1) >= s.min_joints])
    return Views(names, frames, people, {c: intrinsics[c].focal for c in names})


def nanmedian(a: np.ndarray) -> np.ndarray:
    """Return the median over the last axis ignoring NaN (numpy's is 20x slower on small rows)."""
    a = np.sort(a, axis=-1)                  # NaN sort last
    n = np.isfinite(a).sum(-1)
    lo = np.take_along_axis(a, np.maximum((n - 1) // 2, 0)[..., None], -1)[..., 0]
    hi = np.take_along_axis(a, np.maximum(n // 2, 0)[..., None], -1)[..., 0]
    return np.where(n > 0, 0.5 * (lo + hi), np.nan)


def extent_2d(p: np.ndarray) -> np.ndarray:
    """Return the ``[P]`` 2D extents (max of box width and height) of people ``[P, J, 3]``."""
    if not len(p):
        return np.zeros(0)
    with np.errstate(invalid='ignore'):
        lo, hi = np.nanmin(p[..., :2], axis=1), np.nanmax(p[..., :2], axis=1)
    return np.nan_to_num(np.max(hi - lo, axis=1), nan=0.0)


def track_2d(frames: List[np.ndarray], gate: float = 0.35) -> List[np.ndarray]:
    """
    Follow people from frame to frame in one view; return per frame ``[P]`` tracklet ids.

    Consecutive detections are linked by Hungarian matching on the median joint distance
    relative to the person's size, under ``gate``.
    """
    ids, prev, prev_ids, nxt = [], np.zeros((0, 0, 3)), np.zeros(0, int), 0
    for p in frames:
        cur = np.full(len(p), -1)
        if len(p) and len(prev):
            d = np.linalg.norm(p[:, None, :, :2] - prev[None, :, :, :2], axis=-1)
            cost = nanmedian(d) if d.size else d.sum(-1)
            size = np.maximum(extent_2d(p)[:, None], extent_2d(prev)[None, :])
            cost = np.where(np.isfinite(cost), cost / np.maximum(size, 1e-9), 1e9)
            rows, cols = linear_sum_assignment(cost)
            for r, c in zip(rows, cols):
                if cost[r, c] < gate:
                    cur[r] = prev_ids[c]
        for k in np.flatnonzero(cur < 0):
            cur[k] = nxt
            nxt += 1
        ids.append(cur)
        prev, prev_ids = p, cur
    return ids


class no_empty_slice_warnings:
    """Silence numpy's 'mean of empty slice' warnings of all-NaN rows."""

    def __enter__(self):
        import warnings
        self._w = warnings.catch_warnings()
        self._w.__enter__()
        warnings.simplefilter('ignore', RuntimeWarning)

    def __exit__(self, *exc):
        self._w.__exit__(*exc)


def check_views(views: Views, s: Settings) -> None:
    """Raise ``SelfCalError`` for too few people or frames, or people who barely move."""
    shared = sum(sum(len(views.people[c][f]) > 0 for c in views.cameras) >= 2
                 for f in range(len(views.frames)))
    if not any(len(p) for c in views.cameras for p in views.people[c]):
        raise SelfCalError(f'no people with {s.min_joints} joints of confidence >= '
                           f'{s.min_confidence} in any of {len(views.frames)} frames')
    if shared < s.min_frames:
        raise SelfCalError(f'too few frames: people are seen by two cameras or more in '
                           f'{shared} of {len(views.frames)} frames (need {s.min_frames}; '
                           'record longer, with people walking through the whole rig)')
    spans = []
    for c in views.cameras:                  # how far each person moves in each view
        ids = track_2d(views.people[c], s.track_gate)
        roots, sizes, who = [], [], []
        for p, k in zip(views.people[c], ids):
            if len(p):
                with no_empty_slice_warnings():
                    roots.append(np.nanmean(p[..., :2], axis=1))
                sizes.append(extent_2d(p))
                who.append(k)
        if not roots:
            continue
        roots, sizes, who = np.concatenate(roots), np.concatenate(sizes), np.concatenate(who)
        for k in np.unique(who):
            r = roots[who == k]
            if len(r) >= 5:
                span = np.max(np.nanpercentile(r, 95, axis=0) - np.nanpercentile(r, 5, axis=0))
                spans.append(span / max(float(np.median(sizes[who == k])), 1e-9))
    if spans and max(spans) < 0.25:
        raise SelfCalError(f'degenerate motion: the people barely move (in every view each '
                           f'one moves at most {max(spans):.2f} of their height); a few poses '
                           'do not fix the cameras: walk through the whole capture volume')
