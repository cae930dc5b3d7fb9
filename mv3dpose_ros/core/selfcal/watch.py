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
The calibration watch: each camera's pose checked, live, against the rest of the rig.

A rig lives for months: a tripod is kicked, a mount sags, a camera is re-aimed after cleaning,
and every track degrades without a line of output. The watch measures, for every camera, the
small rotation that best maps where the OTHER cameras put the people (their leave-one-out
triangulation of the joints this camera also sees) onto this camera's own keypoints, over a
sliding window of confident joints (``window_s``), robustly (Kabsch on unit bearings with
Cauchy reweighting). A rig's own small calibration errors and its detector's biases show as a
rotation that wanders about a constant: the mean of a camera's first ``baseline_s`` of
estimates is its baseline, their spread its noise, and its drift the rotation since the
baseline. Which cameras place the people changes the biases, so a camera keeps one baseline
per set of cameras left out of its triangulations.

A camera whose drift stays over ``warn_deg`` (or three times its noise, if larger) for
``hold_s`` is named, once: the camera, the
rotation (degrees, about the camera's own x, y and z axes), the stamp of the set it was found
at and what to do. Only one camera is named at a time: among those over their threshold, one
whose leave-one-out triangulations the other cameras agree on (a bumped camera also turns the
triangulations of the cameras it takes part in, but not its own); the others' windows start
again without it, and a named camera never takes part in another's triangulation: the majority
holds the frame. With fewer than ``min_agreeing`` cameras left to agree with, the watch
warns only.

Modes (``mode``): ``off``; ``warn`` (name it, change nothing); ``exclude`` (a named camera
stops contributing to the fusion, is still watched, and comes back when it agrees again);
``correct`` (a named camera is excluded until its drift estimate is stable, then its rotation
is corrected by the estimate: the camera's centre is kept, its orientation turned back, and the
change reported; it rejoins the rig). Translations are not estimated: a camera moved without
turning shows as a growing residual (``residual_px``), not as drift.

A rig of two cameras cannot be watched (a camera's people are placed by one other camera only:
nothing to hold the frame). No ROS here: ``core.live.loop.LiveFusion`` runs it after each fused
set (``fused``), and so does ``mv3dpose track`` in every mode, so they behave the same.
"""

from dataclasses import dataclass, field
import math
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple

from mv3dpose_ros.core.assignment import gated_assignment
from mv3dpose_ros.core.geometry.camera import Camera, turned
from mv3dpose_ros.core.geometry.triangulation import dlt_basis, reproject, triangulate_dlt
from mv3dpose_ros.core.types import CALIBRATION_WATCH_MODES, NS_PER_S, Track, TrackState
import numpy as np

#: Per-camera levels, as ``/diagnostics`` reports them.
OK, WARN, ERROR = 'OK', 'WARN', 'ERROR'


@dataclass
class WatchConfig:
    """Knobs of the calibration watch (defaults fit 10-60 Hz rigs of 3 cameras or more)."""

    mode: str = 'correct'
    window_s: float = 1.5           # sliding window of joints per camera
    interval_s: float = 0.2         # at most one observation per this much stamp time
    min_confidence: float = 0.4     # keypoints below are not used
    min_points: int = 40            # joints in the window before a camera has an estimate
    min_sets: int = 5               # ... from this many observed sets (not a few poses)
    baseline_s: float = 3.0         # estimates averaged into a baseline (and its noise)
    noise_factor: float = 3.0       # a camera's threshold is at least this times its noise
    noise_s: float = 10.0           # the noise keeps being learned over about this long
    min_sigmas: float = 3.0         # ... and the drift is this many standard errors of the
    #                                 window's estimate (the points' spread fixes its axes)
    lead_ratio: float = 1.25        # 4 cameras or more: named if its drift leads the next
    #                                 camera's by this factor (in units of their thresholds)
    support_ratio: float = 1.25     # 3 cameras: named if the others' agreement on its
    #                                 triangulations (against its baseline) is within this
    #                                 factor of the best camera's
    warn_deg: float = 1.0           # drift that names a camera ...
    hold_s: float = 0.5             # ... when it stays over it this long
    error_deg: float = 2.0          # drift reported as ERROR rather than WARN
    agree_ratio: float = 0.4        # a named camera agrees again under this part of it
    stable_deg: float = 0.15        # correct: estimates within this of each other ...
    stable_s: float = 0.5           # ... for this long are applied
    min_agreeing: int = 3           # cameras that must agree before one is corrected
    match_gate: float = 0.5         # detection to track: mean joint distance / 2D height
    triangulation_gate_px: float = 20.0   # leave-one-out points the others reproject worse
    #                                        than this are not used
    outlier_view_px: float = 8.0    # a view this far off, and ...
    outlier_view_ratio: float = 2.0  # ... this many times the next worst, is left out of a
    #                                  point (where three views or more remain)

    @classmethod
    def of(cls, fusion_config: Any) -> 'WatchConfig':
        """Return the watch a ``FusionConfig`` asks for (``calibration_watch``, ``_deg``)."""
        return cls(mode=fusion_config.calibration_watch,
                   warn_deg=fusion_config.calibration_watch_deg)

    def validate(self) -> None:
        """Raise ValueError for a setting that cannot work."""
        if self.mode not in CALIBRATION_WATCH_MODES:
            raise ValueError(f'calibration_watch must be one of '
                             f'{", ".join(CALIBRATION_WATCH_MODES)}, '
                             f'got {self.mode!r}')
        for name in ('window_s', 'baseline_s', 'warn_deg', 'error_deg', 'agree_ratio',
                     'match_gate', 'triangulation_gate_px', 'support_ratio'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f'calibration watch {name} must be finite and > 0, got {value}')
        if self.agree_ratio >= 1:
            raise ValueError('calibration watch agree_ratio must be below 1')
        if self.min_points < 6 or self.min_agreeing < 2:
            raise ValueError('calibration watch needs min_points >= 6 and min_agreeing >= 2')


@dataclass
class CameraWatch:
    """What the watch knows of one camera (read by diagnostics; updated by the watch)."""

    name: str
    level: str = OK
    named: bool = False             # over the threshold: reported, excluded or to correct
    drift_deg: float = float('nan')         # rotation since the baseline
    drift_axis_deg: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    threshold_deg: float = float('nan')     # drift that names it (warn_deg or its noise)
    drift_sigmas: float = float('nan')      # the drift in standard errors of the estimate
    residual_px: float = float('nan')       # median reprojection of the others' points
    baseline_residual_px: float = float('nan')
    support_px: float = float('nan')        # how well the others agree on those points
    support_ratio: float = float('nan')     # ... against the baseline's agreement
    points: int = 0                 # joints in the window
    corrections: int = 0
    baselines: Dict[frozenset, '_Baseline'] = field(default_factory=dict)
    over_since_ns: Optional[int] = None
    stable_since_ns: Optional[int] = None
    last_estimate: Optional[np.ndarray] = None


@dataclass
class WatchEvent:
    """One thing the watch has to say: ``kind`` is named, agrees, corrected or error."""

    kind: str
    camera: str
    stamp_ns: int
    drift_deg: float
    message: str
    camera_model: Optional[Camera] = None   # corrected: the new camera


class _Baseline:
    """A camera's baseline for one set of left-out cameras: mean rotation and its noise."""

    def __init__(self, start_ns: int):
        self.start_ns = start_ns
        self.samples: List[np.ndarray] = []
        self.residuals: List[float] = []
        self.rotation: Optional[np.ndarray] = None
        self.noise2 = float('nan')                 # mean squared drift [deg^2]
        self.residual_px = float('nan')
        self.supports: List[float] = []
        self.support_px = float('nan')

    def add(self, estimate: np.ndarray, residual_px: float, support_px: float, stamp_ns: int,
            duration_s: float) -> bool:
        """Take an estimate while learning; return True once the baseline is set."""
        if self.rotation is not None:
            return True
        self.samples.append(estimate)
        self.residuals.append(residual_px)
        self.supports.append(support_px)
        if stamp_ns - self.start_ns < duration_s * NS_PER_S or len(self.samples) < 3:
            return False
        u, _, vt = np.linalg.svd(np.mean(self.samples, axis=0))      # chordal mean
        self.rotation = u @ np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt))]) @ vt
        self.noise2 = float(np.mean(
            [rotation_angle_deg(r @ self.rotation.T) ** 2 for r in self.samples]))
        self.residual_px = float(np.median(self.residuals))
        self.support_px = float(np.median(self.supports))
        self.samples, self.residuals, self.supports = [], [], []
        return True


