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

Live (``CausalFilter``): a per-joint constant-velocity alpha-beta filter. It uses only past
observations, has no steady-state lag on constant-velocity motion (the velocity term removes
the lag an exponential average would have), fills gaps of up to ``max_gap_s`` by prediction
(those joints are marked PREDICTED) and restarts a joint whose observation jumps by more than
``reset_m`` (a re-acquired or corrected joint is not dragged through space).

Offline (``gaussian_smooth``, ``smooth_track_sequence``): the paper's Gaussian smoothing with
sigma in frames. Gaps of up to ``max_gap_frames`` are first filled by linear interpolation,
then the convolution is normalised over the valid samples only, so missing samples never pull
the signal towards zero (the reference code's zero-bleed bug) and the ends are not attenuated.
"""

import dataclasses
from typing import Dict, List, Optional, Sequence, Tuple

from mv3dpose_ros.core.types import JointState, Track, TrackState
import numpy as np
from scipy.ndimage import gaussian_filter1d

# Joint states as uint8 scalars (the dtype of the state arrays; enum members are slow in numpy).
_MISSING, _TRIANGULATED, _PREDICTED = (np.uint8(s) for s in (
    JointState.MISSING, JointState.TRIANGULATED, JointState.PREDICTED))


class CausalFilter:
    """
    Per-joint alpha-beta filters of ``[T, J, D]`` positions (T tracks) over time.

    All rows are updated together at each stamp; ``reindex`` follows the tracker when tracks
    are born or deleted. A ``[J, D]`` input is treated as a single track.
    """

    def __init__(self, num_joints: int, alpha: float = 0.6, beta: float = 0.25,
                 max_gap_s: float = 0.3, reset_m: float = 0.5, dims: int = 3,
                 rows: int = 0) -> None:
        """Create the filter; ``alpha`` and ``beta`` in (0, 1], as per-update gains."""
        if not (0 < alpha <= 1 and 0 <= beta <= 1):
            raise ValueError(f'CausalFilter: need 0 < alpha <= 1 and 0 <= beta <= 1, '
                             f'got alpha={alpha}, beta={beta}')
        self.alpha, self.beta = float(alpha), float(beta)
        self.max_gap_s, self.reset_m = float(max_gap_s), float(reset_m)
        self._ones = np.ones(dims)          # sums over D as a product: cheaper than .sum(-1)
        self.x = np.full((rows, num_joints, dims), np.nan)
        self.v = np.zeros((rows, num_joints, dims))
        self.count = np.zeros((rows, num_joints), dtype=int)   # observations since (re)start
        self.last_seen = np.full((rows, num_joints), -np.inf)   # stamp of the last observation
        self.stamp: Optional[float] = None

    def reindex(self, previous: np.ndarray) -> None:
        """Rearrange rows: new row ``i`` continues old row ``previous[i]`` (-1 = a new track)."""
        previous = np.asarray(previous, dtype=int)
        if len(previous) == len(self.x) and previous.tolist() == list(range(len(previous))):
            return                                      # same tracks in the same rows
        new = previous < 0
        src = np.where(new, 0, previous)
        if len(self.x) == 0:
            shape = (len(previous),) + self.x.shape[1:]
            self.x, self.v = np.full(shape, np.nan), np.zeros(shape)
            self.count = np.zeros(shape[:2], dtype=int)
            self.last_seen = np.full(shape[:2], -np.inf)
            return
        self.x = np.where(new[:, None, None], np.nan, self.x[src])
        self.v = np.where(new[:, None, None], 0.0, self.v[src])
        self.count = np.where(new[:, None], 0, self.count[src])
        self.last_seen = np.where(new[:, None], -np.inf, self.last_seen[src])

    def update(self, z: np.ndarray, stamp: float) -> Tuple[np.ndarray, np.ndarray]:
        """
        Fold in observations ``z [T, J, D]`` (NaN = not observed) taken at ``stamp`` seconds.

        Returns the filtered positions (NaN where unknown) and the ``[T, J]`` uint8
        JointState: TRIANGULATED (observed now), PREDICTED (gap filled) or MISSING.
        """
        single = z.ndim == 2
        if single:
            z = z[None]
            if len(self.x) == 0:
                self.reindex(np.array([-1]))
        dt = 0.0 if self.stamp is None else max(stamp - self.stamp, 0.0)
        self.stamp = stamp
        obs = np.isfinite(z[..., 0])
        live = self.count > 0
        pred = self.x + self.v * dt
        resid = z - pred
        with np.errstate(invalid='ignore', divide='ignore'):
            jump = (resid * resid) @ self._ones > self.reset_m ** 2      # NaN -> False
            start = obs & (~live | jump)
            second = obs & ~start & (self.count == 1) & (dt > 0)
            restart = start | second                    # the position is the observation
            steady = obs & ~restart
            hold = ~obs & live & (stamp - self.last_seen <= self.max_gap_s + 1e-9)
            x = np.where(restart[..., None], z,
                         np.where(steady[..., None], pred + self.alpha * resid,
                                  np.where(hold[..., None], pred, np.nan)))
            gain = self.beta / dt if dt > 0 else 0.0
            v = np.where(second[..., None], (z - self.x) / (dt if dt > 0 else 1.0),
                         np.where(steady[..., None], self.v + gain * resid,
                                  np.where(hold[..., None], self.v, 0.0)))
        self.count = np.where(start, 1, np.where(obs, self.count + 1,
                                                 np.where(hold, self.count, 0)))
        self.last_seen = np.where(obs, stamp, self.last_seen)
        self.x, self.v = x, v
        state = np.where(obs, _TRIANGULATED, np.where(hold, _PREDICTED, _MISSING))
        if single:
            return x[0].copy(), state[0]
        return x, state


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
            position = tr.position
            if root_joints is not None:
                position = smooth[row, list(root_joints)].mean(axis=0)
            out[f][i] = dataclasses.replace(tr, joints=smooth[row].copy(), joint_state=state,
                                            confidence=conf, position=position)
    return out
