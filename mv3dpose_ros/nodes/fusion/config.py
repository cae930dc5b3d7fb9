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
fusion_node's parameters as config dataclasses, and the checks that make them a setup.

``FusionNodeParams`` is the single source of the node's parameter names, defaults and
descriptions (each field's trailing comment; ``ros.params.declare_config`` declares them,
fields marked ``dynamic`` may change at run time). ``check_setup`` turns the values into a
``FusionSetup``: the rig loaded, the cameras, layout and limits checked, the sync and fusion
configs completed by ``core.live.config`` (the parameters themselves are left as read), and
every problem that prevents the node from starting raised as ``ConfigError`` naming the
parameter.
"""

from dataclasses import dataclass, field
import math
import os
from typing import Dict, List, Sequence, Tuple

from mv3dpose_ros.core.fusion.pipeline import FusionConfig
from mv3dpose_ros.core.geometry.calibration import load_calibration, rig_metadata
from mv3dpose_ros.core.geometry.camera import CalibrationError, Camera, IMAGE_SIZE_TOLERANCE_PX
from mv3dpose_ros.core.live.config import complete_live_config
from mv3dpose_ros.core.live.sync import SyncConfig
from mv3dpose_ros.core.skeleton import get_layout, Layout, LAYOUT_NAMES
from mv3dpose_ros.core.types import NS_PER_S
from mv3dpose_ros.ros.markers import MarkerOptions
from mv3dpose_ros.ros.params import resolve_path
from mv3dpose_ros.ros.qos import sensor_qos

_MARKERS = MarkerOptions()
_DYNAMIC = {'dynamic': True}


class ConfigError(ValueError):
    """A parameter or calibration problem that prevents the node from starting."""


@dataclass
class InputLimits:
    """Bounds on one input message (``limits.*``)."""

    max_persons: int = 50  # Inputs with more persons are dropped and counted (too_many_persons),
    #                        never clipped: bounds the work per set
    max_message_bytes: int = 262_144  # Inputs larger than this [bytes] are dropped and counted
    #                                   (too_large) before decoding


@dataclass
class DiagnosticsParams:
    """The ``/diagnostics`` checks (``diagnostics.*``)."""

    period_s: float = 1.0  # Period [s] of /diagnostics
    silent_warn_s: float = field(default=2.0, metadata=_DYNAMIC)  # WARN when a camera sent
    #                                                    nothing for this long [s] (steady clock)
    clock_stall_s: float = field(default=2.0, metadata=_DYNAMIC)  # Under use_sim_time, ERROR
    #                                 when /clock did not advance for this long [s] (steady clock)
    expected_rate_hz: float = field(default=0.0, metadata=_DYNAMIC)  # Expected input rate per
    #                                        camera [Hz] for the frequency check; 0 = no check


@dataclass
class MarkerParams:
    """The RViz markers of ``~/markers`` (``markers.*``, all dynamic)."""

    enabled: bool = True  # Publish ~/markers (only while subscribed)
    lifetime_s: float = _MARKERS.lifetime_s  # Marker lifetime [s] (safety net for a stalled
    #                                          node)
    line_width_m: float = _MARKERS.line_width_m  # Bone line width [m]
    joint_diameter_m: float = _MARKERS.joint_diameter_m  # Joint sphere diameter [m]
    text_height_m: float = _MARKERS.text_height_m  # Label text height [m]
    coasting_alpha: float = _MARKERS.coasting_alpha  # Alpha of COASTING tracks
    show_labels: bool = _MARKERS.show_labels  # Draw "<id> <state>" labels
    show_velocity: bool = _MARKERS.show_velocity  # Draw root velocity arrows

    def options(self) -> MarkerOptions:
        """Return the marker options these parameters give."""
        return MarkerOptions(
            lifetime_s=self.lifetime_s, line_width_m=self.line_width_m,
            joint_diameter_m=self.joint_diameter_m, text_height_m=self.text_height_m,
            coasting_alpha=self.coasting_alpha, show_labels=self.show_labels,
            show_velocity=self.show_velocity)


@dataclass
class FusionNodeParams:
    """Every parameter of fusion_node (``tf.*`` aside, declared by ``ros.tf``)."""

    rig_config: str = ''  # Rig calibration file (rig YAML, or any format core.calibration reads);
    #                       relative paths are tried against the working directory, then the
    #                       package source and share directories
    camera_ids: List[str] = field(default_factory=list)  # Cameras to fuse (rig camera names);
    #                                                      empty = every camera of the rig
    input_topic: str = '/{camera}/persons_2d'  # Person2DArray topic per camera; {camera} is
    #                                            replaced by the camera id
    input_reliability: str = 'reliable'  # QoS reliability of the inputs: reliable (matches
    #                                      reliable publishers only) or best_effort (matches both)
    input_depth: int = 100  # QoS history depth of each input subscription (absorbs CPU hiccups:
    #                         ~1.7 s at 60 fps; what overflows shows as stamp gaps)
    input_image_size_tolerance_px: int = IMAGE_SIZE_TOLERANCE_PX  # Inputs whose image_width x
    #          image_height differs from the calibration are used when it is a resize (same
    #          aspect ratio: keypoints scaled into the calibration pixels) or a crop or padding
    #          of at most this many pixels per dimension (keypoints unchanged: assumed at the
    #          right/bottom, as codecs do); each is logged once per camera and size. Other sizes
    #          are dropped (image_size). Negative: only the calibrated size is accepted
    layout: str = field(default='coco17', metadata={'help': (
        f'Skeleton layout fused and published ({", ".join(LAYOUT_NAMES)}); inputs of another '
        'known layout are converted')})
    world_frame: str = ''  # frame_id of tracks and markers (the rig's world, z up); empty = the
    #                        rig file's world_frame, else 'map'
    intrinsics_source: str = 'rig'  # rig: intrinsics from rig_config; camera_info: from the first
    #                                 CameraInfo of each camera (extrinsics stay from the rig)
    camera_info_topic: str = '/{camera}/camera_info'  # CameraInfo topic per camera when
    #                                                   intrinsics_source is camera_info
    sync: SyncConfig = field(default_factory=SyncConfig)
    limits: InputLimits = field(default_factory=InputLimits)
    fusion: FusionConfig = field(default_factory=FusionConfig)
    publish_tentative: bool = field(default=False, metadata=_DYNAMIC)  # Also publish TENTATIVE
    #                                                                    (unconfirmed) tracks
    smoothed_lag_frames: int = 3  # Lag L [sets] of ~/tracks_smoothed: each set is published
    #                               smoothed L sets later, stamped with its own capture time;
    #                               0 = off
    input_max_future_s: float = 2.0  # Drop inputs stamped more than this [s] ahead of the node
    #                                  clock (skipped while the clock is zero)
    log_throttle_s: float = 5.0  # Rate limit [s] of repeated warnings per camera and reason
    save_rig: str = ''  # Rig YAML to write the rig in use to, at start and whenever the
    #                     calibration watch corrects a camera (fusion.calibration_watch); empty =
    #                     none (~/rig publishes it either way)
    diagnostics: DiagnosticsParams = field(default_factory=DiagnosticsParams)
    markers: MarkerParams = field(default_factory=MarkerParams, metadata=_DYNAMIC)


@dataclass
class FusionSetup:
    """The checked setup of fusion_node: what its parameters name, loaded and validated."""

    rig_path: str
    rig: Dict[str, Camera]
    camera_ids: Tuple[str, ...]
    layout: Layout
    world_frame: str
    max_future_ns: int               # inputs stamped further ahead of the node clock: dropped
    warnings: List[str]
    sync: SyncConfig                 # p.sync completed for this clock (core.live.config)
    fusion: FusionConfig             # p.fusion, checked

    def summary(self, sync: SyncConfig, sim_time: bool) -> str:
        """Return the line the node logs when it starts."""
        return (f'fusing {len(self.camera_ids)} cameras {list(self.camera_ids)} from '
                f'{self.rig_path} (layout {self.layout.name}, world frame '
                f'{self.world_frame!r}, use_sim_time {sim_time}); sync slop '
                f'{sync.slop_s * 1e3:.1f} ms (0 = half the frame period), max_wait '
                f'{sync.max_wait_s * 1e3:.0f} ms (adapts up to '
                f'{sync.max_wait_cap_s * 1e3:.0f} ms), min_views {sync.min_views}')


def check_setup(p: FusionNodeParams, sim_time: bool, search_dirs: Sequence[str] = (),
                warnings: Sequence[str] = ()) -> FusionSetup:
    """Load the rig and check ``p`` (left unchanged: the setup holds the configs to run with)."""
    warnings = list(warnings)
    rig_path = resolve_path(p.rig_config, search_dirs)
    if not p.rig_config:
        raise ConfigError('parameter rig_config is empty: set it to the rig calibration '
                          'file (e.g. --ros-args -p rig_config:=config/rigs/my_rig.yaml)')
    if not os.path.isfile(rig_path):
        raise ConfigError(f'rig_config {p.rig_config!r} not found (resolved to {rig_path!r})')
    try:
        rig = load_calibration(rig_path)
        rig_frame, rig_problems = rig_metadata(rig_path)
    except (CalibrationError, OSError, ValueError) as exc:
        raise ConfigError(f'cannot load rig_config: {exc}') from exc
    warnings += rig_problems
    ids = [c for c in (p.camera_ids or []) if c] or list(rig)
    unknown = [c for c in ids if c not in rig]
    if unknown:
        raise ConfigError(f'camera_ids {unknown} are not in {rig_path} (its cameras: '
                          f'{", ".join(rig)})')
    if len(set(ids)) != len(ids):
        raise ConfigError(f'camera_ids has duplicates: {ids}')
    try:
        layout = get_layout(p.layout)
    except ValueError as exc:
        raise ConfigError(f'parameter layout: {exc}') from exc
    if '{camera}' not in p.input_topic and len(ids) > 1:
        raise ConfigError(f'input_topic {p.input_topic!r} must contain {{camera}}')
    try:
        sensor_qos(p.input_reliability, p.input_depth)
    except ValueError as exc:
        raise ConfigError(f'input QoS: {exc}') from exc
    if p.intrinsics_source not in ('rig', 'camera_info'):
        raise ConfigError(f'intrinsics_source must be rig or camera_info, got '
                          f'{p.intrinsics_source!r}')
    try:
        sync, fusion, completed = complete_live_config(p.sync, p.fusion, sim_time)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f'parameters: {exc}') from exc
    warnings += completed
    if len(ids) < max(2, fusion.min_views):
        raise ConfigError(f'{len(ids)} camera(s) {ids}: fusion needs at least '
                          f'{max(2, fusion.min_views)}')
    lim = p.limits
    if lim.max_persons < 1 or lim.max_message_bytes < 64:
        raise ConfigError(f'limits.max_persons ({lim.max_persons}) must be >= 1 and '
                          f'limits.max_message_bytes ({lim.max_message_bytes}) >= 64')
    max_future_ns = int(float(p.input_max_future_s) * NS_PER_S)
    if sim_time:
        # The player publishes /clock with the messages: a stamp further ahead of it than
        # sync.jump_s is an outlier, as the synchroniser judges it on a live clock.
        max_future_ns = min(max_future_ns, int(sync.jump_s * NS_PER_S))
    if p.smoothed_lag_frames < 0:
        raise ConfigError(f'smoothed_lag_frames must be >= 0, got {p.smoothed_lag_frames}')
    return FusionSetup(rig_path, rig, tuple(ids), layout, p.world_frame or rig_frame or 'map',
                       max_future_ns, warnings, sync, fusion)


def dynamic_value_problem(name: str, value: object) -> str:
    """Return why a new value of a time, length, rate or alpha parameter is refused ('')."""
    if name.endswith(('_s', '_m', '_hz', '_alpha')) and isinstance(value, (int, float)) \
            and not isinstance(value, bool) and not (math.isfinite(value) and value >= 0):
        return f'{name} must be finite and >= 0'
    return ''