class _Window:
    """A camera's recent bearing pairs: observed (its keypoints) and predicted (the others')."""

    def __init__(self):
        self.stamps = np.zeros(0, dtype=np.int64)
        self.observed = np.zeros((0, 3))
        self.predicted = np.zeros((0, 3))
        self.weight = np.zeros(0)
        self.residual_px = np.zeros(0)
        self.support_px: List[tuple] = []              # (stamp, median over all its points)
        self.estimate: Optional[np.ndarray] = None     # the last rotation (a warm start)
        self.since_ns: Optional[int] = None             # first stamp since the last clear

    def add(self, stamp_ns: int, observed, predicted, weight, residual_px, support_px: float,
            oldest_ns: int):
        if self.since_ns is None:
            self.since_ns = stamp_ns
        keep = self.stamps >= oldest_ns
        self.stamps = np.concatenate([self.stamps[keep], np.full(len(weight), stamp_ns)])
        self.observed = np.concatenate([self.observed[keep], observed])
        self.predicted = np.concatenate([self.predicted[keep], predicted])
        self.weight = np.concatenate([self.weight[keep], weight])
        self.residual_px = np.concatenate([self.residual_px[keep], residual_px])
        self.support_px = [(t, v) for t, v in self.support_px if t >= oldest_ns]
        self.support_px.append((stamp_ns, support_px))

    def clear(self) -> None:
        self.__init__()


