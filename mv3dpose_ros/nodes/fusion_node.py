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
fusion_node: N camera streams of ``Person2DArray`` in, tracked 3D skeletons out.

A thin adapter around the core: per-camera subscriptions feed the N-stream synchroniser
(``core.sync``, header stamps only), each synchronised set goes through ``Fusion.step``, and
the tracks are published as ``~/tracks`` (``TrackedSkeletonArray``, stamped with the set's
capture time, in the world frame), ``~/markers`` (RViz, only when subscribed), a latched
``~/skeleton_info`` and ``/diagnostics``. Every input is validated first; a bad message is
dropped with a rate-limited log line naming the camera, topic and reason, and counted in the
diagnostics, so it can neither stop the node nor reach the tracker.

Inputs are taken as raw CDR and read by ``decode_person2d_array``, which accepts exactly what
rclpy's deserialiser accepts (bytes it refuses are dropped as 'malformed'); ``~/tracks`` and
``~/markers`` are serialised straight to CDR. Both skip one Python object per keypoint, joint
or point, which was most of the node's own cost.
"""

from collections import Counter, deque
import logging
import math
import os
import sys
import threading
import time
from typing import Any, Dict, List, Optional, Union

from geometry_msgs.msg import PoseArray
from mv3dpose_msgs.msg import Person2DArray, SkeletonInfo, SkippedImages, TrackedSkeletonArray
from mv3dpose_ros.core.calibration import load_calibration, rig_metadata
from mv3dpose_ros.core.camera import (CalibrationError, Camera, fit_image_size,
                                      IMAGE_SIZE_TOLERANCE_PX)
from mv3dpose_ros.core.fusion import Fusion, FusionConfig
from mv3dpose_ros.core.output import LiveOutput
from mv3dpose_ros.core.skeleton import convert_poses, get_layout, LAYOUT_NAMES
from mv3dpose_ros.core.sync import StreamSynchronizer, SyncConfig, SyncedSet
from mv3dpose_ros.core.types import NS_PER_S, Track, TrackState
from mv3dpose_ros.ros import params as P
from mv3dpose_ros.ros.diagnostics import (Diagnostics, ERROR, FrequencyStats, level_value,
                                          make_status, OK, RateLimitedLog, TimestampStats,
                                          WARN, WindowStats)
from mv3dpose_ros.ros.frames import Headings, pose_array_cdr, root_poses
from mv3dpose_ros.ros.markers import MarkerOptions, tracks_to_markers_cdr
from mv3dpose_ros.ros.messages import (decode_person2d_array, InvalidMessage, ns_to_stamp,
                                       person2d_array_to_numpy, Persons2D, skeleton_info_msg,
                                       stamp_to_ns, tracks_to_cdr)
from mv3dpose_ros.ros.names import camera_topic
from mv3dpose_ros.ros.qos import (describe, latched_qos, publisher_events, reliable_qos,
                                  sensor_qos, subscription_events)
from mv3dpose_ros.ros.spin import spin_until_shutdown
from mv3dpose_ros.ros.tf import TfBridge, TfError
import numpy as np
from rcl_interfaces.msg import SetParametersResult
import rclpy
from rclpy.clock import Clock, ClockType, JumpThreshold
from rclpy.duration import Duration
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from sensor_msgs.msg import CameraInfo
from std_msgs.msg import Header
from std_srvs.srv import Trigger
from visualization_msgs.msg import MarkerArray

#: Longest stretch [ns] empty steps may cover after the last set (tracks are long deleted by
#: then; a node clock that jumped further must not produce absurd stamps).
MAX_IDLE_SPAN_NS = 3600 * NS_PER_S
#: Shortest delay [s] of the release timer, which wakes when the synchroniser's oldest pending
#: set may be decided (core.sync.next_decision_ns) and is off while nothing is pending.
MIN_RELEASE_DELAY_S = 0.0005
#: Period [s] of the empty steps that age the tracks once no input set arrives.
IDLE_STEP_S = 0.1
#: Tracks coast at least this many set periods (median of the recent set stamp steps), beyond
#: fusion.max_coast_s when sets come slower: an overloaded rig's inference grid (pose2d
#: inference_rate_hz auto) may give a set every 1-3 s, and its people must keep their tracks.
COAST_SET_PERIODS = 2.5


def steady_ns() -> int:
    """Return the steady (monotonic) clock in nanoseconds: waits, throttles and durations."""
    return time.monotonic_ns()


class ConfigError(ValueError):
    """A parameter or calibration problem that prevents the node from starting."""


class _Camera:
    """Per-camera input state and counters."""

    def __init__(self, name: str, topic: str) -> None:
        self.name = name
        self.topic = topic
        self.received = 0
        self.accepted = 0
        self.rejected: Counter = Counter()     # reason -> count (never reset)
        self.rejected_reported: Counter = Counter()   # snapshot at the last diagnostics cycle
        self.lost_reported = 0                 # sync stats' upstream losses at the last cycle
        self.freq = FrequencyStats()
        self.stamps = TimestampStats()
        self.last_rx_ns: Optional[int] = None
        self.size_problem = ''                 # last message's size disagreed with calibration
        self.info_problem = ''                 # the CameraInfo was rejected
        self.camera_info_received = False
        self.skips = 0                         # SkippedImages notices taken
        self.skips_rejected = 0                # ... and refused (bad stamps)
        self.late_used = 0                     # late for their set, folded in at their stamp

    @property
    def calibration_problem(self) -> str:
        """Return what disagrees with the calibration ('' when nothing)."""
        return '; '.join(p for p in (self.info_problem, self.size_problem) if p)


class _RosLogHandler(logging.Handler):
    """Forward the core's Python ``logging`` records to the node's ROS logger."""

    def __init__(self, node: Node) -> None:
        super().__init__(logging.INFO)
        self._node = node

    def emit(self, record: logging.LogRecord) -> None:
        logger = self._node.get_logger()
        text = f'{record.name}: {record.getMessage()}'
        if record.levelno >= logging.ERROR:
            logger.error(text)
        elif record.levelno >= logging.WARNING:
            logger.warning(text)
        else:
            logger.info(text)


class FusionNode(Node):
    """ROS adapter of ``core.fusion.Fusion`` fed by the N-stream synchroniser."""

    def __init__(self, node_name: str = 'fusion_node', **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        self._lock = threading.RLock()
        self._declare_parameters()
        self._read_parameters()
        try:   # TF where tf2_ros exists (ros/tf.py): static camera poses, or extrinsics from TF
            self.tf = TfBridge(self, self.world_frame)
            self.rig = self.tf.start(self.rig, self.camera_ids, self.get_clock().now().to_msg())
        except TfError as exc:
            raise ConfigError(str(exc)) from exc
        self.headings = Headings(self.layout)
        # Throttling, waits and durations run on the steady clock: a stalled /clock must not
        # silence the node (core.sync waits on it too).
        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._rlog = RateLimitedLog(self.get_logger().warning, self.log_throttle_s)
        for problem in self.config_warnings:
            self.get_logger().warning(problem)
        self._log_handler = _RosLogHandler(self)
        logging.getLogger('mv3dpose_ros').addHandler(self._log_handler)

        self.tracks_pub = self._publisher(TrackedSkeletonArray, '~/tracks', reliable_qos(10))
        # Fixed-lag output (core.output.LiveOutput): each set smoothed_lag_frames sets later.
        self.smoothed_pub = None
        if self.smoothed_lag_frames > 0:
            self.smoothed_pub = self._publisher(TrackedSkeletonArray, '~/tracks_smoothed',
                                                reliable_qos(10))
        self.markers_pub = self._publisher(MarkerArray, '~/markers', reliable_qos(5))
        self.info_pub = self._publisher(SkeletonInfo, '~/skeleton_info', latched_qos())
        self.info_pub.publish(skeleton_info_msg(self.layout, Header(frame_id=self.world_frame)))
        # Standard output beside ~/tracks: the root poses of the same skeletons (ros/frames.py).
        self.poses_pub = self._publisher(PoseArray, '~/poses', reliable_qos(10))
        self._reset_srv = self.create_service(Trigger, '~/reset', self._on_reset_request)

        self.sync = StreamSynchronizer(self.camera_ids, self.sync_config, clock=steady_ns)
        self.fusion: Optional[Fusion] = None
        self.cams: Dict[str, _Camera] = {}
        self._start_ns = steady_ns()
        self._slop_note_logged = False
        self._last_set_node_ns: Optional[int] = None   # node clock when the last set came
        self._last_set_anchor_ns = 0                     # stamp of the last real set
        self._set_steps_ns: Any = deque(maxlen=9)        # recent set stamp steps (coast)
        self._drops_reported: Dict[str, int] = {}
        self._clock_seen = (self._now_ns(), steady_ns())   # node clock value, steady at change
        self.output = self._new_output()
        self.latency = WindowStats()
        self.processing = WindowStats()
        self.output_rate = FrequencyStats()
        self.last_tracks: List[Track] = []
        self.counts = Counter()                 # resets, fusion_errors, sets, ...
        self._last_set_ns: Optional[int] = None
        self._last_rx_any_ns: Optional[int] = None

        in_qos = sensor_qos(self.input_reliability, self.input_depth)
        self._subs = []
        for cam in self.camera_ids:
            topic = self._topic(self.input_topic, cam, 'input_topic')
            state = _Camera(cam, self.resolve_topic_name(topic))
            self.cams[cam] = state
            # raw=True: CDR bytes decoded by decode_person2d_array (no object per keypoint).
            self._subs.append(self.create_subscription(
                Person2DArray, topic, lambda msg, c=cam: self._on_persons(c, msg), in_qos,
                event_callbacks=subscription_events(self, topic, in_qos), raw=True))
            # pose2d_node announces the images it will send no persons for: sets stop
            # waiting for them (SkippedImages.msg).
            skipped = f'{state.topic}/skipped'
            self._subs.append(self.create_subscription(
                SkippedImages, skipped, lambda msg, c=cam: self._on_skipped(c, msg),
                reliable_qos(10)))
            self.get_logger().info(f'input {cam}: {state.topic} [{describe(in_qos)}], '
                                   f'{skipped}')
        if self.intrinsics_source == 'camera_info':
            info_qos = sensor_qos('best_effort', 1)
            for cam in self.camera_ids:
                topic = self._topic(self.camera_info_topic, cam, 'camera_info_topic')
                self._subs.append(self.create_subscription(
                    CameraInfo, topic, lambda msg, c=cam: self._on_camera_info(c, msg),
                    info_qos, event_callbacks=subscription_events(self, topic, info_qos)))
                self.get_logger().info(f'intrinsics {cam}: {self.resolve_topic_name(topic)} '
                                       f'[{describe(info_qos)}] (latched on first message)')
        else:
            self._build_fusion()

        self.diagnostics = Diagnostics(self, self.diagnostics_period_s)
        self.diagnostics.add_task(self._diag_inputs)
        self.diagnostics.add_task(self._diag_pipeline)
        # Off until a set is pending; then armed for the moment it may be decided (no polling).
        self._release_timer = self.create_timer(1.0, self._poll, clock=self._steady,
                                                autostart=False)
        self._release_due: Optional[int] = None        # what it is armed for; None: off
        self._idle_timer = self.create_timer(IDLE_STEP_S, self._idle_step, clock=self._steady)
        self._jump_handle = self.get_clock().create_jump_callback(
            JumpThreshold(min_forward=None, min_backward=Duration(seconds=-0.5),
                          on_clock_change=False),
            post_callback=self._on_time_jump)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.add_post_set_parameters_callback(self._after_set_parameters)
        self.get_logger().info(
            f'fusing {len(self.camera_ids)} cameras {list(self.camera_ids)} from '
            f'{self.rig_path} (layout {self.layout.name}, world frame {self.world_frame!r}, '
            f'use_sim_time {self.get_parameter("use_sim_time").value}); sync slop '
            f'{self.sync_config.slop_s * 1e3:.1f} ms (0 = half the frame period), max_wait '
            f'{self.sync_config.max_wait_s * 1e3:.0f} ms (adapts up to '
            f'{self.sync_config.max_wait_cap_s * 1e3:.0f} ms), min_views '
            f'{self.sync_config.min_views}')

    # ------------------------------------------------------------------ parameters
    def _declare_parameters(self) -> None:
        d = P.declare
        d(self, 'rig_config', '', 'Rig calibration file (rig YAML, or any format '
          'core.calibration reads); relative paths are tried against the working directory, '
          'then the package source and share directories', read_only=True)
        d(self, 'camera_ids', [], 'Cameras to fuse (rig camera names); empty = every camera of '
          'the rig', read_only=True)
        d(self, 'input_topic', '/{camera}/persons_2d',
          'Person2DArray topic per camera; {camera} is replaced by the camera id',
          read_only=True)
        d(self, 'input_reliability', 'reliable', 'QoS reliability of the inputs: reliable '
          '(matches reliable publishers only) or best_effort (matches both)', read_only=True)
        d(self, 'input_depth', 100, 'QoS history depth of each input subscription (absorbs '
          'CPU hiccups: ~1.7 s at 60 fps; what overflows shows as stamp gaps)',
          read_only=True)
        d(self, 'input_image_size_tolerance_px', IMAGE_SIZE_TOLERANCE_PX, 'Inputs whose '
          'image_width x image_height differs from the calibration are used when it is a '
          'resize (same aspect ratio: keypoints scaled into the calibration pixels) or a crop '
          'or padding of at most this many pixels per dimension (keypoints unchanged: assumed at '
          'the right/bottom, as codecs do); each is logged once per camera and size. Other '
          'sizes are dropped (image_size). Negative: only the calibrated size is accepted',
          read_only=True)
        d(self, 'layout', 'coco17', 'Skeleton layout fused and published '
          f'({", ".join(LAYOUT_NAMES)}); inputs of another known layout are converted',
          read_only=True)
        d(self, 'world_frame', '', "frame_id of tracks and markers (the rig's world, z up); "
          "empty = the rig file's world_frame, else 'map'", read_only=True)
        d(self, 'intrinsics_source', 'rig', 'rig: intrinsics from rig_config; camera_info: '
          'from the first CameraInfo of each camera (extrinsics stay from the rig)',
          read_only=True)
        d(self, 'camera_info_topic', '/{camera}/camera_info',
          'CameraInfo topic per camera when intrinsics_source is camera_info', read_only=True)
        P.declare_dataclass(self, SyncConfig, 'sync', read_only=True)
        d(self, 'limits.max_persons', 50, 'Inputs with more persons are dropped and counted '
          '(too_many_persons), never clipped: bounds the work per set', read_only=True)
        d(self, 'limits.max_message_bytes', 262_144, 'Inputs larger than this [bytes] are '
          'dropped and counted (too_large) before decoding', read_only=True)
        P.declare_dataclass(self, FusionConfig, 'fusion', read_only=True)
        d(self, 'publish_tentative', False, 'Also publish TENTATIVE (unconfirmed) tracks',
          dynamic=True)
        d(self, 'smoothed_lag_frames', 3, 'Lag L [sets] of ~/tracks_smoothed: each set is '
          'published smoothed L sets later, stamped with its own capture time; 0 = off',
          read_only=True)
        d(self, 'input_max_future_s', 2.0, 'Drop inputs stamped more than this [s] ahead of '
          'the node clock (skipped while the clock is zero)', read_only=True)
        d(self, 'log_throttle_s', 5.0, 'Rate limit [s] of repeated warnings per camera and '
          'reason', read_only=True)
        d(self, 'diagnostics.period_s', 1.0, 'Period [s] of /diagnostics', read_only=True)
        d(self, 'diagnostics.silent_warn_s', 2.0, 'WARN when a camera sent nothing for this '
          'long [s] (steady clock)', dynamic=True)
        d(self, 'diagnostics.clock_stall_s', 2.0, 'Under use_sim_time, ERROR when /clock did '
          'not advance for this long [s] (steady clock)', dynamic=True)
        d(self, 'diagnostics.expected_rate_hz', 0.0, 'Expected input rate per camera [Hz] for '
          'the frequency check; 0 = no check', dynamic=True)
        mo = MarkerOptions()
        d(self, 'markers.enabled', True, 'Publish ~/markers (only while subscribed)',
          dynamic=True)
        d(self, 'markers.lifetime_s', mo.lifetime_s, 'Marker lifetime [s] (safety net for a '
          'stalled node)', dynamic=True)
        d(self, 'markers.line_width_m', mo.line_width_m, 'Bone line width [m]', dynamic=True)
        d(self, 'markers.joint_diameter_m', mo.joint_diameter_m, 'Joint sphere diameter [m]',
          dynamic=True)
        d(self, 'markers.text_height_m', mo.text_height_m, 'Label text height [m]',
          dynamic=True)
        d(self, 'markers.coasting_alpha', mo.coasting_alpha, 'Alpha of COASTING tracks',
          dynamic=True)
        d(self, 'markers.show_labels', mo.show_labels, 'Draw "<id> <state>" labels',
          dynamic=True)
        d(self, 'markers.show_velocity', mo.show_velocity, 'Draw root velocity arrows',
          dynamic=True)

    def _read_parameters(self) -> None:
        v = self._value
        self.config_warnings = P.unknown_parameter_warnings(self)
        self.rig_path = P.resolve_path(v('rig_config'), P.package_search_dirs())
        if not v('rig_config'):
            raise ConfigError('parameter rig_config is empty: set it to the rig calibration '
                              'file (e.g. --ros-args -p rig_config:=config/rigs/my_rig.yaml)')
        if not os.path.isfile(self.rig_path):
            raise ConfigError(f'rig_config {v("rig_config")!r} not found (resolved to '
                              f'{self.rig_path!r})')
        try:
            self.rig: Dict[str, Camera] = load_calibration(self.rig_path)
            rig_frame, rig_problems = rig_metadata(self.rig_path)
        except (CalibrationError, OSError, ValueError) as exc:
            raise ConfigError(f'cannot load rig_config: {exc}') from exc
        self.config_warnings += rig_problems
        ids = [c for c in (v('camera_ids') or []) if c]
        if not ids:
            ids = list(self.rig)
        unknown = [c for c in ids if c not in self.rig]
        if unknown:
            raise ConfigError(f'camera_ids {unknown} are not in {self.rig_path} (its cameras: '
                              f'{", ".join(self.rig)})')
        if len(set(ids)) != len(ids):
            raise ConfigError(f'camera_ids has duplicates: {ids}')
        self.camera_ids = tuple(ids)
        try:
            self.layout = get_layout(v('layout'))
        except ValueError as exc:
            raise ConfigError(f'parameter layout: {exc}') from exc
        self.input_topic = v('input_topic')
        if '{camera}' not in self.input_topic and len(ids) > 1:
            raise ConfigError(f'input_topic {self.input_topic!r} must contain {{camera}}')
        self.input_reliability = v('input_reliability')
        self.input_depth = int(v('input_depth'))
        self.image_size_tolerance_px = int(v('input_image_size_tolerance_px'))
        self._image_size_logged: set = set()    # (camera, image and calibration sizes) logged
        try:
            sensor_qos(self.input_reliability, self.input_depth)
        except ValueError as exc:
            raise ConfigError(f'input QoS: {exc}') from exc
        self.world_frame = v('world_frame') or rig_frame or 'map'
        self.intrinsics_source = v('intrinsics_source')
        if self.intrinsics_source not in ('rig', 'camera_info'):
            raise ConfigError(f'intrinsics_source must be rig or camera_info, got '
                              f'{self.intrinsics_source!r}')
        self.camera_info_topic = v('camera_info_topic')
        sim_time = bool(self.get_parameter('use_sim_time').value)
        try:
            self.sync_config = P.build_dataclass(self, SyncConfig, 'sync')
            self.sync_config.validate()
            if sim_time:
                # A replay's stamps follow /clock, not the arrival clock: judge them there.
                self.sync_config.stream_ahead_check = False
            self.fusion_config = P.build_dataclass(self, FusionConfig, 'fusion')
            self.fusion_config.validate()
        except (TypeError, ValueError) as exc:
            raise ConfigError(f'parameters: {exc}') from exc
        if self.sync_config.min_views < 2 and not self.fusion_config.view_updates:
            # A set of one camera only updates tracks through single-view updates.
            self.config_warnings.append('sync.min_views 1 needs fusion.view_updates: using 2')
            self.sync_config.min_views = 2
        if len(ids) < max(2, self.fusion_config.min_views):
            raise ConfigError(f'{len(ids)} camera(s) {ids}: fusion needs at least '
                              f'{max(2, self.fusion_config.min_views)}')
        self.max_persons = int(v('limits.max_persons'))
        self.max_message_bytes = int(v('limits.max_message_bytes'))
        if self.max_persons < 1 or self.max_message_bytes < 64:
            raise ConfigError(f'limits.max_persons ({self.max_persons}) must be >= 1 and '
                              f'limits.max_message_bytes ({self.max_message_bytes}) >= 64')
        self.max_future_ns = int(float(v('input_max_future_s')) * NS_PER_S)
        if sim_time:
            # The player publishes /clock with the messages: a stamp further ahead of it than
            # sync.jump_s is an outlier, as the synchroniser judges it on a live clock.
            self.max_future_ns = min(self.max_future_ns,
                                     int(self.sync_config.jump_s * NS_PER_S))
        self.smoothed_lag_frames = int(v('smoothed_lag_frames'))
        if self.smoothed_lag_frames < 0:
            raise ConfigError(f'smoothed_lag_frames must be >= 0, got {self.smoothed_lag_frames}')
        self.log_throttle_s = float(v('log_throttle_s'))
        self.diagnostics_period_s = float(v('diagnostics.period_s'))
        self._read_dynamic()

    def _read_dynamic(self) -> None:
        v = self._value
        self.publish_tentative = bool(v('publish_tentative'))
        if getattr(self, 'output', None) is not None:
            self.output.publisher.publish_tentative = self.publish_tentative
        self.silent_warn_ns = int(float(v('diagnostics.silent_warn_s')) * NS_PER_S)
        self.clock_stall_ns = int(float(v('diagnostics.clock_stall_s')) * NS_PER_S)
        self.expected_rate_hz = float(v('diagnostics.expected_rate_hz'))
        self.markers_enabled = bool(v('markers.enabled'))
        self.marker_options = MarkerOptions(
            lifetime_s=float(v('markers.lifetime_s')),
            line_width_m=float(v('markers.line_width_m')),
            joint_diameter_m=float(v('markers.joint_diameter_m')),
            text_height_m=float(v('markers.text_height_m')),
            coasting_alpha=float(v('markers.coasting_alpha')),
            show_labels=bool(v('markers.show_labels')),
            show_velocity=bool(v('markers.show_velocity')))

    def _value(self, name: str) -> Any:
        return P.value(self, name)

    def _on_set_parameters(self, changes: List[Parameter]) -> SetParametersResult:
        for p in changes:
            if p.name.endswith('_s') or p.name.endswith('_m') or p.name.endswith('_hz') \
                    or p.name.endswith('_alpha'):
                if p.type_ in (Parameter.Type.DOUBLE, Parameter.Type.INTEGER) and (
                        not math.isfinite(float(p.value)) or float(p.value) < 0):
                    return SetParametersResult(successful=False,
                                               reason=f'{p.name} must be finite and >= 0')
        return SetParametersResult(successful=True)

    def _after_set_parameters(self, changes: List[Parameter]) -> None:
        with self._lock:
            self._read_dynamic()
            self.get_logger().info('parameters changed: ' + ', '.join(
                f'{p.name}={p.value!r}' for p in changes))

    def _topic(self, pattern: str, cam: str, param: str) -> str:
        """Return ``pattern`` for camera ``cam``; ConfigError if it is no valid topic name."""
        topic = camera_topic(pattern, cam)     # {camera} -> the camera's ROS name (ros/names)
        try:
            self.resolve_topic_name(topic)
        except Exception as exc:  # noqa: B902 - rclpy raises RCLError / ValueError variants
            raise ConfigError(
                f'{param} {pattern!r} gives the invalid topic {topic!r} for camera {cam!r} '
                f'({exc})') from exc
        return topic

    def _publisher(self, msg_type: Any, topic: str, qos: Any) -> Any:
        pub = self.create_publisher(msg_type, topic, qos,
                                    event_callbacks=publisher_events(self, topic, qos))
        self.get_logger().info(f'output {pub.topic_name} [{describe(qos)}]')
        return pub

    # ------------------------------------------------------------------ calibration
    def _build_fusion(self) -> None:
        cameras = {c: self.rig[c] for c in self.camera_ids}
        self.fusion = Fusion(cameras, self.layout, self.fusion_config)
        for c in self.camera_ids:
            cam = cameras[c]
            self.get_logger().info(
                f'camera {c}: {cam.width}x{cam.height} px, f {cam.focal:.1f} px, centre '
                f'{np.round(cam.center, 3).tolist()} m ({self.intrinsics_source} intrinsics)')

    def _on_camera_info(self, cam: str, msg: CameraInfo) -> None:
        with self._lock:
            state = self.cams[cam]
            if state.camera_info_received:
                return
            try:
                camera = camera_from_info(self.rig[cam], msg)
            except (CalibrationError, ValueError) as exc:
                state.info_problem = f'CameraInfo rejected: {exc}'
                self._rlog(f'{cam}:camera_info', f'camera {cam}: CameraInfo on '
                           f'{self.resolve_topic_name(camera_topic(self.camera_info_topic, cam))}'
                           f' rejected: {exc}')
                return
            rig_cam = self.rig[cam]
            if (camera.width, camera.height) != (rig_cam.width, rig_cam.height):
                self.get_logger().warning(
                    f'camera {cam}: CameraInfo size {camera.width}x{camera.height} differs '
                    f'from the rig file ({rig_cam.width}x{rig_cam.height}); using CameraInfo '
                    f'(its intrinsics, and its size to check the inputs against)')
            self.rig[cam] = camera
            state.camera_info_received = True
            state.info_problem = ''
            if all(self.cams[c].camera_info_received for c in self.camera_ids):
                self._build_fusion()
                self.get_logger().info('intrinsics of every camera received: fusing')

    # ------------------------------------------------------------------ input
    def _now_ns(self) -> int:
        return self.get_clock().now().nanoseconds

    def _reject(self, state: _Camera, reason: str, text: str, now_ns: int = 0) -> None:
        state.rejected[reason] += 1
        self._rlog(f'{state.name}:{reason}', f'dropped Person2DArray of camera {state.name} '
                   f'on {state.topic}: {text}')

    def _decode(self, state: _Camera, data: bytes) -> Union[Persons2D, Person2DArray]:
        """Decode raw CDR (InvalidMessage 'malformed' for bytes rclpy would refuse too)."""
        return decode_person2d_array(data)

    def _validate(self, state: _Camera, msg: Union[Persons2D, Person2DArray], stamp_ns: int,
                  now_ns: int):
        """Return ``(poses, None)`` or ``(None, (reason, text))``."""
        cam = state.name
        if msg.camera_id and msg.camera_id != cam:
            if msg.camera_id not in self.rig:
                return None, ('unknown_camera', f'camera_id {msg.camera_id!r} is not in the rig '
                              f'({", ".join(self.rig)})')
            return None, ('wrong_camera', f'camera_id {msg.camera_id!r} arrived on the topic '
                          f'of camera {cam!r} (remapping mistake?)')
        if stamp_ns <= 0:
            return None, ('zero_stamp', 'header stamp is zero (the publisher must copy the '
                          'image capture stamp)')
        if now_ns > 0 and stamp_ns > now_ns + self.max_future_ns:
            return None, ('future_stamp', f'stamp {stamp_ns / NS_PER_S:.3f} s is '
                          f'{(stamp_ns - now_ns) / NS_PER_S:.3f} s ahead of the node clock '
                          f'(limit input_max_future_s)')
        calib = self.rig[cam]
        fit = None
        if msg.image_width and msg.image_height and (
                msg.image_width != calib.width or msg.image_height != calib.height):
            # A codec's crop/padding or a resized stream is mapped into the calibration's
            # pixels (core.camera.fit_image_size); only what cannot be explained is dropped.
            fit = fit_image_size(calib.width, calib.height, msg.image_width, msg.image_height,
                                 self.image_size_tolerance_px)
            source = 'CameraInfo' if state.camera_info_received else self.rig_path
            if not fit.accepted:
                problem = (f'image_width x image_height differs from the calibration '
                           f'({source}): {fit.note}; parameter input_image_size_tolerance_px '
                           f'({self.image_size_tolerance_px}) sets the crop or padding '
                           f'accepted')
                state.size_problem = problem
                return None, ('image_size', problem)
            key = (cam, fit.image_size, fit.calib_size)
            if key not in self._image_size_logged:
                self._image_size_logged.add(key)
                self.get_logger().warning(
                    f'camera {cam} on {state.topic}: {fit.note} ({fit.kind}; calibration from '
                    f'{source}; parameter input_image_size_tolerance_px '
                    f'{self.image_size_tolerance_px}); logged once per size')
        state.size_problem = ''
        persons = len(msg.counts) if isinstance(msg, Persons2D) else len(msg.persons)
        if persons > self.max_persons:
            return None, ('too_many_persons', f'{persons} persons > limits.max_persons '
                          f'{self.max_persons} (dropped whole, not clipped)')
        layout_name = msg.layout or self.layout.name
        try:
            src = get_layout(layout_name)
        except ValueError:
            return None, ('unknown_layout', f'layout {msg.layout!r} unknown (known: '
                          f'{", ".join(LAYOUT_NAMES)})')
        try:
            poses = person2d_array_to_numpy(msg, src.num_joints)
        except InvalidMessage as exc:
            return None, (exc.reason, str(exc))
        if fit is not None:
            poses = fit.apply(poses)
        if src.name != self.layout.name and len(poses):
            poses = convert_poses(poses, src, self.layout)
            bad = ~np.isfinite(poses).all(axis=-1)
            poses[bad] = 0.0
        elif src.name != self.layout.name:
            poses = np.zeros((0, self.layout.num_joints, 3))
        if len(poses) == 0:
            poses = poses.reshape(0, self.layout.num_joints, 3)
        return poses, None

    def _on_persons(self, cam: str, msg: Union[bytes, Person2DArray]) -> None:
        """Take one input: serialised CDR (the raw subscription) or a ``Person2DArray``."""
        with self._lock:
            now = self._now_ns()
            arrival = steady_ns()
            state = self.cams[cam]
            state.received += 1
            state.freq.tick()
            state.last_rx_ns = arrival
            self._last_rx_any_ns = arrival
            if isinstance(msg, Person2DArray):
                stamp_ns = stamp_to_ns(msg.header.stamp)
            else:
                if len(msg) > self.max_message_bytes:
                    self._reject(state, 'too_large', f'{len(msg)} bytes > '
                                 f'limits.max_message_bytes {self.max_message_bytes}', now)
                    return
                try:
                    msg = self._decode(state, msg)
                except InvalidMessage as exc:
                    self._reject(state, exc.reason, str(exc), now)
                    return
                stamp_ns = (msg.stamp_ns if isinstance(msg, Persons2D)
                            else stamp_to_ns(msg.header.stamp))
            state.stamps.record(stamp_ns, now)
            if self.fusion is None:
                waiting = [c for c in self.camera_ids if not self.cams[c].camera_info_received]
                self._reject(state, 'no_calibration',
                             f'waiting for CameraInfo of {", ".join(waiting)}', now)
                return
            poses, problem = self._validate(state, msg, stamp_ns, now)
            if problem is not None:
                seen = self.sync.stats[cam].last_seen_ns
                if stamp_ns > 0 and (problem[0] != 'future_stamp' or seen is None or
                                     stamp_ns - seen <= self.sync_config.jump_s * NS_PER_S):
                    self.sync.observe(cam, stamp_ns)   # dropped here, not lost upstream
                    # Its stamp may show that the camera will send nothing for a pending set.
                    self._release(arrival)
                self._reject(state, *problem, now)
                return
            result = self.sync.add(cam, stamp_ns, poses, arrival)
            if result.reset:
                self._reset(result.reason, from_sync=True)
            if result.kind == 'late':
                self._late(state, poses, stamp_ns, result.reason, now)
            elif result.kind == 'outlier':   # held; counted by the synchroniser when dropped
                self._rlog(f'{cam}:outlier', f'Person2DArray of camera {cam} on {state.topic}: '
                           f'{result.reason}')
            elif result.reason and not result.reset:   # a forward jump of the rig, taken
                self._rlog('forward_jump', result.reason)
            if result.accepted:
                state.accepted += 1
            if self.sync.slop_note and not self._slop_note_logged:
                self._slop_note_logged = True
                self.get_logger().warning(self.sync.slop_note)
            for synced in result.sets:
                self._process(synced)
            self._release(arrival)     # after a late message too (add decides nothing then)

    def _late(self, state: _Camera, poses: np.ndarray, stamp_ns: int, reason: str,
              now: int) -> None:
        """Fold a message that missed its set into the tracks at its own stamp, or drop it."""
        if not self.fusion_config.view_updates:
            self._reject(state, 'late', reason, now)
            return
        try:
            used = self.fusion.update_view(state.name, poses, stamp_ns / NS_PER_S, stamp_ns)
        except Exception as exc:  # noqa: B902 - a core failure must not stop the node
            self.counts['fusion_errors'] += 1
            self._rlog('fusion_error', f'Fusion.update_view failed on camera {state.name} at '
                       f'{stamp_ns / NS_PER_S:.6f} s ({exc!r}); message dropped')
            return
        if used:
            state.late_used += 1
        # else: every joint it saw was updated after its stamp (or nobody to update): it
        # brought nothing, and counts as late in /diagnostics, not as rejected

    def _on_skipped(self, cam: str, msg: SkippedImages) -> None:
        """Stop waiting for the camera's images it announces it sends no persons for."""
        with self._lock:
            state = self.cams[cam]
            before, after = stamp_to_ns(msg.header.stamp), stamp_to_ns(msg.after)
            if not 0 <= after < before:
                state.skips_rejected += 1
                self._rlog(f'{cam}:bad_skip', f'dropped SkippedImages of camera {cam} on '
                           f'{state.topic}/skipped: after {after / NS_PER_S:.6f} s is not '
                           f'before header.stamp {before / NS_PER_S:.6f} s')
                return
            state.skips += 1
            if self.fusion is None:
                return
            now = steady_ns()
            for synced in self.sync.skip(cam, after, before, now):
                self._process(synced)
            self._arm_release()

    def _poll(self) -> None:
        """Let the sets go whose wait for missing cameras ran out (the release timer)."""
        with self._lock:
            self._release_due = -1     # it fired: periodic again until re-armed or cancelled
            self._release(steady_ns())

    def _release(self, now: int) -> None:
        """Process the sets the synchroniser decides at ``now`` (steady), then re-arm."""
        if self.fusion is not None and self.sync.pending():
            for synced in self.sync.poll(now):
                self._process(synced)
        self._arm_release()

    def _arm_release(self) -> None:
        """Wake ``_poll`` when the oldest pending set may be decided; sleep while none is."""
        now = steady_ns()
        due = self.sync.next_decision_ns(now) if self.fusion is not None else None
        if due == self._release_due:
            return
        self._release_due = due
        if due is None:
            self._release_timer.cancel()
            return
        self._release_timer.timer_period_ns = max(due - now,
                                                  int(MIN_RELEASE_DELAY_S * NS_PER_S))
        self._release_timer.reset()

    def _idle_step(self) -> None:
        """
        Age the tracks while no input set arrives: empty steps, as the tracker would get them.

        Once no set came for ``fusion.max_coast_s`` (and longer than the synchroniser could
        wait) and no input at all arrived for as long, every IDLE_STEP_S the tracks step
        with no views at the last set's stamp
        advanced by the node-clock time since (less that wait), so they go COASTING and are
        DELETED after ``fusion.max_coast_s`` as with empty sets; a message stamped before that
        time is then late. Under sim time a stalled /clock stops this too (and is reported in
        /diagnostics).
        """
        with self._lock:
            if self.fusion is None or not len(self.fusion.tracker.tracks) or \
                    self._last_set_ns is None or self._last_set_node_ns is None or \
                    self.sync.pending():
                return
            now_ns = self._now_ns()
            if now_ns <= 0 or self._last_set_node_ns <= 0:
                return     # sim time before the first /clock: no elapsed time to judge
            idle_ns = now_ns - self._last_set_node_ns
            # Frames captured up to (now - wait) would have arrived: the empty step stands for
            # them. Stepping only starts after max_coast_s, so a hiccup of a publisher (or a
            # replay slower than real time) does not turn its next frames late.
            wait_ns = self.sync.max_wait_ns + \
                (self.sync.frame_period_ns or int(IDLE_STEP_S * NS_PER_S))
            coast_ns = int(self.fusion.tracker.config.max_coast_s * NS_PER_S)
            if idle_ns <= max(wait_ns, coast_ns):
                return
            if self._last_rx_any_ns is not None and steady_ns() - self._last_rx_any_ns <= coast_ns:
                return     # inputs still arrive (dropped, e.g. under a stalled /clock): no gap
            stamp_ns = self._last_set_anchor_ns + idle_ns - wait_ns
            if stamp_ns <= self._last_set_ns or stamp_ns > self._last_set_ns + MAX_IDLE_SPAN_NS:
                return     # nothing to age, or a node clock that jumped far ahead
            self.sync.decide_through(stamp_ns)
            self.counts['idle_steps'] += 1
            self._step({}, stamp_ns, idle=True)

    def _on_time_jump(self, jump: Any) -> None:
        with self._lock:
            self._reset(f'node clock jumped back {-jump.delta.nanoseconds / NS_PER_S:.3f} s')

    def _reset(self, why: str, from_sync: bool = False) -> None:
        """Clear synchroniser and tracks; publish tombstones of the published tracks."""
        self.counts['resets'] += 1
        self.get_logger().warning(f'reset: {why}; synchroniser and tracks cleared')
        if not from_sync:
            self.sync.reset()
        tombs = self.fusion.reset() if self.fusion is not None else []
        tombs, held = self.output.reset(tombs)
        self._publish_smoothed(held)
        self.last_tracks = []
        if tombs and self._last_set_ns is not None:
            self._publish(tombs, self._last_set_ns)
            self._publish_smoothed([(self._last_set_ns, 0.0, tombs)])
        self._last_set_ns = None
        self._last_set_node_ns = None

    # ------------------------------------------------------------------ fusion and output
    def _process(self, synced: SyncedSet) -> None:
        self._last_set_node_ns = self._now_ns()
        self._adapt_coast(synced.stamp_ns)
        self._last_set_anchor_ns = synced.stamp_ns
        if self._step(synced.messages, synced.stamp_ns):
            self.counts['sets'] += 1
            if synced.missing:
                self.counts['partial_sets'] += 1

    def _adapt_coast(self, stamp_ns: int) -> None:
        """Let tracks coast COAST_SET_PERIODS set periods at least (slow sets keep tracks)."""
        step = stamp_ns - self._last_set_anchor_ns
        if self._last_set_anchor_ns and 0 < step < 30 * NS_PER_S:
            self._set_steps_ns.append(step)
        if len(self._set_steps_ns) < 3:
            return
        period = sorted(self._set_steps_ns)[len(self._set_steps_ns) // 2] / NS_PER_S
        coast = max(self.fusion_config.max_coast_s, COAST_SET_PERIODS * period)
        tracker = self.fusion.tracker.config
        if abs(coast - tracker.max_coast_s) > 0.05 * tracker.max_coast_s:
            self.get_logger().info(
                f'tracks coast {coast:.2f} s (sets every {period:.2f} s; fusion.max_coast_s '
                f'{self.fusion_config.max_coast_s:g} s)')
            tracker.max_coast_s = coast

    def _step(self, views: Dict[str, Any], stamp_ns: int, idle: bool = False) -> bool:
        """Run ``Fusion.step`` and publish; return False when the core failed (counted)."""
        t0 = time.perf_counter()
        try:
            tracks = self.fusion.step(views, stamp_ns / NS_PER_S, stamp_ns)
        except Exception as exc:  # noqa: B902 - a core failure must not stop the node
            self.counts['fusion_errors'] += 1
            self._rlog('fusion_error', f'Fusion.step failed on the set at '
                       f'{stamp_ns / NS_PER_S:.6f} s ({exc!r}); tracks reset')
            self.fusion.reset()
            self._publish_smoothed(self.output.reset()[1])
            return False
        if not idle:
            self.processing.add(time.perf_counter() - t0)
        self.last_tracks = [t for t in tracks if t.state != TrackState.DELETED]
        # The fixed-lag estimate only while ~/tracks_smoothed has a subscriber (its window is
        # kept regardless, so one that joins gets what it would have got all along).
        want = self.smoothed_pub is not None and self.smoothed_pub.get_subscription_count() > 0
        out, smoothed = self.output.step(tracks, stamp_ns / NS_PER_S, stamp_ns, smoothed=want)
        self._publish(out, stamp_ns, latency=not idle)
        self._publish_smoothed([smoothed] if smoothed is not None else [])
        self._last_set_ns = stamp_ns
        return True

    def _new_output(self) -> LiveOutput:
        try:
            root = self.layout.root_joints
        except ValueError:
            root = None
        return LiveOutput(self.fusion_config.publish_coast_s, self.publish_tentative,
                          self.smoothed_lag_frames, root)

    def _publish_smoothed(self, sets: List[Any]) -> None:
        """Publish fixed-lag sets ``(stamp_ns, stamp, tracks)``, each with its own stamp."""
        for stamp_ns, _, tracks in sets:
            if self.smoothed_pub is not None:
                header = Header(stamp=ns_to_stamp(stamp_ns), frame_id=self.world_frame)
                self.smoothed_pub.publish(tracks_to_cdr(tracks, header, self.layout.name))

    def _publish(self, tracks: List[Track], stamp_ns: int, latency: bool = True) -> None:
        header = Header(stamp=ns_to_stamp(stamp_ns), frame_id=self.world_frame)
        self.tracks_pub.publish(tracks_to_cdr(tracks, header, self.layout.name))
        yaws = self.headings.update(tracks)
        self.poses_pub.publish(pose_array_cdr(root_poses(tracks, yaws), header))
        self.tf.publish_tracks(tracks, yaws, header)
        self.output_rate.tick()
        if latency:
            self.latency.add((self._now_ns() - stamp_ns) / NS_PER_S)
        if self.markers_enabled and self.markers_pub.get_subscription_count() > 0:
            self.markers_pub.publish(tracks_to_markers_cdr(tracks, self.layout.bones, header,
                                                           self.marker_options))

    def _on_reset_request(self, request: Trigger.Request,
                          response: Trigger.Response) -> Trigger.Response:
        """Serve ``~/reset`` (std_srvs/Trigger): clear the synchroniser and the tracks."""
        with self._lock:
            count = len(self.last_tracks)
            self._reset('~/reset service call')
        response.success = True
        response.message = f'cleared {count} tracks and the synchroniser'
        return response

    def destroy_node(self) -> None:
        """Detach the logging bridge, then destroy the node."""
        logging.getLogger('mv3dpose_ros').removeHandler(self._log_handler)
        super().destroy_node()

    # ------------------------------------------------------------------ diagnostics
    def _expected_rate_hz(self, cam: str) -> float:
        """Rate a camera should deliver: its own usual rate, or the rig's if that is higher."""
        usual = [r for r in (self.sync.stats[c].usual_rate_hz for c in self.camera_ids)
                 if math.isfinite(r)]
        own = self.sync.stats[cam].usual_rate_hz
        rig = sorted(usual)[len(usual) // 2] if usual else math.nan
        return max((r for r in (own, rig) if math.isfinite(r)), default=math.nan)

    def _diag_inputs(self) -> List[Any]:
        with self._lock:
            now = steady_ns()
            out = []
            for cam in self.camera_ids:
                st = self.cams[cam]
                ss = self.sync.stats[cam]
                rate = st.freq
                rate.min_hz = self.expected_rate_hz
                rate.max_hz = self.expected_rate_hz if self.expected_rate_hz > 0 else math.inf
                f_level, f_msg, values = rate.sample(now)
                t_level, t_msg, t_values = st.stamps.sample()
                expected = self._expected_rate_hz(cam)
                values = {'topic': st.topic, **values, **t_values,
                          'rate from stamps (Hz)': ss.rate_hz,
                          'expected rate (Hz)': expected,
                          'lost upstream (stamp gaps)': ss.lost,
                          'skipped by pose2d (announced gaps)': ss.skipped,
                          'received': st.received, 'accepted': st.accepted,
                          'used in sets': ss.used, 'dropped by sync': ss.dropped,
                          'late': ss.late, 'late, used (tracks updated at its stamp)':
                              st.late_used, 'outlier stamps': ss.outliers,
                          'missing from sets': ss.missing,
                          'skip notices (persons_2d/skipped)': st.skips,
                          'skip notices rejected': st.skips_rejected,
                          'offset mean (ms)': ss.offset_mean_s * 1e3,
                          'offset jitter (ms)': ss.offset_jitter_s * 1e3}
                for reason, n in sorted(ss.unmatched.items()):
                    values[f'dropped by sync: {reason}'] = n
                for reason, n in sorted(st.rejected.items()):
                    values[f'rejected: {reason}'] = n
                level, message = OK, 'receiving'
                since = now - (st.last_rx_ns if st.last_rx_ns is not None else self._start_ns)
                new_lost = ss.lost - st.lost_reported
                st.lost_reported = ss.lost
                if since > self.silent_warn_ns:
                    level = WARN
                    message = f'no input on {st.topic} for {since / NS_PER_S:.1f} s'
                elif st.calibration_problem:
                    level, message = ERROR, st.calibration_problem
                elif level_value(t_level) > level_value(OK):
                    level, message = t_level, t_msg
                elif level_value(f_level) > level_value(OK) and self.expected_rate_hz > 0:
                    level, message = f_level, f_msg
                elif ss.rate_hz < 0.75 * expected:
                    level, message = WARN, (f'{ss.rate_hz:.1f} Hz from the stamps, below the '
                                            f'usual {expected:.1f} Hz')
                new = st.rejected - st.rejected_reported
                st.rejected_reported = Counter(st.rejected)
                if level == OK and new:
                    level = WARN
                    message = 'dropped ' + ', '.join(f'{n} {r}' for r, n in sorted(new.items()))
                if level == OK and new_lost > 0:
                    level = WARN
                    message = (f'{new_lost} frames lost upstream (gaps in the stamps: '
                               'publisher, network or DDS queue)')
                out.append(make_status(self.diagnostics.name(f'{cam} input'), level, message,
                                       hardware_id=cam, values=values))
            return out

    def _diag_pipeline(self) -> List[Any]:
        with self._lock:
            now = steady_ns()
            s = self.sync
            stats = [s.stats[c] for c in self.camera_ids]
            drops = {
                'lost upstream (stamp gaps)': sum(x.lost for x in stats),
                'dropped at input (validation)': sum(
                    n for c in self.camera_ids for r, n in self.cams[c].rejected.items()
                    if r != 'late'),
                'dropped in sync: late': sum(x.late for x in stats) - sum(
                    self.cams[c].late_used for c in self.camera_ids),
                'dropped in sync: outlier stamps': sum(x.outliers for x in stats),
                'dropped in sync: too few views': sum(x.unmatched['too_few_views']
                                                      for x in stats),
                'dropped in sync: duplicates': sum(x.unmatched['duplicates'] for x in stats),
                'sets decided early (queue full)': s.overflow_decisions}
            new = {k: v - self._drops_reported.get(k, 0) for k, v in drops.items()}
            self._drops_reported = drops
            values = {'sets emitted': s.sets_emitted, 'partial sets': s.partial_sets,
                      'incomplete sets decided on skip notices':
                          s.decisions['skipped (announced)'],
                      'pivots dropped (too few views)': s.pivots_dropped,
                      'pending messages': s.pending(), 'held outlier messages': s.held_outliers,
                      'slop (ms)': s.slop_ns / 1e6,
                      'max_wait in use (ms)': s.max_wait_ns / 1e6,
                      'arrival spread p95 (ms)': s.spread_p95_s * 1e3,
                      'frame period (ms)': (s.frame_period_ns or math.nan) / 1e6,
                      'resets': self.counts['resets'],
                      'forward jumps (no reset)': s.forward_jumps,
                      'idle steps (no input)': self.counts['idle_steps'], **drops}
            changed = {k: v for k, v in new.items() if v > 0}
            level = WARN if changed else OK
            message = f'{s.sets_emitted} sets, {s.partial_sets} partial'
            if changed:
                message += '; this cycle: ' + ', '.join(f'{v} {k}' for k, v in changed.items())
            sync_status = make_status(self.diagnostics.name('synchronizer'), level, message,
                                      values=values)
            states = Counter(TrackState(t.state).name.lower() for t in self.last_tracks)
            f_level, f_msg, rate = self.output_rate.sample(now)
            values = {'active tracks': len(self.last_tracks),
                      'confirmed tracks': states.get('confirmed', 0),
                      'coasting tracks': states.get('coasting', 0),
                      'tentative tracks': states.get('tentative', 0),
                      'output frequency (Hz)': rate['Actual frequency (Hz)'],
                      'latency median (ms)': self.latency.percentile(50) * 1e3,
                      'latency p95 (ms)': self.latency.percentile(95) * 1e3,
                      'processing median (ms)': self.processing.percentile(50) * 1e3,
                      'processing p95 (ms)': self.processing.percentile(95) * 1e3,
                      'processing max (ms)': self.processing.percentile(100) * 1e3,
                      'fusion errors': self.counts['fusion_errors']}
            if self.fusion is not None:
                fc = self.fusion.counts
                values.update({
                    'tracks updated by single views': fc['view_updates'],
                    'late messages used': fc['late_views_used'],
                    'tracks recovered after a gap': fc['recovered'],
                    'duplicate tracks merged': fc['merged_tracks']})
            level, message = OK, f'{len(self.last_tracks)} tracks'
            if self.fusion is None:
                level, message = WARN, 'waiting for calibration (CameraInfo)'
            elif self.counts['fusion_errors']:
                level, message = WARN, f'{self.counts["fusion_errors"]} fusion errors'
            track_status = make_status(self.diagnostics.name('tracking'), level, message,
                                       values=values)
            problems = {c: self.cams[c].calibration_problem for c in self.camera_ids
                        if self.cams[c].calibration_problem}
            calib = make_status(
                self.diagnostics.name('calibration'), ERROR if problems else OK,
                '; '.join(f'{c}: {p}' for c, p in problems.items()) or
                f'{len(self.camera_ids)} cameras from {self.rig_path}',
                values={'rig_config': self.rig_path, **{f'{c} problem': p
                                                        for c, p in problems.items()}})
            return [sync_status, track_status, calib, self._diag_clock(now)]

    def _diag_clock(self, steady: int) -> Any:
        """Node clock status: under use_sim_time, ERROR naming /clock when it stopped."""
        node_now = self._now_ns()
        if node_now != self._clock_seen[0]:
            self._clock_seen = (node_now, steady)
        stalled = (steady - self._clock_seen[1]) / NS_PER_S
        sim = bool(self.get_parameter('use_sim_time').value)
        values = {'use_sim_time': sim, 'node clock (s)': node_now / NS_PER_S,
                  'unchanged for (s, steady clock)': stalled}
        name = self.diagnostics.name('clock')
        if not sim:
            return make_status(name, OK, 'system clock', values=values)
        if node_now == 0:
            return make_status(name, ERROR, f'no /clock received for {stalled:.1f} s '
                               '(use_sim_time is true: start the bag player with --clock)',
                               values=values)
        if stalled * NS_PER_S > self.clock_stall_ns:
            return make_status(name, ERROR, f'/clock stalled at {node_now / NS_PER_S:.3f} s '
                               f'for {stalled:.1f} s: sim time does not advance (player paused '
                               'or gone), so inputs are judged against a stopped clock',
                               values=values)
        return make_status(name, OK, '/clock advancing', values=values)


def camera_from_info(rig_camera: Camera, msg: CameraInfo) -> Camera:
    """Return ``rig_camera`` with the intrinsics of ``msg`` (errors name camera and field)."""
    name = rig_camera.name
    K = np.asarray(msg.k, dtype=np.float64).reshape(3, 3)
    if not np.any(K):
        raise CalibrationError('all zeros (uncalibrated camera driver)', camera=name,
                               field='CameraInfo.k')
    if msg.width == 0 or msg.height == 0:
        raise CalibrationError(f'image size {msg.width}x{msg.height}', camera=name,
                               field='CameraInfo.width/height')
    model = msg.distortion_model or 'plumb_bob'
    d = np.asarray(msg.d, dtype=np.float64)
    if model not in ('plumb_bob', 'rational_polynomial') or len(d) > 5 and np.any(d[5:]):
        raise CalibrationError(f'distortion model {model!r} with {len(d)} coefficients is not '
                               'supported (plumb_bob only)', camera=name,
                               field='CameraInfo.distortion_model')
    dist = np.zeros(5)
    dist[:min(5, len(d))] = d[:5]
    return Camera(name=name, K=K, dist=dist, R=rig_camera.R, t=rig_camera.t,
                  width=int(msg.width), height=int(msg.height))


def main(args: Optional[List[str]] = None) -> int:
    """Entry point of the ``fusion_node`` console script."""
    rclpy.init(args=args)
    try:
        node = FusionNode()
    except ConfigError as exc:
        rclpy.logging.get_logger('fusion_node').fatal(f'cannot start: {exc}')
        rclpy.try_shutdown()
        return 2
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    try:
        spin_until_shutdown(executor)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
