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
Temporal smoothing of joint trajectories (paper, step 4), live and offline.

Live (``JointKalman``): per-joint constant-velocity Kalman filters with measurement noise
from the triangulation geometry, an innovation gate against single-frame outliers, velocities
that start at zero, and joints held (not extrapolated) in gaps with growing variance. The
tracker owns them (``core.tracking.tracker``), so track motion comes from the filtered state.

Fixed lag (``FixedLagSmoother``): each set's tracks re-estimated from the accepted
observations up to ``lag`` sets later, published that much later with their own stamps.

Offline (``gaussian_smooth``, ``smooth_track_sequence``): the paper's Gaussian smoothing with
sigma in frames. Gaps of up to ``max_gap_frames`` are first filled by linear interpolation,
then the convolution is normalised over the valid samples only, so missing samples never pull
the signal towards zero (the reference code's zero-bleed bug) and the ends are not attenuated.
"""

import dataclasses
from typing import Dict, List, Optional, Sequence, Tuple

from mv3dpose_ros.core.types import JointState, PositionSource, Track, TrackState
import numpy as np
from scipy.ndimage import gaussian_filter1d

# Joint states as uint8 scalars (the dtype of the state arrays; enum members are slow in numpy).
_MISSING, _TRIANGULATED, _PREDICTED = (np.uint8(s) for s in (
    JointState.MISSING, JointState.TRIANGULATED, JointState.PREDICTED))
_XYZ = np.ones(3)          # sums over x, y, z as a product with ones (cheaper than .sum(-1))


@dataclasses.dataclass
class KalmanUpdate:
    """Estimates of ``JointKalman.update`` at one stamp, ``[T, J]`` rows."""

    joints: np.ndarray      # [T, J, 3] metres, NaN where MISSING (held in gaps)
    state: np.ndarray       # [T, J] uint8 JointState: TRIANGULATED (updated now), PREDICTED
    #                         (held), MISSING
    variance: np.ndarray    # [T, J] per-axis position variance [m^2], NaN where MISSING
    accepted: np.ndarray    # [T, J] bool, an observation updated the joint now


@dataclasses.dataclass
class RayUpdate:
    """What ``JointKalman.update_rays`` did, ``[N, J]`` rows of the rows it was given."""

    accepted: np.ndarray    # [N, J] bool, the ray updated the joint
    point: np.ndarray       # [N, J, 3] the ray's point nearest the prediction, NaN if not
    variance: np.ndarray    # [N, J] its per-axis variance across the ray [m^2], NaN if not


class JointKalman:
    """
    Per-joint constant-velocity Kalman filters of ``[T, J, 3]`` positions (T tracks) over time.

    Each joint has the state (position, velocity) per axis with one isotropic covariance
    shared by the three axes (``p_xx``, ``p_xv``, ``p_vv`` in m^2, m^2/s, m^2/s^2), driven by
    white acceleration noise of spectral density ``accel_noise`` (m^2/s^3). The measurement
    variance of each joint comes with the observation (from the triangulation geometry).

    - A joint starts at its first observation with velocity 0 (variance ``init_speed_mps``^2),
      not from the difference of two noisy samples.
    - An observation whose squared Mahalanobis innovation exceeds ``gate_chi2`` (chi-square, 3
      degrees of freedom) is rejected as an outlier; after ``reinit_after`` consecutive
      rejections the joint restarts at the observation (the person really moved).
    - In a gap the joint is HELD at its last estimate (not extrapolated) with a variance that
      grows with the time since its last update; after ``max_gap_s`` it is MISSING and
      restarts at its next observation.

    All rows are updated together; ``reindex`` follows the tracker when tracks are born or
    deleted.
    """

    def __init__(self, num_joints: int, accel_noise: float = 2.0, init_speed_mps: float = 1.0,
                 gate_chi2: float = 16.3, reinit_after: int = 2, max_gap_s: float = 0.3,
                 rows: int = 0) -> None:
        """Create the filters (``rows`` tracks of ``num_joints`` joints, all unknown)."""
        if not (accel_noise > 0 and init_speed_mps >= 0 and gate_chi2 > 0
                and reinit_after >= 1 and max_gap_s >= 0):
            raise ValueError(f'JointKalman: need accel_noise > 0, init_speed_mps >= 0, '
                             f'gate_chi2 > 0, reinit_after >= 1, max_gap_s >= 0; got '
                             f'{accel_noise}, {init_speed_mps}, {gate_chi2}, {reinit_after}, '
                             f'{max_gap_s}')
        self.q, self.v0 = float(accel_noise), float(init_speed_mps) ** 2
        self.gate, self.reinit_after = float(gate_chi2), int(reinit_after)
        self.max_gap_s = float(max_gap_s)
        self.num_joints = int(num_joints)
        self._alloc(rows)

    def _alloc(self, rows: int) -> None:
        shape = (rows, self.num_joints)
        self.x = np.full(shape + (3,), np.nan)
        self.v = np.zeros(shape + (3,))
        self.p_xx, self.p_xv, self.p_vv = np.zeros(shape), np.zeros(shape), np.zeros(shape)
        self.t = np.full(shape, -np.inf)                 # stamp of the last update
        self.count = np.zeros(shape, dtype=np.int64)     # updates since the (re)start, 0 = none
        self.rejects = np.zeros(shape, dtype=np.int64)   # consecutive rejected observations

    def __len__(self) -> int:
        """Return the number of rows (tracks)."""
        return len(self.x)

    def reindex(self, previous: np.ndarray) -> None:
        """Rearrange rows: new row ``i`` continues old row ``previous[i]`` (-1 = a new track)."""
        previous = np.asarray(previous, dtype=np.int64)
        if len(previous) == len(self.x) and previous.tolist() == list(range(len(previous))):
            return                                      # same tracks in the same rows
        old = (self.x, self.v, self.p_xx, self.p_xv, self.p_vv, self.t, self.count,
               self.rejects)
        self._alloc(len(previous))
        keep = previous >= 0
        if keep.any():
            src, dst = previous[keep], np.nonzero(keep)[0]
            for new, arr in zip((self.x, self.v, self.p_xx, self.p_xv, self.p_vv, self.t,
                                 self.count, self.rejects), old):
                new[dst] = arr[src]

    def predict_variance(self, stamp: float) -> np.ndarray:
        """Return the ``[T, J]`` per-axis variance of each held joint at ``stamp``."""
        dt = np.maximum(stamp - self.t, 0.0)
        with np.errstate(invalid='ignore'):
            var = self.p_xx + 2 * dt * self.p_xv + dt * dt * self.p_vv \
                + self.q * dt * dt * dt / 3
            # holding instead of moving adds the squared drift of the velocity estimate
            speed2 = (self.v * self.v) @ _XYZ / 3
            return var + speed2 * dt * dt

    def update(self, z: np.ndarray, r: np.ndarray, stamp: float) -> KalmanUpdate:
        """
        Fold in observations ``z [T, J, 3]`` (NaN = none) of variance ``r [T, J]`` (m^2/axis).

        Returns the estimates at ``stamp``: positions (NaN where MISSING), JointState, per-axis
        variance (NaN where MISSING) and which observations were accepted.
        """
        obs = np.isfinite(z[..., 0]) & np.isfinite(r)
        dt = stamp - self.t                                       # inf for unknown joints
        live = (self.count > 0) & (dt <= self.max_gap_s + 1e-9)
        dt = np.where(live, np.maximum(dt, 0.0), 0.0)
        xp, pxx, pxv, pvv = _predict(self.q, self.x, self.v, self.p_xx, self.p_xv, self.p_vv,
                                     dt)
        with np.errstate(invalid='ignore'):
            resid = z - xp
            s = pxx + r
            d2 = (resid * resid) @ _XYZ / s                       # NaN where not observed
            seen = obs & live
            accept = seen & (d2 <= self.gate)
            rejected = seen & ~accept
            rejects = np.where(rejected, self.rejects + 1, 0)
            start = obs & (~live | (rejects >= self.reinit_after))
            accept &= ~start
            k1, k2 = pxx / s, pxv / s
        a3, s3 = accept[..., None], start[..., None]
        self.x = np.where(s3, z, np.where(a3, xp + k1[..., None] * resid, self.x))
        held_v = np.where(live[..., None], self.v, 0.0)
        self.v = np.where(s3, 0.0, np.where(a3, self.v + k2[..., None] * resid, held_v))
        gain = 1 - k1
        self.p_xx = np.where(start, r, np.where(accept, gain * pxx, self.p_xx))
        self.p_xv = np.where(start, 0.0, np.where(accept, gain * pxv, self.p_xv))
        self.p_vv = np.where(start, self.v0, np.where(accept, pvv - k2 * pxv, self.p_vv))
        upd = accept | start
        self.t = np.where(upd, stamp, self.t)
        self.count = np.where(start, 1, np.where(accept, self.count + 1,
                                                 np.where(live, self.count, 0)))
        self.rejects = np.where(start, 0, rejects)
        held = live & ~upd
        state = np.where(upd, _TRIANGULATED, np.where(held, _PREDICTED, _MISSING))
        # a held joint: the predicted variance plus the drift it is not moved by (see
        # predict_variance; dt is the time since its last update)
        var = np.where(upd, self.p_xx, np.where(
            held, pxx + (self.v * self.v) @ _XYZ / 3 * dt * dt, np.nan))
        x = np.where((upd | held)[..., None], self.x, np.nan)
        return KalmanUpdate(joints=x, state=state, variance=var, accepted=upd)

    def update_rays(self, rows: np.ndarray, origin: np.ndarray, direction: np.ndarray,
                    noise_norm: float, stamp: float, gate_chi2: float,
                    min_variance: float = 0.0, same_instant_s: float = 0.0) -> RayUpdate:
        """
        Fold in one camera's view of joints: each 2D keypoint is a ray from ``origin``.

        ``rows [N]`` are distinct filter rows, ``direction [N, J, 3]`` unit ray directions in
        the world (NaN: not seen), ``noise_norm`` the 2D noise of one view (px / focal), so
        the variance across the ray is ``(noise_norm * depth)^2`` at the joint's depth. A ray
        says nothing along itself: the update moves the joint across the ray only, with the
        residual from the predicted joint to its nearest point on the ray, gated at
        ``gate_chi2`` (2 degrees of freedom). The isotropic covariance keeps the mean of the
        three axes' (two shrink, one does not), so repeated views of one camera do not make
        the depth look known. Only live joints are updated (a ray cannot place a new joint).

        A joint updated after ``stamp`` (a late message) is left alone: retrodicted with a
        velocity that lags, the residual pulls the joint back towards where the person was
        (measured: a one-step out-of-sequence update made the joints worse), so a late view
        counts where it is the newest news, e.g. for joints held or tracks coasting. A joint
        updated at most ``same_instant_s`` after ``stamp`` counts as updated at ``stamp``
        (views of one instant from free-running cameras differ by a few milliseconds).
        """
        rows = np.asarray(rows, dtype=np.int64)
        x, v, t = self.x[rows], self.v[rows], self.t[rows]
        count = self.count[rows]
        dt = stamp - t
        seen = np.isfinite(direction[..., 0])
        live = (count > 0) & (dt >= -same_instant_s) & (dt <= self.max_gap_s + 1e-9) & seen
        dt = np.where(live, np.maximum(dt, 0.0), 0.0)
        p_xx, p_xv, p_vv = self.p_xx[rows], self.p_xv[rows], self.p_vv[rows]
        xp, pxx, pxv, pvv = _predict(self.q, x, v, p_xx, p_xv, p_vv, dt)
        with np.errstate(invalid='ignore'):
            w = xp - origin
            depth = (w * direction) @ _XYZ                        # along the ray, [N, J]
            resid = direction * depth[..., None] - w              # to the nearest ray point
            r = np.maximum((noise_norm * depth) ** 2, min_variance)
            s = pxx + r
            d2 = (resid * resid) @ _XYZ / s
            accept = live & (depth > 0) & (d2 <= gate_chi2)
            k1, k2 = pxx / s, pxv / s
        a3 = accept[..., None]
        self.x[rows] = np.where(a3, xp + k1[..., None] * resid, x)
        # along the ray the velocity keeps what the last triangulations taught it (decaying
        # it there was measured worse: a walking person's depth then lags behind)
        self.v[rows] = np.where(a3, v + k2[..., None] * resid, v)
        two_thirds = 2.0 / 3.0
        shrink = 1 - two_thirds * k1
        self.p_xx[rows] = np.where(accept, pxx * shrink, p_xx)
        self.p_xv[rows] = np.where(accept, pxv * shrink, p_xv)
        self.p_vv[rows] = np.where(accept, pvv - two_thirds * k2 * pxv, p_vv)
        self.t[rows] = np.where(accept, np.maximum(stamp, t), t)
        self.count[rows] = np.where(accept, count + 1, count)
        point = np.where(a3, xp + resid, np.nan)
        return RayUpdate(accepted=accept, point=point, variance=np.where(accept, r, np.nan))

    def body_velocity(self, rows: Optional[np.ndarray] = None) -> np.ndarray:
        """
        Return the ``[T, 3]`` body velocity: inverse-variance mean of the joint velocities.

        Only joints updated at least twice since their (re)start count; NaN where none has.
        """
        w = np.where(self.count >= 2, 1.0 / np.maximum(self.p_vv, 1e-12), 0.0)
        total = w.sum(axis=1)
        with np.errstate(invalid='ignore', divide='ignore'):
            vel = (w[..., None] * self.v).sum(axis=1) / total[:, None]
        return np.where((total > 0)[:, None], vel, np.nan)


def _predict(q: float, x: np.ndarray, v: np.ndarray, p_xx: np.ndarray, p_xv: np.ndarray,
             p_vv: np.ndarray, dt: np.ndarray):
    """Return the constant-velocity prediction ``(x, p_xx, p_xv, p_vv)`` ``dt`` ahead."""
    qdt = q * dt
    pxv = p_xv + dt * (p_vv + qdt / 2)
    pxx = p_xx + dt * (p_xv + pxv - qdt * dt / 6)     # = + 2dt pxv + dt^2 pvv + q dt^3 / 3
    pvv = p_vv + qdt
    return x + v * dt[..., None], pxx, pxv, pvv


def interpolate_gaps(traj: np.ndarray, max_gap: int) -> Tuple[np.ndarray, np.ndarray]:
    """
    Fill interior gaps of at most ``max_gap`` samples by linear interpolation.

    ``traj [T, J, D]`` with NaN rows for missing samples (a sample is valid when all its D
    values are finite). Returns the filled copy and the ``[T, J]`` mask of filled samples.
    Gaps at the ends or longer than ``max_gap`` stay NaN.
    """
    traj = np.asarray(traj, dtype=float)
    num_t = traj.shape[0]
    valid = np.isfinite(traj).all(axis=-1)                          # [T, J]
    if num_t == 0:
        return traj.copy(), valid & False
    t = np.arange(num_t)[:, None]
    prev = np.maximum.accumulate(np.where(valid, t, -1), axis=0)
    nxt = np.minimum.accumulate(np.where(valid, t, num_t)[::-1], axis=0)[::-1]
    fill = ~valid & (prev >= 0) & (nxt < num_t) & (nxt - prev - 1 <= max_gap)
    out = traj.copy()
    if fill.any():
        ti, ji = np.nonzero(fill)
        p, n = prev[ti, ji], nxt[ti, ji]
        w = ((ti - p) / (n - p))[:, None]
        out[ti, ji] = (1 - w) * traj[p, ji] + w * traj[n, ji]
    return out, fill


def gaussian_smooth(traj: np.ndarray, sigma_frames: float = 2.0,
                    max_gap_frames: int = 10) -> Tuple[np.ndarray, np.ndarray]:
    """
    Smooth ``traj [T, J, D]`` over time with a Gaussian (sigma in frames), offline.

    Short gaps are interpolated first (see ``interpolate_gaps``); the convolution is then
    normalised by the convolved validity mask, so only valid samples contribute and the
    output is NaN wherever the (filled) input is. Returns ``(smoothed, filled [T, J])``.
    """
    filled, interp = interpolate_gaps(traj, max_gap_frames)
    valid = np.isfinite(filled).all(axis=-1)
    if sigma_frames <= 0 or len(filled) == 0:
        return filled, interp
    m = valid.astype(float)
    num = gaussian_filter1d(np.where(valid[..., None], filled, 0.0), sigma_frames, axis=0,
                            mode='constant', cval=0.0)
    den = gaussian_filter1d(m, sigma_frames, axis=0, mode='constant', cval=0.0)
    with np.errstate(invalid='ignore', divide='ignore'):
        out = num / den[..., None]
    out[~valid] = np.nan
    return out, interp


def smooth_track_sequence(frames: Sequence[Sequence[Track]], sigma_frames: float = 2.0,
                          max_gap_frames: int = 10,
                          root_joints: Optional[Tuple[int, int]] = None) -> List[List[Track]]:
    """
    Apply ``gaussian_smooth`` to every track of a finished run (batch mode).

    ``frames`` are the per-frame outputs of ``Fusion.step`` (run without causal smoothing).
    Only TRIANGULATED joints count as observations; joints filled by interpolation come out
    PREDICTED, joints in longer gaps MISSING. DELETED tombstones pass through unchanged. With
    ``root_joints`` (left_hip, right_hip indices) the track position is recomputed.
    """
    spans: Dict[int, List[Tuple[int, int]]] = {}
    for f, tracks in enumerate(frames):
        for i, tr in enumerate(tracks):
            if tr.state != TrackState.DELETED:
                spans.setdefault(tr.track_id, []).append((f, i))
    out = [list(tracks) for tracks in frames]
    for where in spans.values():
        first = frames[where[0][0]][where[0][1]]
        num_j = first.num_joints
        traj = np.full((len(where), num_j, 4), np.nan)
        for row, (f, i) in enumerate(where):
            tr = frames[f][i]
            obs = tr.joint_state == JointState.TRIANGULATED
            traj[row, obs, :3] = tr.joints[obs]
            traj[row, obs, 3] = tr.confidence[obs]
        smooth, interp = gaussian_smooth(traj, sigma_frames, max_gap_frames)
        conf_all = np.clip(np.nan_to_num(smooth[..., 3]), 0.0, 1.0)
        smooth = smooth[..., :3]
        for row, (f, i) in enumerate(where):
            tr = frames[f][i]
            valid = np.isfinite(smooth[row]).all(axis=-1)
            state = np.where(valid, JointState.TRIANGULATED, JointState.MISSING).astype(np.uint8)
            state[interp[row]] = JointState.PREDICTED
            conf = np.where(valid, conf_all[row], 0.0)
            position, source = tr.position, tr.position_source
            if root_joints is not None:
                hips = smooth[row, list(root_joints)].mean(axis=0)
                if np.isfinite(hips).all():      # else the live root (e.g. the body centre)
                    position, source = hips, PositionSource.HIPS
            out[f][i] = dataclasses.replace(tr, joints=smooth[row].copy(), joint_state=state,
                                            confidence=conf, position=position,
                                            position_source=source)
    return out


class FixedLagSmoother:
    """
    Fixed-lag smoothing of a live track stream: each set comes out ``lag`` sets later.

    ``push(key, stamp, tracks)`` takes the tracks published for one set (public ids) and
    returns the set ``lag`` pushes earlier, re-estimated with what came after it, or None
    while the window fills; ``flush()`` returns the sets still held (end of a run, reset).
    The tracks, their states and ids are those of the live output; only joints, root
    position, velocity and variances change. Each joint is a local linear fit (position and
    velocity at the set's stamp) to the observations the joint filters accepted within
    ``back`` sets before and ``lag`` sets after, weighted by a Gaussian of ``sigma_sets`` sets
    and by the inverse measurement variance. A joint not observed at the set but observed on
    both sides becomes PREDICTED (interpolated); one without support keeps its live value.
    ``lag = 0`` passes sets straight through.
    """

    def __init__(self, lag: int = 3, back: Optional[int] = None,
                 sigma_sets: float = 2.0, root_joints: Optional[Tuple[int, int]] = None
                 ) -> None:
        """Create an empty smoother (``back`` defaults to ``2 * lag``)."""
        if lag < 0 or sigma_sets <= 0:
            raise ValueError(f'FixedLagSmoother: need lag >= 0 and sigma_sets > 0, got '
                             f'lag={lag}, sigma_sets={sigma_sets}')
        self.lag = int(lag)
        self.back = 2 * self.lag if back is None else int(back)
        self.sigma = float(sigma_sets)
        self.root = root_joints
        self._sets: List[Tuple[object, float, List[Track]]] = []
        self._done = 0                    # sets of self._sets already returned

    def push(self, key: object, stamp: float, tracks: Sequence[Track], smooth: bool = True
             ) -> Optional[Tuple[object, float, List[Track]]]:
        """
        Add one set; return ``(key, stamp, tracks)`` of the set ``lag`` pushes earlier.

        With ``smooth=False`` that set's tracks are returned as pushed (same ids and states),
        not re-estimated: for a consumer that needs none now. The window is kept either way,
        so later sets come out exactly as if every set had been smoothed.
        """
        self._sets.append((key, float(stamp), list(tracks)))
        if len(self._sets) - self._done <= self.lag:
            return None
        out = self._smooth(self._done) if smooth else self._sets[self._done]
        self._done += 1
        drop = max(0, self._done - self.back)
        if drop:
            del self._sets[:drop]
            self._done -= drop
        return out

    def flush(self) -> List[Tuple[object, float, List[Track]]]:
        """Return every set not yet returned (smoothed with what is known) and clear."""
        out = [self._smooth(k) for k in range(self._done, len(self._sets))]
        self._sets, self._done = [], 0
        return out

    def _smooth(self, k: int) -> Tuple[object, float, List[Track]]:
        key, stamp, tracks = self._sets[k]
        if self.lag == 0:
            return key, stamp, tracks
        lo, hi = max(0, k - self.back), min(len(self._sets), k + self.lag + 1)
        window = self._sets[lo:hi]
        by_id = [{t.track_id: t for t in s[2] if t.state != TrackState.DELETED}
                 for s in window]
        offsets = np.arange(lo, hi) - k
        kernel = np.exp(-0.5 * (offsets / self.sigma) ** 2)
        tau = np.array([s[1] for s in window]) - stamp
        out = []
        for tr in tracks:
            if tr.state == TrackState.DELETED or tr.measurement is None:
                out.append(tr)
                continue
            out.append(self._smooth_track(tr, [m.get(tr.track_id) for m in by_id], kernel,
                                          tau, offsets))
        return key, stamp, out

    def _smooth_track(self, tr: Track, seq: List[Optional[Track]], kernel: np.ndarray,
                      tau: np.ndarray, offsets: np.ndarray) -> Track:
        num_j = tr.num_joints
        z = np.full((len(seq), num_j, 3), np.nan)
        r = np.full((len(seq), num_j), np.nan)
        for i, t in enumerate(seq):
            if t is not None and t.measurement is not None:
                z[i], r[i] = t.measurement, t.measurement_variance
        ok = np.isfinite(z[..., 0]) & np.isfinite(r) & (r > 0)
        w = np.where(ok, kernel[:, None] / np.where(ok, r, 1.0), 0.0)            # [W, J]
        tt = tau[:, None]
        s0, s1, s2 = w.sum(0), (w * tt).sum(0), (w * tt * tt).sum(0)
        zz = np.where(ok[..., None], z, 0.0)
        sz = (w[..., None] * zz).sum(0)
        stz = (w[..., None] * tt[..., None] * zz).sum(0)
        det = s0 * s2 - s1 * s1
        before = (ok & (offsets < 0)[:, None]).any(0)
        after = (ok & (offsets > 0)[:, None]).any(0)
        now = ok[offsets == 0].any(0) if (offsets == 0).any() else np.zeros(num_j, bool)
        # a line needs support on both sides of the stamp (or at it): no extrapolation
        line = (det > 1e-12 * np.maximum(s0 * s2, 1e-300)) & (now | (before & after))
        with np.errstate(invalid='ignore', divide='ignore'):
            pos_line = (s2[:, None] * sz - s1[:, None] * stz) / det[:, None]
            vel_line = (s0[:, None] * stz - s1[:, None] * sz) / det[:, None]
            var_line = s2 / det
            pos_mean = sz / s0[:, None]
        mean = ~line & now                          # one stamp only: its weighted mean
        joints = np.where(line[:, None], pos_line,
                          np.where(mean[:, None], pos_mean, tr.joints))
        var = tr.joint_variance if tr.joint_variance is not None else np.full(num_j, np.nan)
        var = np.where(line, var_line, np.where(mean, 1.0 / np.where(mean, s0, 1.0), var))
        state = np.where(now, _TRIANGULATED,
                         np.where(line, _PREDICTED, tr.joint_state)).astype(np.uint8)
        confidence = np.where((state == _PREDICTED) & (tr.joint_state == _MISSING),
                              0.5 * np.max(tr.confidence, initial=0.0), tr.confidence)
        position, velocity, cov = tr.position, tr.velocity, tr.position_covariance
        source = tr.position_source
        if self.root is not None:
            left, right = self.root
            hips = (joints[left] + joints[right]) / 2
            if np.isfinite(hips).all():    # else the live root (e.g. the body centre) stays
                position, source = hips, PositionSource.HIPS
                cov = (var[left] + var[right]) / 4 * np.eye(3)
            if line[left] and line[right]:
                velocity = (vel_line[left] + vel_line[right]) / 2
        return dataclasses.replace(tr, joints=joints, joint_state=state, joint_variance=var,
                                   confidence=confidence, position=position,
                                   velocity=velocity, position_covariance=cov,
                                   position_source=source)