def rotation_angle_deg(rotation: np.ndarray) -> float:
    """Return the angle of a rotation matrix in degrees."""
    cos = (float(np.trace(rotation)) - 1.0) / 2.0
    return math.degrees(math.acos(min(1.0, max(-1.0, cos))))


def rotation_vector_deg(rotation: np.ndarray) -> np.ndarray:
    """Return the axis-angle vector ``[3]`` of a rotation in degrees (small angles: per axis)."""
    angle = math.radians(rotation_angle_deg(rotation))
    skew = np.array([rotation[2, 1] - rotation[1, 2], rotation[0, 2] - rotation[2, 0],
                     rotation[1, 0] - rotation[0, 1]])
    if angle < 1e-9:
        return np.degrees(0.5 * skew)
    return np.degrees(skew * (angle / (2.0 * math.sin(angle))))


def robust_rotation(observed: np.ndarray, predicted: np.ndarray, weight: np.ndarray,
                    start: Optional[np.ndarray] = None, iterations: int = 3) -> np.ndarray:
    """
    Return the rotation ``R`` with ``observed ~ R @ predicted`` (unit bearings ``[N, 3]``).

    Weighted Kabsch, reweighted by a Cauchy function of each pair's residual (scale: 1.5 times
    the median residual), so a joint matched to the wrong person or a swapped limb does not
    turn the camera. ``start`` (the last estimate of a sliding window) makes the first
    reweighting meaningful, so one iteration then does.
    """
    w = weight
    rotation = start
    for _ in range(1 if start is not None else iterations):
        if rotation is not None:
            r = np.linalg.norm(observed - predicted @ rotation.T, axis=1)
            scale = max(1.5 * float(np.median(r)), 1e-6)
            w = weight / (1.0 + (r / scale) ** 2)
        h = (predicted * w[:, None]).T @ observed
        u, _, vt = np.linalg.svd(h)
        d = np.sign(np.linalg.det(vt.T @ u.T))
        rotation = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    return rotation


