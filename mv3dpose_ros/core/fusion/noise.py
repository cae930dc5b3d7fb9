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
The 2D noise of the detector on this rig, estimated as sets come in, and what it means in 3D.

The noise per view (normalised units) is ``noise_gain`` times a running mean of the per-set
median reprojection error, corrected for the degrees of freedom of the views, starting from
``measurement_noise_norm``. A triangulated joint's per-axis variance is that noise squared
times its depth in the cameras that saw it, squared, divided by their number: the filters
smooth as much as the detector's noise on this rig calls for, on any data set.
"""

from typing import Optional

from mv3dpose_ros.core.fusion.config import FusionConfig
from mv3dpose_ros.core.geometry.triangulation import Triangulation
from mv3dpose_ros.core.tracking.tracker import centroid
import numpy as np

#: Floor of a joint's measurement variance [m^2]: (5 mm)^2.
MIN_VARIANCE = 0.005 ** 2


class NoiseModel:
    """The running 2D noise estimate of a rig and the measurement variance it gives."""

    def __init__(self, config: FusionConfig, depth_rows: np.ndarray) -> None:
        """Start from ``measurement_noise_norm``; ``depth_rows [C, 4]`` give depths per camera."""
        self.config = config
        self._depth_rows = depth_rows
        self._views = min(3, len(depth_rows))        # 2-view residuals say little about noise
        self._estimate, self._sets, self._calls = config.measurement_noise_norm, 0, 0

    @property
    def norm(self) -> float:
        """Return the 2D noise per view (normalised units) behind the measurement variance."""
        cfg = self.config
        if cfg.noise_gain <= 0 or self._sets == 0:
            return cfg.measurement_noise_norm
        return cfg.noise_gain * self._estimate

    def fold(self, tri: Triangulation) -> None:
        """Fold this set's median reprojection error into the running 2D noise estimate."""
        self._calls += 1
        if self.config.noise_gain <= 0 or (self._sets >= 100 and self._calls % 10):
            return                       # settled: every 10th set is enough (deterministic)
        n = tri.num_views
        ok = (n >= self._views) & (tri.error < np.inf)              # finite (NaN: False)
        count = int(np.count_nonzero(ok))
        if count < 5:
            return
        # DLT from n views leaves 2n - 3 of 2n degrees of freedom in the residuals; the median
        # of a 2D Gaussian error's length is 1.177 sigma.
        k = n[ok]
        e = tri.error[ok] * np.sqrt(2 * k / (2 * k - 3))
        sigma = float(np.partition(e, count // 2)[count // 2]) / 1.177
        self._sets += 1
        if self._sets == 1:
            self._estimate = sigma
        else:
            self._estimate += (sigma - self._estimate) / min(self._sets, 200)

    def variance(self, tri: Triangulation, centre: Optional[np.ndarray] = None) -> np.ndarray:
        """
        Return the ``[K, J]`` per-axis variance [m^2] of triangulated joints (NaN if none).

        noise^2 * mean depth^2 / views (``norm``, normalised units): a joint far from its
        cameras or seen by few of them is uncertain. ``centre [K, 3]``: the joints' centroids,
        if known.
        """
        if not len(tri.joints):
            return np.zeros(tri.joints.shape[:2])
        # depth of each candidate's centre in each camera: the joints of a person are at
        # about the same distance from a camera, compared with the distance itself
        if centre is None:
            centre = centroid(tri.joints)                                   # [K, 3]
        depth = centre @ self._depth_rows[:, :3].T + self._depth_rows[:, 3]  # [K, C]
        n = tri.num_views
        with np.errstate(invalid='ignore', divide='ignore'):
            mean_depth = (tri.used * depth.T[:, :, None]).sum(axis=0) / n   # [K, J]
            var = self.norm ** 2 * mean_depth * mean_depth / n
        return np.where(np.isfinite(tri.joints[..., 0]), np.maximum(var, MIN_VARIANCE), np.nan)
