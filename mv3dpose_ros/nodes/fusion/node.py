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

Wiring around the live core (``core.live.loop.LiveFusion``: synchroniser, ``Fusion.step``, the
publication policy, idle steps, coasting and resets, the same object ``mv3dpose track``
runs): per-camera subscriptions feed it (header stamps only), and the tracks it gives are
published as ``~/tracks`` (``TrackedSkeletonArray``, stamped with the set's capture time, in
the world frame), ``~/markers`` (RViz, only when subscribed), a latched ``~/skeleton_info``
and ``/diagnostics`` (``.diagnostics``). Parameters are the fields of
``.config.FusionNodeParams``. Every input is validated first
(``.inputs.PersonsInputCheck``); a bad message is dropped with a rate-limited log line
naming the camera, topic and reason, and counted in the diagnostics, so it can neither stop
the node nor reach the tracker.

Inputs are taken as raw CDR and read by ``decode_person2d_array``, which accepts exactly what
rclpy's deserialiser accepts (bytes it refuses are dropped as 'malformed'); ``~/tracks`` and
``~/markers`` are serialised straight to CDR. Both skip one Python object per keypoint, joint
or point, which was most of the node's own cost.
"""

import logging
import sys
import threading
import time
from typing import Any, Dict, List, Optional, Union

from geometry_msgs.msg import PoseArray
from mv3dpose_msgs.msg import Person2DArray, SkeletonInfo, SkippedImages, TrackedSkeletonArray
from mv3dpose_ros.core.fusion.pipeline import Fusion
from mv3dpose_ros.core.geometry.camera import CalibrationError
from mv3dpose_ros.core.live.loop import IDLE_STEP_S, LiveFusion, LiveLog, Publication
from mv3dpose_ros.core.types import NS_PER_S
from mv3dpose_ros.nodes.fusion.config import (check_setup, ConfigError, dynamic_value_problem,
                                              FusionNodeParams)
from mv3dpose_ros.nodes.fusion.diagnostics import FusionStatus
from mv3dpose_ros.nodes.fusion.inputs import camera_from_info, CameraInputStats, PersonsInputCheck
from mv3dpose_ros.nodes.fusion.log_bridge import RosLogHandler
from mv3dpose_ros.nodes.fusion.rig_output import RigOutput
from mv3dpose_ros.ros import params as P
from mv3dpose_ros.ros.diagnostics import Diagnostics, RateLimitedLog
from mv3dpose_ros.ros.frames import Headings, pose_array_cdr, root_poses
from mv3dpose_ros.ros.markers import tracks_to_markers_cdr
from mv3dpose_ros.ros.messages import (InvalidMessage, ns_to_stamp, skeleton_info_msg, stamp_to_ns,
                                       tracks_to_cdr)
from mv3dpose_ros.ros.names import camera_topic
from mv3dpose_ros.ros.qos import (describe, latched_qos, publisher_events, reliable_qos,
                                  sensor_qos, subscription_events)
from mv3dpose_ros.ros.spin import run_node
from mv3dpose_ros.ros.tf import TfBridge, TfError
import numpy as np
from rcl_interfaces.msg import SetParametersResult
from rclpy.clock import Clock, ClockType, JumpThreshold
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.parameter import Parameter
from sensor_msgs.msg import CameraInfo
from std_msgs.msg import Header
from std_srvs.srv import Trigger
from visualization_msgs.msg import MarkerArray

#: Shortest delay [s] of the release timer, which wakes when the synchroniser's oldest pending
#: set may be decided (core.sync.next_decision_ns) and is off while nothing is pending.
MIN_RELEASE_DELAY_S = 0.0005


def steady_ns() -> int:
    """Return the steady (monotonic) clock in nanoseconds: waits, throttles and durations."""
    return time.monotonic_ns()


class FusionNode(Node):
    """ROS wiring of ``core.live.loop.LiveFusion``: parameters, topics, diagnostics, rig."""

    def __init__(self, node_name: str = 'fusion_node', **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        self._lock = threading.RLock()
        P.declare_config(self, FusionNodeParams)
        self._read_parameters()
        try:   # TF where tf2_ros exists (ros/tf.py): static camera poses, or extrinsics from TF
            self.tf = TfBridge(self, self.world_frame)
            self.inputs.rig = self.rig = self.tf.start(self.rig, self.camera_ids,
                                                       self.get_clock().now().to_msg())
        except TfError as exc:
            raise ConfigError(str(exc)) from exc
        self.headings = Headings(self.layout)
        # Throttling, waits and durations run on the steady clock: a stalled /clock must not
        # silence the node (core.sync waits on it too).
        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._rlog = RateLimitedLog(self.get_logger().warning, self.params.log_throttle_s)
        for problem in self.config_warnings:
            self.get_logger().warning(problem)
        self._log_handler = RosLogHandler(self)
        logging.getLogger('mv3dpose_ros').addHandler(self._log_handler)

        self.tracks_pub = self._publisher(TrackedSkeletonArray, '~/tracks', reliable_qos(10))
        # Fixed-lag output (core.output.LiveOutput): each set smoothed_lag_frames sets later.
        self.smoothed_pub = None
        if self.params.smoothed_lag_frames > 0:
            self.smoothed_pub = self._publisher(TrackedSkeletonArray, '~/tracks_smoothed',
                                                reliable_qos(10))
        self.markers_pub = self._publisher(MarkerArray, '~/markers', reliable_qos(5))
        self.info_pub = self._publisher(SkeletonInfo, '~/skeleton_info', latched_qos())
        self.info_pub.publish(skeleton_info_msg(self.layout, Header(frame_id=self.world_frame)))
        # Standard output beside ~/tracks: the root poses of the same skeletons (ros/frames.py).
        self.poses_pub = self._publisher(PoseArray, '~/poses', reliable_qos(10))
        self._reset_srv = self.create_service(Trigger, '~/reset', self._on_reset_request)
        self.rig_out = RigOutput(self, self.tf, self.world_frame, self.camera_ids,
                                 self.params.save_rig)

        log = self.get_logger()
        self.live = LiveFusion(
            self.camera_ids, self.layout, self.sync_config, self.fusion_config,
            self.params.publish_tentative, self.params.smoothed_lag_frames,
            LiveLog(info=log.info, warning=log.warning, throttled=self._rlog,
                    rig=lambda cams: self.rig_out.publish(cams, 'corrected by the '
                                                          'calibration watch')),
            wants_smoothed=lambda: self.smoothed_pub is not None and
            self.smoothed_pub.get_subscription_count() > 0)
        self.cams: Dict[str, CameraInputStats] = {}

        p = self.params
        in_qos = sensor_qos(p.input_reliability, p.input_depth)
        self._subs = []
        for cam in self.camera_ids:
            topic = self._topic(p.input_topic, cam, 'input_topic')
            state = self.cams[cam] = CameraInputStats(cam, self.resolve_topic_name(topic))
            # raw=True: CDR bytes decoded by decode_person2d_array (no object per keypoint).
            self._subs.append(self.create_subscription(
                Person2DArray, topic, lambda msg, c=cam: self.on_persons(c, msg), in_qos,
                event_callbacks=subscription_events(self, topic, in_qos), raw=True))
            # pose2d_node announces the images it will send no persons for: sets stop
            # waiting for them (SkippedImages.msg).
            skipped = f'{state.topic}/skipped'
            self._subs.append(self.create_subscription(
                SkippedImages, skipped, lambda msg, c=cam: self._on_skipped(c, msg),
                reliable_qos(10)))
            self.get_logger().info(f'input {cam}: {state.topic} [{describe(in_qos)}], '
                                   f'{skipped}')
        if p.intrinsics_source == 'camera_info':
            info_qos = sensor_qos('best_effort', 1)
            for cam in self.camera_ids:
                topic = self._topic(p.camera_info_topic, cam, 'camera_info_topic')
                self._subs.append(self.create_subscription(
                    CameraInfo, topic, lambda msg, c=cam: self._on_camera_info(c, msg),
                    info_qos, event_callbacks=subscription_events(self, topic, info_qos)))
                self.get_logger().info(f'intrinsics {cam}: {self.resolve_topic_name(topic)} '
                                       f'[{describe(info_qos)}] (latched on first message)')
        else:
            self._build_fusion()

        self.diagnostics = Diagnostics(self, p.diagnostics.period_s)
        self.status = FusionStatus(self.live, self.cams, self.camera_ids, self.rig_path,
                                   self.diagnostics.name, steady_ns(), self._now_ns())
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
        self.get_logger().info(self.setup.summary(
            self.sync_config, self.get_parameter('use_sim_time').value))

    @property
    def fusion(self) -> Optional[Fusion]:
        """Return the live core's ``Fusion``; None until every camera's calibration is known."""
        return self.live.fusion

    @property
    def release_armed(self) -> bool:
        """Tell whether the release timer is armed: it is off while no set is pending."""
        return not self._release_timer.is_canceled()

    # ------------------------------------------------------------------ parameters
    def _read_parameters(self) -> None:
        self.config_warnings = P.unknown_parameter_warnings(self)
        try:
            self.params = P.build_config(self, FusionNodeParams)
        except (TypeError, ValueError) as exc:
            raise ConfigError(f'parameters: {exc}') from exc
        p = self.params
        self.setup = setup = check_setup(p, bool(self.get_parameter('use_sim_time').value),
                                         P.package_search_dirs(), self.config_warnings)
        self.config_warnings, self.rig_path = setup.warnings, setup.rig_path
        self.camera_ids, self.layout, self.world_frame = (setup.camera_ids, setup.layout,
                                                          setup.world_frame)
        self.sync_config, self.fusion_config = setup.sync, setup.fusion   # completed
        self.inputs = PersonsInputCheck(
            setup.rig, self.layout, self.rig_path, p.limits.max_persons,
            p.limits.max_message_bytes, setup.max_future_ns,
            p.input_image_size_tolerance_px, self.get_logger().warning)
        self.rig = self.inputs.rig
        self._read_dynamic()

    def _read_dynamic(self) -> None:
        p = P.build_config(self, FusionNodeParams)
        if getattr(self, 'live', None) is not None:
            self.live.publish_tentative = p.publish_tentative
        self.diag, self.markers = p.diagnostics, p.markers
        self.marker_options = p.markers.options()

    def _on_set_parameters(self, changes: List[Parameter]) -> SetParametersResult:
        problems = [dynamic_value_problem(p.name, p.value) for p in changes]
        reason = next((p for p in problems if p), '')
        return SetParametersResult(successful=not reason, reason=reason)

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
        cameras = self.live.start(self.rig).cameras
        self.rig_out.publish(self.live.cameras, f'the rig in use at start ({self.rig_path})')
        for c, cam in zip(self.camera_ids, cameras):
            self.get_logger().info(
                f'camera {c}: {cam.width}x{cam.height} px, f {cam.focal:.1f} px, centre '
                f'{np.round(cam.center, 3).tolist()} m ({self.params.intrinsics_source} '
                'intrinsics)')

    def _on_camera_info(self, cam: str, msg: CameraInfo) -> None:
        with self._lock:
            state = self.cams[cam]
            if state.camera_info_received:
                return
            try:
                camera = camera_from_info(self.rig[cam], msg)
            except (CalibrationError, ValueError) as exc:
                state.info_problem = f'CameraInfo rejected: {exc}'
                topic = camera_topic(self.params.camera_info_topic, cam)
                self._rlog(f'{cam}:camera_info', f'camera {cam}: CameraInfo on '
                           f'{self.resolve_topic_name(topic)} rejected: {exc}')
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

    def _reject(self, state: CameraInputStats, reason: str, text: str) -> None:
        state.rejected[reason] += 1
        self._rlog(f'{state.name}:{reason}', f'dropped Person2DArray of camera {state.name} '
                   f'on {state.topic}: {text}')

    def on_persons(self, cam: str, msg: Union[bytes, Person2DArray]) -> None:
        """Take camera ``cam``'s input: serialised CDR (the raw subscription) or a message."""
        with self._lock:
            now, arrival = self._now_ns(), steady_ns()
            state = self.cams[cam]
            state.arrived(arrival)
            self.live.heard(arrival)
            try:
                msg, stamp_ns = self.inputs.read(msg)
            except InvalidMessage as exc:
                return self._reject(state, exc.reason, str(exc))
            state.stamps.record(stamp_ns, now)
            if self.fusion is None:
                waiting = [c for c in self.camera_ids if not self.cams[c].camera_info_received]
                return self._reject(state, 'no_calibration',
                                    f'waiting for CameraInfo of {", ".join(waiting)}')
            try:
                poses = self.inputs.validate(state, msg, stamp_ns, now)
            except InvalidMessage as exc:
                self._emit(self.live.dropped(cam, stamp_ns, exc.reason, arrival, now))
                self._arm_release()
                return self._reject(state, exc.reason, str(exc))
            intake = self.live.add(cam, stamp_ns, poses, arrival, now)
            if intake.late_refused:
                self._reject(state, 'late', intake.reason)
            elif intake.kind == 'outlier':   # held; counted by the synchroniser when dropped
                self._rlog(f'{cam}:outlier', f'Person2DArray of camera {cam} on {state.topic}: '
                           f'{intake.reason}')
            elif intake.reason and not intake.reset and intake.kind != 'late':
                self._rlog('forward_jump', intake.reason)   # a forward jump of the rig, taken
            state.late_used += intake.late_used
            state.accepted += intake.accepted
            self._emit(intake.publications)
            self._arm_release()

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
            if self.fusion is not None:
                self._emit(self.live.skip(cam, after, before, steady_ns(), self._now_ns()))
                self._arm_release()

    # ------------------------------------------------------------------ timers and resets
    def _poll(self) -> None:
        """Let the sets go whose wait for missing cameras ran out (the release timer)."""
        with self._lock:
            self._release_due = -1     # it fired: periodic again until re-armed or cancelled
            self._emit(self.live.release(steady_ns(), self._now_ns()))
            self._arm_release()

    def _arm_release(self) -> None:
        """Wake ``_poll`` when the oldest pending set may be decided; sleep while none is."""
        now = steady_ns()
        due = self.live.next_release_ns(now)
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
        """Age the tracks while no input set arrives (``LiveFusion.idle_step``)."""
        with self._lock:
            self._emit(self.live.idle_step(steady_ns(), self._now_ns()))

    def _on_time_jump(self, jump: Any) -> None:
        with self._lock:
            self._emit(self.live.reset(
                f'node clock jumped back {-jump.delta.nanoseconds / NS_PER_S:.3f} s'))

    def _on_reset_request(self, request: Trigger.Request,
                          response: Trigger.Response) -> Trigger.Response:
        """Serve ``~/reset`` (std_srvs/Trigger): clear the synchroniser and the tracks."""
        with self._lock:
            count = len(self.live.last_tracks)
            self._emit(self.live.reset('~/reset service call'))
        response.success = True
        response.message = f'cleared {count} tracks and the synchroniser'
        return response

    # ------------------------------------------------------------------ output
    def _emit(self, publications: List[Publication]) -> None:
        """Publish what the live core produced, in order."""
        for pub in publications:
            header = Header(stamp=ns_to_stamp(pub.stamp_ns), frame_id=self.world_frame)
            if pub.smoothed:
                if self.smoothed_pub is not None:
                    self.smoothed_pub.publish(tracks_to_cdr(pub.tracks, header,
                                                            self.layout.name))
                continue
            if pub.processing_s is not None:
                self.status.processing.add(pub.processing_s)
            self.tracks_pub.publish(tracks_to_cdr(pub.tracks, header, self.layout.name))
            yaws = self.headings.update(pub.tracks)
            self.poses_pub.publish(pose_array_cdr(root_poses(pub.tracks, yaws), header))
            self.tf.publish_tracks(pub.tracks, yaws, header)
            self.status.output_rate.tick()
            if pub.latency:
                self.status.latency.add((self._now_ns() - pub.stamp_ns) / NS_PER_S)
            if self.markers.enabled and self.markers_pub.get_subscription_count() > 0:
                self.markers_pub.publish(tracks_to_markers_cdr(
                    pub.tracks, self.layout.bones, header, self.marker_options))

    def destroy_node(self) -> None:
        """Detach the logging bridge, then destroy the node."""
        logging.getLogger('mv3dpose_ros').removeHandler(self._log_handler)
        super().destroy_node()

    # ------------------------------------------------------------------ diagnostics
    def _diag_inputs(self) -> List[Any]:
        with self._lock:
            return self.status.inputs(steady_ns(), self.diag.expected_rate_hz,
                                      int(self.diag.silent_warn_s * NS_PER_S))

    def _diag_pipeline(self) -> List[Any]:
        with self._lock:
            now = steady_ns()
            sim = bool(self.get_parameter('use_sim_time').value)
            return self.status.pipeline(now) + [self.status.clock(
                self._now_ns(), now, sim, int(self.diag.clock_stall_s * NS_PER_S))]


def main(args: Optional[List[str]] = None) -> int:
    """Entry point of the ``fusion_node`` console script; exit 2 on a bad configuration."""
    return run_node('fusion_node', lambda overrides: FusionNode(), args,
                    config_errors=(ConfigError,), hugepages=False)


if __name__ == '__main__':
    sys.exit(main())