def rotation_information(observed: np.ndarray, predicted: np.ndarray, weight: np.ndarray,
                         rotation: np.ndarray, sets: int) -> np.ndarray:
    """
    Return the ``[3, 3]`` information (inverse covariance, 1/deg^2) of a rotation estimate.

    A small turn ``w`` moves a bearing ``b`` by ``w x b``: the points' spread decides how well
    each axis is known (people in the middle of the image fix the roll poorly). The scatter is
    the residuals' robust spread; the joints of one set share their errors (one pose, one
    detector pass), so the sets, not the joints, count as independent.
    """
    b = predicted @ rotation.T
    r = observed - b
    sigma2 = (1.4826 * float(np.median(np.linalg.norm(r, axis=1)))) ** 2 / 2 + 1e-12
    skew = np.zeros((len(b), 3, 3))
    skew[:, 0, 1], skew[:, 0, 2], skew[:, 1, 2] = -b[:, 2], b[:, 1], -b[:, 0]
    skew -= skew.transpose(0, 2, 1)
    w = weight / max(float(weight.mean()), 1e-12)
    info = np.einsum('n,nji,njk->ik', w, skew, skew) / sigma2
    return info * (sets / max(len(b), 1)) * math.radians(1.0) ** 2


def _bearings(xy: np.ndarray) -> np.ndarray:
    b = np.concatenate([xy, np.ones(xy.shape[:-1] + (1,))], axis=-1)
    return b / np.linalg.norm(b, axis=-1, keepdims=True)


