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
The parameters of ``Fusion`` and how they reach the tracker.

``FusionConfig`` names every parameter once, in the units of its name; ``tracker_config`` is
the one place that maps the tracking ones onto ``TrackerConfig``'s (shorter) names and derives
the tracker's rig-dependent values.
"""

from dataclasses import asdict, dataclass

from mv3dpose_ros.core.tracking.tracker import TrackerConfig
from mv3dpose_ros.core.types import CALIBRATION_WATCH_MODES
import numpy as np

SMOOTHING_MODES = ('causal', 'none')


@dataclass
class FusionConfig:
    """Parameters of ``Fusion`` (all defaulted; units in the names, ``_norm`` = px / focal)."""

    # 2D input
    min_joint_confidence: float = 0.1       # keypoints below this count as missing
    min_pose_joints: int = 4                # 2D poses with fewer visible joints are ignored
    # association (paper: theta)
    epipolar_threshold_norm: float = 0.045  # mean symmetric epipolar distance gate
    min_shared_joints: int = 3              # joints two views must share for a valid cost
    max_reference_views: int = 4            # member views per candidate used in the cost
    min_views: int = 2                      # cameras a candidate needs to be triangulated
    # triangulation
    reprojection_gate_norm: float = 0.03    # max reprojection error of a view of a joint
    swap_check: bool = True                 # undo left/right swaps in single views
    swap_ratio: float = 0.5                 # swapped labels must fit this much better
    bone_check: bool = True                 # reject joints of implausibly long/short bones
    merge_distance_m: float = 0.25          # candidates closer than this are one person
    min_candidate_joints: int = 5           # triangulated joints a 3D pose needs
    # tracking (paper: tau)
    tracking_gate_m: float = 0.2            # mean joint distance to continue a track
    tracking_gate_growth_mps: float = 1.0   # gate widening per second since last observed
    tracking_recovery_gate_m: float = 0.5   # second-chance gate before starting a new track
    tracking_prediction: bool = True        # constant-velocity prediction of the root
    confirm_hits: int = 3                   # observations before a track is CONFIRMED
    max_coast_s: float = 3.0                # unobserved time before a track is DELETED: a
    #                                         person lost for less is found again with its id
    confirm_at_birth_ratio: float = 0.6     # a new track with this share of the layout's joints
    #                                         triangulated from >= min(3, cameras) views is
    #                                         CONFIRMED at once (> 1: never)
    publish_coast_s: float = 0.15           # COASTING tracks are published this long, then
    #                                         withheld until recovered or deleted
    min_birth_joints: int = 6               # triangulated joints to start a new track
    min_birth_cameras_in_view: int = 3      # cameras whose image must contain a new track's
    #                                         centroid (capped at cameras - 1): no tracks are
    #                                         started outside the rig's shared working volume
    min_birth_view_ratio: float = 0.5       # a new track's views / cameras that should see it
    # per-joint Kalman filters (always run: the tracker's motion comes from them)
    smoothing: str = 'causal'               # output 'causal' (filtered joints) or 'none'
    #                                         (accepted raw triangulations, held in gaps)
    measurement_noise_norm: float = 0.008   # 2D noise per view (px / focal) until estimated
    noise_gain: float = 1.5                 # 2D noise = gain * the noise estimated from the
    #                                         reprojection errors (0: measurement_noise_norm)
    accel_noise: float = 1.0                # white acceleration noise density [m^2/s^3]
    innovation_gate_chi2: float = 16.3      # reject an observation beyond this (3 dof, 99.9 %)
    reinit_after: int = 2                   # consecutive rejections before a joint restarts
    max_gap_s: float = 0.3                  # joints are held for at most this long
    # every observation counts: single views update the tracks they belong to
    view_updates: bool = True               # 2D keypoints no >= 2-view triangulation used
    #                                         update existing tracks as rays (False: only
    #                                         joints triangulated in one set do, the paper's)
    view_min_joints: int = 3                # joints a view must update to observe a track
    view_only_s: float = 1.0                # single views keep a track observed this long
    #                                         after its last triangulated match (depth drifts)
    tentative_coast_s: float = 0.25         # a TENTATIVE track outlives sets that miss a camera
    #                                         and it this long (not every sparse set sees a
    #                                         birth; a complete set without it deletes it)
    view_gate_chi2: float = 13.8            # ray innovation gate (chi-square, 2 dof, 99.9 %)
    calibration_watch: str = 'correct'      # each camera's pose checked against the rig's
    #                                         people (core.selfcal.watch): off, warn, exclude
    #                                         (a turned camera left out until it agrees) or
    #                                         correct (left out, then turned back)
    calibration_watch_deg: float = 1.0      # rotation since its baseline that names a camera

    def validate(self) -> None:
        """Raise ValueError naming the first out-of-range field."""
        positive = ('epipolar_threshold_norm', 'reprojection_gate_norm', 'tracking_gate_m',
                    'measurement_noise_norm', 'accel_noise', 'innovation_gate_chi2')
        non_negative = ('min_joint_confidence', 'swap_ratio', 'merge_distance_m',
                        'min_birth_view_ratio', 'tracking_gate_growth_mps',
                        'tracking_recovery_gate_m', 'max_coast_s', 'max_gap_s',
                        'confirm_at_birth_ratio', 'publish_coast_s', 'noise_gain',
                        'tentative_coast_s', 'view_only_s')
        positive += ('calibration_watch_deg',)
        at_least_one = ('min_pose_joints', 'min_shared_joints', 'max_reference_views',
                        'min_candidate_joints', 'confirm_hits', 'min_birth_joints',
                        'min_birth_cameras_in_view', 'reinit_after', 'view_min_joints')
        for name, value in asdict(self).items():
            if isinstance(value, bool) or name in ('smoothing', 'calibration_watch'):
                continue
            if not isinstance(value, (int, float)) or not np.isfinite(value):
                raise ValueError(f'FusionConfig.{name} must be a finite number, got {value!r}')
            if name in positive and value <= 0:
                raise ValueError(f'FusionConfig.{name} must be > 0, got {value}')
            if name in non_negative and value < 0:
                raise ValueError(f'FusionConfig.{name} must be >= 0, got {value}')
            if name in at_least_one and value < 1:
                raise ValueError(f'FusionConfig.{name} must be >= 1, got {value}')
        if self.min_views < 2:
            raise ValueError(f'FusionConfig.min_views must be >= 2 (triangulation needs two '
                             f'views), got {self.min_views}')
        if self.calibration_watch not in CALIBRATION_WATCH_MODES:
            raise ValueError(f'FusionConfig.calibration_watch must be one of '
                             f'{CALIBRATION_WATCH_MODES}, got {self.calibration_watch!r}')
        if self.smoothing not in SMOOTHING_MODES:
            raise ValueError(f'FusionConfig.smoothing must be one of {SMOOTHING_MODES}, '
                             f'got {self.smoothing!r}')

    def tracker_config(self, num_cameras: int) -> TrackerConfig:
        """
        Return the tracker's parameters for a rig of ``num_cameras``.

        Renamed on the way: ``tracking_gate_m`` -> ``gate_m``, ``tracking_gate_growth_mps`` ->
        ``gate_growth_mps``, ``tracking_recovery_gate_m`` -> ``recovery_gate_m``,
        ``tracking_prediction`` -> ``predict``, ``innovation_gate_chi2`` -> ``gate_chi2``.
        Derived: a track is lost (matched after the others) once it is not published
        (``publish_coast_s``, at least 0.3 s), and confirmation needs min(3, cameras - 1)
        cameras behind its 3D poses.
        """
        return TrackerConfig(
            gate_m=self.tracking_gate_m, gate_growth_mps=self.tracking_gate_growth_mps,
            recovery_gate_m=self.tracking_recovery_gate_m,
            min_shared_joints=self.min_shared_joints, predict=self.tracking_prediction,
            confirm_hits=self.confirm_hits, max_coast_s=self.max_coast_s,
            min_birth_joints=self.min_birth_joints, accel_noise=self.accel_noise,
            gate_chi2=self.innovation_gate_chi2, reinit_after=self.reinit_after,
            max_gap_s=self.max_gap_s, tentative_coast_s=self.tentative_coast_s,
            lost_after_s=max(self.publish_coast_s, 0.3),
            confirm_views=max(2, min(3, num_cameras - 1)))