class CalibrationWatch:
    """The live watch over a rig's extrinsics; ``observe`` after every fused set."""

    def __init__(self, cameras: Mapping[str, Camera], config: Optional[WatchConfig] = None):
        self.config = config or WatchConfig()
        self.config.validate()
        self.names: List[str] = list(cameras)
        self.cameras: Dict[str, Camera] = dict(cameras)
        self.status: Dict[str, CameraWatch] = {n: CameraWatch(n) for n in self.names}
        self._windows = {n: _Window() for n in self.names}
        self._projections = np.zeros((len(self.names), 3, 4))
        self._basis = np.zeros(0)
        self._last_ns: Optional[int] = None
        self._added_ns: Dict[str, int] = {}       # when each camera's window last took a set
        self._set_projections()

    @classmethod
    def unstarted(cls, config: Optional[WatchConfig] = None) -> 'CalibrationWatch':
        """Return a watch over no camera yet (before the rig is known): it observes nothing."""
        return cls({}, config)

    # ------------------------------------------------------------------ public
    @property
    def enabled(self) -> bool:
        """Tell whether the watch runs at all."""
        return self.config.mode != 'off'

    def excluded(self) -> List[str]:
        """Return the cameras the fusion should leave out now (exclude and correct modes)."""
        if self.config.mode not in ('exclude', 'correct'):
            return []
        # With fewer than min_agreeing others, leaving a camera out leaves a rig that may track
        # worse than with it: only a camera turned past error_deg is left out then.
        return [n for n in self.names if self.status[n].named and (
            self._agreeing(n) >= self.config.min_agreeing
            or self.status[n].drift_deg > self.config.error_deg)]

    def reset(self) -> None:
        """Forget every window and baseline (a rig change, a clock jump)."""
        for name in self.names:
            self._windows[name].clear()
            self.status[name] = CameraWatch(name, corrections=self.status[name].corrections)
        self._last_ns = None
        self._added_ns.clear()

    def fused(self, fusion: Any, views: Mapping[str, np.ndarray], stamp: float,
              stamp_ns: int) -> Tuple[List[Track], List[WatchEvent]]:
        """
        Run ``fusion.step`` on the views of the cameras not left out, then watch the set.

        A correction is applied to ``fusion`` (``Fusion.replace_camera``) before this returns.
        ``Fusion.step`` failing raises; the watch failing is an ``error`` event, never more.
        """
        left_out = self.excluded()
        tracks = fusion.step({c: p for c, p in views.items() if c not in left_out}
                             if left_out else views, stamp, stamp_ns)
        if not views or not self.enabled:
            return tracks, []
        try:
            events = self.observe(views, tracks, stamp_ns)
        except Exception as exc:  # noqa: B902 - the watch must never stop the fusion
            return tracks, [WatchEvent('error', '', stamp_ns, float('nan'),
                                       f'calibration watch failed on the set at '
                                       f'{stamp_ns / NS_PER_S:.6f} s ({exc!r}); set not watched')]
        for event in events:
            if event.kind == 'corrected':
                fusion.replace_camera(event.camera_model)
        return tracks, events

    def observe(self, views: Mapping[str, np.ndarray], tracks: Sequence[Track],
                stamp_ns: int) -> List[WatchEvent]:
        """Take one fused set: the views that went in and the tracks that came out."""
        cfg = self.config
        if not self.enabled or len(self.names) < 3:
            return []
        if self._last_ns is not None and stamp_ns < self._last_ns:
            self.reset()                      # the clock went back: windows mean nothing
        self._last_ns = stamp_ns
        # Each camera takes a set at most every interval_s (the cost), but every set it can
        # use when views are sparse (dropped frames, a slow rig): its window fills anyway.
        due = [n for n in self.names if n in views and (
            n not in self._added_ns
            or stamp_ns - self._added_ns[n] >= cfg.interval_s * NS_PER_S)]
        if not due:
            return []
        joints = np.array([t.joints for t in tracks
                           if t.state == TrackState.CONFIRMED and t.valid.sum() >= 4])
        if len(joints):
            self._collect(views, joints, stamp_ns, due)
        return self._judge(stamp_ns)

    # ------------------------------------------------------------------ collecting
    def _set_projections(self) -> None:
        for c, name in enumerate(self.names):
            cam = self.cameras[name]
            self._projections[c] = np.hstack([cam.R, cam.t[:, None]])
        self._basis = dlt_basis(self._projections) if self.names else np.zeros(0)

    def _collect(self, views: Mapping[str, np.ndarray], joints: np.ndarray, stamp_ns: int,
                 due: Sequence[str]) -> None:
        """Match each camera's people to the tracks, triangulate leave-one-out, keep pairs."""
        cfg = self.config
        num_c, (num_t, num_j) = len(self.names), joints.shape[:2]
        u = np.zeros((num_c, num_t, num_j))
        v = np.zeros_like(u)
        w = np.zeros_like(u)
        px = np.full((num_c, num_t, num_j, 2), np.nan)
        for c, name in enumerate(self.names):
            poses = views.get(name)
            if poses is None or not len(poses) or poses.shape[1] != num_j:
                continue
            cam = self.cameras[name]
            rows, cols = self._match(cam, poses, joints)
            if not len(rows):
                continue
            mine = poses[cols]
            xy = cam.undistort(mine[..., :2])
            ok = np.isfinite(xy).all(axis=-1) & (mine[..., 2] >= cfg.min_confidence)
            u[c, rows] = np.where(ok, xy[..., 0], 0.0)
            v[c, rows] = np.where(ok, xy[..., 1], 0.0)
            w[c, rows] = np.where(ok, mine[..., 2], 0.0)
            px[c, rows] = np.where(ok[..., None], mine[..., :2], np.nan)
        # Every camera's leave-one-out triangulation in one solve: candidate block c holds the
        # tracks as the other cameras (named ones never) see them.
        others = np.tile(w, (1, num_c, 1))
        others[[c for c, n in enumerate(self.names) if self.status[n].named]] = 0.0
        for c in range(num_c):
            others[c, c * num_t:(c + 1) * num_t] = 0.0
        uu, vv = np.tile(u, (1, num_c, 1)), np.tile(v, (1, num_c, 1))
        x = triangulate_dlt(uu, vv, others, self._projections, basis=self._basis)
        x, others = self._without_worst_view(x, uu, vv, others)
        support = self._support_px(x, uu, vv, others)
        # Two views place a point as well as their calibration and detections allow, and no
        # better: with four cameras or more, points of three views or more only.
        views = (others > 0).sum(axis=0)
        good = np.isfinite(x).all(axis=0) & (support < self.config.triangulation_gate_px) & (
            views >= min(3, num_c - 2))
        oldest = stamp_ns - int(cfg.window_s * NS_PER_S)
        for c, name in enumerate(self.names):
            if name not in due:
                continue
            block = slice(c * num_t, (c + 1) * num_t)
            tried = (w[c] > 0) & np.isfinite(x[:, block]).all(axis=0)
            ok = tried & good[block]
            if not ok.any():
                continue
            cam = self.cameras[name]
            points = np.moveaxis(x[:, block], 0, -1)[ok]                # [N, 3]
            in_cam = points @ cam.R.T + cam.t
            front = in_cam[:, 2] > 0
            observed = _bearings(np.stack([u[c][ok], v[c][ok]], axis=1))[front]
            predicted = (in_cam / np.linalg.norm(in_cam, axis=1, keepdims=True))[front]
            residual = np.linalg.norm(cam.project(points[front]) - px[c][ok][front], axis=1)
            self._added_ns[name] = stamp_ns
            self._windows[name].add(stamp_ns, observed, predicted, w[c][ok][front], residual,
                                    float(np.median(support[block][tried])), oldest)

    def _match(self, cam: Camera, poses: np.ndarray, joints: np.ndarray):
        """Return ``(tracks, detections)``: the tracks' projections matched to the people."""
        proj = cam.project(joints)                                     # [T, J, 2]
        with np.errstate(invalid='ignore'):
            size = np.nanmax(proj, axis=1) - np.nanmin(proj, axis=1)    # [T, 2]
        height = np.nan_to_num(np.max(size, axis=1), nan=0.0)
        diff = np.linalg.norm(proj[:, None] - poses[None, :, :, :2], axis=-1)   # [T, P, J]
        usable = np.isfinite(diff) & (poses[None, :, :, 2] >= self.config.min_confidence)
        shared = usable.sum(axis=2)
        mean = np.where(usable, diff, 0.0).sum(axis=2) / np.maximum(shared, 1)
        cost = np.where(shared >= 4, mean / np.maximum(height, 1.0)[:, None], np.nan)
        return gated_assignment(cost, self.config.match_gate)

    def _view_errors_px(self, x: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Return ``[C, K, J]``: the reprojection error (px) of each point in every camera."""
        ru, rv, depth = reproject(x, self._projections)
        focal = np.array([self.cameras[n].focal for n in self.names])[:, None, None]
        return np.where(depth > 0, np.hypot(ru - u, rv - v) * focal, np.inf)

    def _without_worst_view(self, x: np.ndarray, u: np.ndarray, v: np.ndarray,
                            w: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """
        Triangulate again without each point's worst view where it stands out.

        A turned camera pulls every triangulation it takes part in; where three views or more
        remain, its view is the one that disagrees most, by far, and is left out, so the other
        cameras' windows do not turn with it.
        """
        used = w > 0
        err = np.where(used, self._view_errors_px(x, u, v), -1.0)
        order = np.sort(err, axis=0)
        worst, second = order[-1], order[-2]
        drop = (used.sum(axis=0) >= 3) & (worst > self.config.outlier_view_px) & (
            worst > self.config.outlier_view_ratio * second)
        if not drop.any():
            return x, w
        w = np.where(drop[None] & (err == worst[None]), 0.0, w)
        x2 = triangulate_dlt(u, v, w, self._projections, basis=self._basis)
        return np.where(drop[None], x2, x), w

    def _support_px(self, x: np.ndarray, u: np.ndarray, v: np.ndarray,
                    others: np.ndarray) -> np.ndarray:
        """Return ``[K, J]``: each point's worst reprojection (px) in the views that made it."""
        err = self._view_errors_px(x, u, v)
        return np.where(others > 0, err, 0.0).max(axis=0)

    # ------------------------------------------------------------------ judging
    def _judge(self, stamp_ns: int) -> List[WatchEvent]:
        cfg = self.config
        events: List[WatchEvent] = []
        candidates = []
        named = frozenset(n for n in self.names if self.status[n].named)
        for name in self.names:
            st, win = self.status[name], self._windows[name]
            st.points = len(win.weight)
            if st.points < cfg.min_points or len(win.support_px) < cfg.min_sets or (
                    stamp_ns - win.since_ns < 0.9 * cfg.window_s * NS_PER_S):
                continue
            estimate = robust_rotation(win.observed, win.predicted, win.weight, win.estimate)
            win.estimate = estimate
            info = rotation_information(win.observed, win.predicted, win.weight, estimate,
                                        len(win.support_px))
            st.residual_px = float(np.median(win.residual_px))
            st.support_px = float(np.median([v for _, v in win.support_px]))
            base = st.baselines.setdefault(named - {name}, _Baseline(stamp_ns))
            if not base.add(estimate, st.residual_px, st.support_px, stamp_ns, cfg.baseline_s):
                continue
            st.support_ratio = st.support_px / max(base.support_px, 1e-6)
            drift = estimate @ base.rotation.T
            st.baseline_residual_px = base.residual_px
            st.drift_deg = rotation_angle_deg(drift)
            if not st.named and st.drift_deg <= st.threshold_deg:
                # The noise goes on being learned while the camera agrees, slowly (a bump is
                # a step, the wander of sparse views is not): noise_s of estimates.
                rate = min(1.0, cfg.interval_s / cfg.noise_s)
                base.noise2 = (1 - rate) * base.noise2 + rate * st.drift_deg ** 2
            st.threshold_deg = max(cfg.warn_deg, cfg.noise_factor * math.sqrt(base.noise2))
            st.drift_axis_deg = rotation_vector_deg(drift)
            st.drift_sigmas = math.sqrt(max(float(st.drift_axis_deg @ info @ st.drift_axis_deg),
                                            0.0))
            if st.named:
                events += self._follow_named(st, drift, stamp_ns)
                continue
            st.level = OK
            if st.drift_deg <= st.threshold_deg or st.drift_sigmas < cfg.min_sigmas:
                st.over_since_ns = None
                continue
            if st.over_since_ns is None:
                st.over_since_ns = stamp_ns
            if stamp_ns - st.over_since_ns >= cfg.hold_s * NS_PER_S:
                candidates.append(st)
        culprit = self._culprit(candidates)
        if culprit is not None:
            events.append(self._name(culprit, stamp_ns))
        return events

    def _culprit(self, candidates: List[CameraWatch]) -> Optional[CameraWatch]:
        """
        Return the one candidate to name, or None while it is not clear which.

        A bumped camera turns the triangulations it takes part in, so the other cameras drift
        too, less. With four cameras or more the culprit's drift leads; with three, the two
        others still agree with each other on its triangulations, while each of theirs holds
        the culprit.
        """
        if not candidates:
            return None
        judged = [st for st in self.status.values() if np.isfinite(st.threshold_deg)]
        worst = max(candidates, key=lambda c: c.drift_deg / c.threshold_deg)
        rest = [st.drift_deg / st.threshold_deg for st in judged if st is not worst]
        if len(judged) >= 4:
            lead = worst.drift_deg / worst.threshold_deg
            return worst if lead >= self.config.lead_ratio * max(rest) else None
        best = min(st.support_ratio for st in judged)
        supported = [c for c in candidates
                     if c.support_ratio <= self.config.support_ratio * best]
        return max(supported, key=lambda c: c.drift_deg / c.threshold_deg) if supported else None

    def _rig_changed(self, changed: str) -> None:
        """Start the other cameras' windows again: the cameras that place the people changed."""
        for other in self.names:
            if other != changed:
                self._windows[other].clear()
                self.status[other].over_since_ns = None

    def _agreeing(self, name: str) -> int:
        return sum(1 for n in self.names if n != name and not self.status[n].named
                   and self.status[n].baselines)

    def _name(self, st: CameraWatch, stamp_ns: int) -> WatchEvent:
        cfg = self.config
        st.named, st.over_since_ns, st.stable_since_ns = True, None, None
        st.level = ERROR if st.drift_deg > cfg.error_deg else WARN
        self._rig_changed(st.name)               # their windows held this camera's points
        ax = st.drift_axis_deg
        agreeing = self._agreeing(st.name)
        if cfg.mode == 'warn':
            todo = ('check its mount, then recalibrate it (mv3dpose calibrate --refine) or '
                    'set fusion.calibration_watch to correct')
        elif cfg.mode == 'exclude':
            todo = 'it is left out of the fusion until it agrees again'
        elif agreeing < cfg.min_agreeing:
            todo = (f'only {agreeing} other camera(s) agree with the rig (need '
                    f'{cfg.min_agreeing} to correct one): not corrected, '
                    + ('left out of the fusion' if st.drift_deg > cfg.error_deg else
                       f'still used (under {cfg.error_deg:g} deg)') + '; check its mount')
        else:
            todo = 'it is left out of the fusion while its correction is estimated'
        message = (f"camera '{st.name}' disagrees with the rig: turned {st.drift_deg:.2f} deg "
                   f'(about its x {ax[0]:+.2f}, y {ax[1]:+.2f}, z {ax[2]:+.2f} deg) since its '
                   f'baseline, found at the set stamped {stamp_ns / NS_PER_S:.3f} s; median '
                   f'reprojection {st.residual_px:.1f} px (baseline '
                   f'{st.baseline_residual_px:.1f} px); {todo}')
        return WatchEvent('named', st.name, stamp_ns, st.drift_deg, message)

    def _follow_named(self, st: CameraWatch, drift: np.ndarray,
                      stamp_ns: int) -> List[WatchEvent]:
        """Follow a named camera: it agrees again, or (correct mode) is corrected once stable."""
        cfg = self.config
        st.level = ERROR if st.drift_deg > cfg.error_deg else WARN
        if st.drift_deg < cfg.agree_ratio * st.threshold_deg:
            st.named, st.level, st.over_since_ns = False, OK, None
            self._rig_changed(st.name)
            return [WatchEvent('agrees', st.name, stamp_ns, st.drift_deg,
                               f"camera '{st.name}' agrees with the rig again (drift "
                               f'{st.drift_deg:.2f} deg at {stamp_ns / NS_PER_S:.3f} s)')]
        if cfg.mode != 'correct' or self._agreeing(st.name) < cfg.min_agreeing:
            return []
        last, st.last_estimate = st.last_estimate, drift
        if last is None or rotation_angle_deg(drift @ last.T) > cfg.stable_deg:
            st.stable_since_ns = stamp_ns
            return []
        if stamp_ns - st.stable_since_ns < cfg.stable_s * NS_PER_S:
            return []
        old = self.cameras[st.name]
        new = turned(old, drift)
        self.cameras[st.name] = new
        self._set_projections()
        self._windows[st.name].clear()
        self._rig_changed(st.name)
        moved = st.drift_deg
        st.named, st.level, st.corrections = False, OK, st.corrections + 1
        st.last_estimate = st.stable_since_ns = st.over_since_ns = None
        return [WatchEvent('corrected', st.name, stamp_ns, moved,
                           f"camera '{st.name}' corrected at {stamp_ns / NS_PER_S:.3f} s: "
                           f'turned {moved:.2f} deg about its centre to where the people put '
                           f'it (correction {st.corrections}); it rejoins the rig', new)]
