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
pose2d_node: one camera's ``sensor_msgs/Image`` -> ``mv3dpose_msgs/Person2DArray``.

Topics (relative, so ``-r __ns:=/cam0`` puts them under the camera):

- sub ``image`` (SensorDataQoS, history depth 1; reliability from ``image_qos.reliability``),
  encodings bgr8 / rgb8 / mono8 (and 8UC3 / 8UC1); others are rejected with a rate-limited
  error and counted. Held by a helper node ``<name>_intake`` (see below).
- pub/sub ``rig_rate_topic`` (``std_msgs/Float64``, auto mode): the rig's shared grid rate.
- pub ``persons_2d`` (RELIABLE, KEEP_LAST 10): one message per processed image, header copied
  verbatim, also when empty; images with a zero stamp are rejected (no output).
- pub ``skeleton_info`` (RELIABLE + TRANSIENT_LOCAL, depth 1): the coco17 layout, latched.
- pub ``~/debug_image`` (bgr8): drawn only while someone subscribes.
- pub ``/diagnostics``: input/output rate, inference and whole-path latency, drops, rejects.

Only the newest image is processed. The inference thread takes it from DDS itself when the
model is free (spinning the ``<name>_intake`` helper node, which no executor spins), so images
skipped by the grid or superseded while the model was busy are never copied out of DDS's
shared memory; they are counted from the publication sequence numbers (superseded ones as
dropped). The node is a lifecycle node: the model loads in ``on_configure``, the subscription
exists while active; ``autostart`` (default true) configures and activates it at start-up.
"""

from collections import deque
import math
import os
import struct
import sys
import threading
import time
from typing import Any, Deque, List, Optional, Tuple, Union

from mv3dpose_msgs.msg import Person2DArray, SkeletonInfo, SkippedImages
from mv3dpose_ros.core.skeleton import get_layout
from mv3dpose_ros.core.types import NS_PER_S
from mv3dpose_ros.pose2d.draw import draw_people
from mv3dpose_ros.pose2d.estimator import CPU, DEFAULT_SCORE, ModelError, open_estimator
from mv3dpose_ros.pose2d.estimator import PoseEstimator, resolve_providers
from mv3dpose_ros.pose2d.models import (fetched_sizes, fit_size, get_spec, ModelNotFound,
                                        parse_size, pick_precision, resolve_model_path,
                                        size_tag)
from mv3dpose_ros.pose2d.scheduling import (AUTO_RATES_HZ, AutoInferenceRate, frame_period_ns,
                                            grid_period_ns, grid_selects, on_new_window,
                                            parse_inference_rate, RIG_AUTO_RATES_HZ,
                                            RIG_RATE_PERIOD_S, RigRate, size_ladder)
from mv3dpose_ros.ros.diagnostics import (Diagnostics, ERROR, FrequencyStats, level_value,
                                          make_status, OK, RateLimitedLog, TimestampStats,
                                          WARN, WindowStats)
from mv3dpose_ros.ros.images import decode_image_bytes, ImageError, message_to_numpy
from mv3dpose_ros.ros.images import numpy_to_image
from mv3dpose_ros.ros.memory import reexec_with_hugepages
from mv3dpose_ros.ros.messages import (ns_to_stamp, numpy_to_person2d_array, skeleton_info_msg,
                                       stamp_to_ns)
from mv3dpose_ros.ros.qos import (describe, latched_qos, publisher_events, reliable_qos,
                                  sensor_qos, subscription_events)
from mv3dpose_ros.ros.spin import spin_until_shutdown
from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
import rclpy
from rclpy.clock import Clock, ClockType
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from sensor_msgs.msg import CompressedImage, Image
from std_msgs.msg import Float64

_STAMP = {True: struct.Struct('<iI'), False: struct.Struct('>iI')}


def header_stamp_ns(msg: Any) -> Optional[int]:
    """
    Return the header stamp of an image message or of its serialised CDR bytes.

    In CDR the stamp follows the 4-byte encapsulation header (byte 1 = 1: little endian), so
    the raw subscription reads it without parsing the image. None when too short.
    """
    if isinstance(msg, (bytes, bytearray, memoryview)):
        buf = memoryview(msg)
        if len(buf) < 12:
            return None
        sec, nanosec = _STAMP[buf[1] == 1].unpack_from(buf, 4)
        return sec * NS_PER_S + nanosec
    return stamp_to_ns(msg.header.stamp)


#: Per-image stages timed in /diagnostics (medians): capture stamp -> receipt, receipt ->
#: worker start (waiting behind the previous inference), CDR parse + numpy, letterbox,
#: onnxruntime, NMS + inversion, message build + publish.
STAGES = ('transport', 'wait', 'decode', 'pre', 'inference', 'post', 'publish')

# name -> (default, description, dynamic)
PARAMETERS = {
    'camera_id': ('', 'rig camera name written into every Person2DArray; empty = the last '
                      'component of the node namespace (e.g. cam0 under /cam0)', False),
    'model.name': ('yolo11n-pose', 'registered model used when model.path is empty (see '
                                   '`mv3dpose model list`)', False),
    'model.path': ('', 'explicit ONNX file of a supported family (overrides model.name)', False),
    'model.family': ('auto', 'auto | yolo-pose | movenet-multipose (auto reads the ONNX)', False),
    'model.input_size': ('auto', 'auto: of the fetched sizes of the registered model, the one '
                                 "that fits the first image's aspect (384x640 for 16:9, 640x384 "
                                 'for portrait); with inference_rate_hz auto, smaller fetched '
                                 'sizes down to model.min_input_side are used while the camera '
                                 'outpaces inference. N or HxW: that size, fixed; empty: the '
                                 "model's default. For models with dynamic input it sets the "
                                 'size', False),
    'model.min_input_side': (320, 'smallest long side of the input that model.input_size auto '
                                  'steps down to under load (320: 192x320 for 16:9 images, which '
                                  'still finds every person on the Panoptic frames with 4 '
                                  'cameras, its keypoints about 18 px off those of 640x640; 512 '
                                  'stops at 288x512, 10 px); a value above the chosen size keeps '
                                  'it fixed', False),
    'model.cache_dir': ('', 'model cache (empty = $MV3DPOSE_MODEL_DIR or '
                            '~/.cache/mv3dpose/models)', False),
    'model.threads': (0, 'onnxruntime intra-op threads (0 = one per core; bringup gives each '
                         'of N cameras cores / N)', False),
    'model.precision': ('auto', 'auto | fp32 | int8: variant of the registered model; auto = '
                                'int8 on the CPU where fetched (make setup builds it; 15-20 % '
                                'less time, see README for its accuracy), else fp32', False),
    'model.providers': ('auto', 'onnxruntime execution providers: auto (TensorRT where its '
                                'libraries load, CUDA, OpenVINO, CPU: the first available) or a '
                                'comma-separated list of tensorrt, cuda, openvino, cpu; CPU is '
                                'the fallback', False),
    'score_threshold': (-1.0, '[DYNAMIC] minimum person score; < 0 = family default '
                              '(YOLO 0.25, MoveNet 0.2)', True),
    'keypoint_threshold': (0.0, '[DYNAMIC] keypoint confidences below this are published as 0',
                           True),
    'nms_iou': (0.7, '[DYNAMIC] IoU above which overlapping person boxes are merged (YOLO)',
                True),
    'max_people': (100, '[DYNAMIC] most people published per image', True),
    'image_qos.reliability': ('best_effort', 'input QoS reliability: best_effort (REP-2003 '
                                             'sensor data) | reliable | system_default', False),
    'image_transport': ('raw', 'raw: sensor_msgs/Image on image | compressed: '
                               'sensor_msgs/CompressedImage (JPEG/PNG) on image/compressed, as '
                               "image_transport's compressed plugin publishes it", False),
    'output_qos.depth': (10, 'persons_2d QoS history depth (RELIABLE)', False),
    'debug_image': (True, 'offer ~/debug_image (drawn only while subscribed)', False),
    'debug_min_confidence': (0.3, '[DYNAMIC] keypoints drawn in the debug image from this '
                                  'confidence', True),
    'diagnostics_period_s': (1.0, '/diagnostics publish period [s]', False),
    'min_rate_hz': (0.0, '[DYNAMIC] output rate below which diagnostics WARN (0 = off)', True),
    'no_input_timeout_s': (5.0, '[DYNAMIC] WARN when no image arrived for this long [s]', True),
    'inference_rate_hz': (-1.0, '[DYNAMIC] -1 or auto: every image while the node keeps up; '
                                'when images come faster than it infers, a smaller input, then '
                                '(once over a quarter of the images go uninferred) '
                                "a grid rate it can sustain (measured; the slowest camera's "
                                'for the whole rig, see rig_rate_topic), so the cameras of a '
                                'rig infer common instants; 0: infer the newest image whenever '
                                'the model is free; > 0: infer only the first image of each '
                                '1/rate window of the header stamps (every camera of a '
                                'synchronised rig infers the same instants)', True),
    'rig_rate_topic': ('/mv3dpose/pose2d_auto_rate', 'auto mode: the topic on which the '
                                                     'cameras of a rig announce their grid '
                                                     'rates (std_msgs/Float64); each follows the '
                                                     'slowest, so all infer the same instants, '
                                                     'on a grid of 1.33-1.5x steps '
                                                     '(one topic per rig; empty: each camera '
                                                     'alone)', False),
    'inference_nice': (5, 'nice value of the inference thread (0 = unchanged): on a shared '
                          'CPU the light, latency-critical work (image receipt, publishing, '
                          'fusion) runs before inference instead of queueing behind it', False),
    'autostart': (True, 'configure and activate at start-up (false: wait for lifecycle '
                        'transitions)', False),
}


class Pose2DNode(LifecycleNode):
    """Run a 2D multi-person pose model on one camera's images."""

    def __init__(self, node_name: str = 'pose2d_node', **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        for name, (default, text, dynamic) in PARAMETERS.items():
            self.declare_parameter(name, default, ParameterDescriptor(
                description=text, read_only=not dynamic,
                dynamic_typing=name == 'inference_rate_hz'))   # 1, 1.0 and auto all work
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.layout = get_layout('coco17')
        self.estimator: Optional[PoseEstimator] = None
        self.error = ''
        self.camera_id = ''
        self._sub = None
        self._compressed = False        # image_transport: compressed
        self._pub = self._info_pub = self._debug_pub = self._skipped_pub = None
        #: (publication sequence number, stamp) of the last image whose persons were published
        #: (images not following it are announced on persons_2d/skipped).
        self._published: Tuple[Optional[int], int] = (None, 0)
        self._diag: Optional[Diagnostics] = None
        self._worker: Optional[threading.Thread] = None
        self._cv = threading.Condition()
        self._pending: Union[Image, bytes, None] = None
        self._pending_ns = 0                 # steady clock when the pending image arrived
        self._pending_seq: Optional[int] = None  # its publication sequence number (DDS)
        self._fit_pending = False            # model.input_size auto: choose at the first image
        self._ladder: List[Tuple[int, int]] = []  # sizes auto may use, the fitted one first
        self._estimators: dict = {}          # input size -> opened estimator (ladder steps)
        self._rate_hz = 0.0                  # grid rate in use (0: every image)
        self._auto: Optional[AutoInferenceRate] = None
        self._rig = RigRate()                # auto mode: the rates the rig's cameras announce
        self._rig_pub = self._rig_sub = self._rig_timer = None
        self._grid_stamp: Optional[int] = None   # stamp of the image that opened the window
        self._intake = self._intake_exec = None  # images, taken by the inference thread
        self._last_seq: Optional[int] = None     # publication sequence number of the last one
        # images taken: (arrival wall ns, stamp ns, camera frames since the one before)
        self._taken: Deque[Tuple[int, int, int]] = deque(maxlen=32)
        try:
            self._set_rate(parse_inference_rate(self.get_parameter('inference_rate_hz').value))
            self._rate_error = ''
        except ValueError as exc:
            self._rate_error = str(exc)
        self._stop = False
        self.worker_stuck = False            # the inference thread outlived _stop_worker
        self._stats_lock = threading.Lock()
        self._reset_stats()
        self._rl = RateLimitedLog(lambda text: self.get_logger().error(text), 5.0)
        if self.get_parameter('autostart').value:
            if self.trigger_configure() == TransitionCallbackReturn.SUCCESS:
                self.trigger_activate()

    # -- state ----------------------------------------------------------------------------------
    @property
    def active(self) -> bool:
        """Tell whether the node is in the active lifecycle state."""
        return self._state_machine.current_state[1] == 'active'

    def _reset_stats(self) -> None:
        self.received = self.processed = self.dropped = self.skipped = self.taken = 0
        self.skips_announced = 0             # SkippedImages published (persons_2d/skipped)
        self.rejected_encoding = self.rejected_stamp = self.failed = 0
        self.people_last = 0
        self._in_freq, self._out_freq = FrequencyStats(), FrequencyStats()
        self._stamps = TimestampStats()
        self._infer_ms, self._path_ms = WindowStats(), WindowStats()
        self._stage_ms = {stage: WindowStats() for stage in STAGES}
        self._capture_ms = WindowStats()          # header stamp -> persons_2d published
        self._last_input_ns: Optional[int] = None
        self._rejects_reported = 0

    def _param(self, name: str) -> Any:
        return self.get_parameter(name).value

    def _on_set_parameters(self, params: List[Any]) -> SetParametersResult:
        est = self.estimator
        for p in params:
            if p.name in ('nms_iou', 'keypoint_threshold', 'debug_min_confidence') and not (
                    0.0 <= float(p.value) <= 1.0):
                return SetParametersResult(successful=False, reason=f'{p.name} must be in [0, 1]')
            if p.name == 'max_people' and int(p.value) < 1:
                return SetParametersResult(successful=False, reason='max_people must be >= 1')
            if p.name == 'inference_rate_hz':
                try:
                    parse_inference_rate(p.value)
                except ValueError as exc:
                    return SetParametersResult(successful=False, reason=str(exc))
        for p in params:
            if p.name == 'inference_rate_hz':
                with self._cv:
                    self._set_rate(parse_inference_rate(p.value))
        if est is not None:
            for p in params:
                if p.name == 'score_threshold':
                    est.score_threshold = (float(p.value) if float(p.value) >= 0 else
                                           DEFAULT_SCORE[est.family])
                elif p.name in ('keypoint_threshold', 'nms_iou'):
                    setattr(est, p.name, float(p.value))
                elif p.name == 'max_people':
                    est.max_people = int(p.value)
        return SetParametersResult(successful=True)

    # -- lifecycle ------------------------------------------------------------------------------
    def _open(self, path: str, input_size: Optional[Tuple[int, int]] = None) -> PoseEstimator:
        """Open ``path`` with the node's parameters; log the provider and its options."""
        thr = float(self._param('score_threshold'))
        est = open_estimator(
            path, family=self._param('model.family'), threads=int(self._param('model.threads')),
            input_size=input_size, score_threshold=thr if thr >= 0 else None,
            keypoint_threshold=float(self._param('keypoint_threshold')),
            nms_iou=float(self._param('nms_iou')), max_people=int(self._param('max_people')),
            providers=self._param('model.providers'))
        for text in est.warnings:
            self.get_logger().warning(f'camera {self.camera_id}: {text}')
        options = ', '.join(f'{k}={v}' for k, v in sorted(est.provider_options.items()))
        # A GPU provider sets itself up on its first run (0.2-0.6 s on CUDA, during which the
        # camera's images would be replaced): make that run here, before this model is used.
        ready = f', set up in {est.warm_up():.0f} ms' if est.provider != CPU else ''
        self.get_logger().info(
            f'camera {self.camera_id}: {est.family} model {est.path} input '
            f'{est.input_size[0]}x{est.input_size[1]} {est.precision} on {est.provider} '
            f'({options or "default options"}{ready}), intra-op threads '
            f'{self._param("model.threads") or "one per core"}, score>{est.score_threshold:g}; '
            f'weights licence: {est.licence}')
        return est

    def _set_rate(self, value: float) -> None:
        """Apply a parsed ``inference_rate_hz``: auto (< 0), every image (0) or fixed."""
        rates = RIG_AUTO_RATES_HZ if self._param('rig_rate_topic') else AUTO_RATES_HZ
        self._auto = AutoInferenceRate(self._ladder, rates) if value < 0 else None
        self._rate_hz = max(0.0, value)

    @property
    def inference_rate_hz(self) -> float:
        """Grid rate in use now (0: every image; in auto mode the one chosen)."""
        return self._rate_hz

    def _on_cpu(self) -> bool:
        """Tell whether ``model.providers`` puts the model on the CPU (for precision auto)."""
        try:
            return resolve_providers(self._param('model.providers'))[0][0] == CPU
        except ValueError:                   # reported when the model is opened
            return True

    def _registered_path(self, size: Optional[Tuple[int, int]]) -> str:
        name, cache = self._param('model.name'), self._param('model.cache_dir') or None
        hw = tuple(size) if size else get_spec(name).default_size
        precision = pick_precision(name, hw, cache, self._param('model.precision'),
                                   self._on_cpu())
        return resolve_model_path(name, size_tag(hw), cache, precision)

    def _fetched_sizes(self) -> List[Tuple[int, int]]:
        """Return the sizes of the registered model in the cache: registry order, then others."""
        precision = self._param('model.precision')
        if precision == 'auto':
            precision = ('fp32', 'int8') if self._on_cpu() else 'fp32'
        return fetched_sizes(self._param('model.name'), self._param('model.cache_dir') or None,
                             precision)

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Load the model and create the publishers."""
        ns_last = self.get_namespace().strip('/').split('/')[-1]
        self.camera_id = self._param('camera_id') or ns_last or self.get_name()
        if self._rate_error:
            self.error = self._rate_error
            self.get_logger().error(self.error)
            return TransitionCallbackReturn.FAILURE
        size = str(self._param('model.input_size')).strip().lower()
        self._fit_pending = False
        try:
            path = self._param('model.path')
            if path:
                hw = parse_size(size) if size not in ('', 'auto') else None
            elif size == 'auto':
                spec = get_spec(self._param('model.name'))
                have = self._fetched_sizes()
                # Start on the default size (or any fetched); the first image picks the best.
                hw = spec.default_size if spec.default_size in have or not have else have[0]
                path = self._registered_path(hw)
                self._fit_pending = True
                hw = None
            else:
                path = self._registered_path(parse_size(size) if size else None)
                hw = None
            self.estimator = self._open(path, hw)
        except (ModelError, ModelNotFound, ValueError) as exc:
            self.error = str(exc)
            self.get_logger().error(f'cannot load the pose model: {exc}')
            return TransitionCallbackReturn.FAILURE
        out_qos = reliable_qos(int(self._param('output_qos.depth')))
        self._pub = self.create_publisher(Person2DArray, 'persons_2d', out_qos,
                                          event_callbacks=publisher_events(
                                              self, 'persons_2d', out_qos))
        self._skipped_pub = self.create_publisher(SkippedImages, 'persons_2d/skipped',
                                                  reliable_qos(10))
        self._info_pub = self.create_publisher(SkeletonInfo, 'skeleton_info', latched_qos())
        if self._param('debug_image'):
            self._debug_pub = self.create_publisher(Image, '~/debug_image', reliable_qos(1))
        self._diag = Diagnostics(self, float(self._param('diagnostics_period_s')))
        self._diag.add_task(self._diagnose)
        rig_topic = self._param('rig_rate_topic')
        if rig_topic:
            rig_qos = reliable_qos(10)
            self._rig_pub = self.create_publisher(Float64, rig_topic, rig_qos)
            self._rig_sub = self.create_subscription(Float64, rig_topic, self._on_rig_rate,
                                                     rig_qos)
            # Steady clock: announcements and expiry go on while a bag is paused (sim time).
            self._rig_timer = self.create_timer(RIG_RATE_PERIOD_S, self._rig_tick,
                                                clock=Clock(clock_type=ClockType.STEADY_TIME))
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Publish the skeleton info, subscribe to images and start the inference thread."""
        info = skeleton_info_msg(self.layout)
        info.header.stamp = self.get_clock().now().to_msg()
        self._info_pub.publish(info)
        # History depth 1: the inference thread takes the newest image when it is free.
        qos = sensor_qos(self._param('image_qos.reliability'), 1)
        transport = self._param('image_transport')
        if transport not in ('raw', 'compressed'):
            self.error = f"image_transport must be 'raw' or 'compressed', got {transport!r}"
            self.get_logger().error(self.error)
            return TransitionCallbackReturn.FAILURE
        self._compressed = transport == 'compressed'
        topic = self.resolve_topic_name('image') + '/compressed' if self._compressed else 'image'
        # Images are taken by the inference thread when the model is free, through a helper
        # node that only that thread spins, not by this node's executor: taking a 6 MB image
        # costs 13-25 ms of CPU, and one never taken (skipped by the grid, or superseded while
        # the model was busy) costs almost nothing (it stays in DDS's shared memory).
        # raw=True: the pixels are read in place from the CDR bytes (decode_image_bytes).
        self._last_seq = None
        self._intake = rclpy.create_node(
            f'{self.get_name()}_intake', namespace=self.get_namespace(), context=self.context,
            use_global_arguments=False, enable_rosout=False, start_parameter_services=False)
        self._sub = self._intake.create_subscription(
            CompressedImage if self._compressed else Image, self.resolve_topic_name(topic),
            self._on_taken, qos, event_callbacks=subscription_events(self, topic, qos), raw=True)
        self._intake_exec = SingleThreadedExecutor(context=self.context)
        self._intake_exec.add_node(self._intake)
        self._stop = False
        self._worker = threading.Thread(target=self._work, name=f'pose2d-{self.camera_id}',
                                        daemon=True)
        self._worker.start()
        self.get_logger().info(
            f'{self.resolve_topic_name(topic)} [{describe(qos)}] -> '
            f'{self.resolve_topic_name("persons_2d")} [{describe(reliable_qos())}]')
        return TransitionCallbackReturn.SUCCESS

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Stop taking images and stop the inference thread."""
        self._stop_worker()
        self._close_intake()
        return TransitionCallbackReturn.SUCCESS

    def _close_intake(self) -> None:
        if self._intake_exec is not None:
            self._intake_exec.shutdown(timeout_sec=1.0)
        if self._intake is not None:
            self._intake.destroy_node()
        self._intake = self._intake_exec = self._sub = None

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Release the model and the publishers."""
        self._release()
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Stop everything."""
        self.on_deactivate(state)
        self._release()
        return TransitionCallbackReturn.SUCCESS

    def _release(self) -> None:
        for pub in (self._pub, self._info_pub, self._debug_pub, self._rig_pub,
                    self._skipped_pub):
            if pub is not None:
                self.destroy_publisher(pub)
        self._pub = self._info_pub = self._debug_pub = self._rig_pub = self._skipped_pub = None
        if self._rig_sub is not None:
            self.destroy_subscription(self._rig_sub)
        if self._rig_timer is not None:
            self.destroy_timer(self._rig_timer)
        self._rig_sub = self._rig_timer = None
        if self._diag is not None:
            self._diag.destroy()
            self._diag = None
        self.estimator = None
        self._estimators = {}

    def _stop_worker(self) -> None:
        with self._cv:
            self._stop = True
            self._pending = None
            self._cv.notify_all()
        if self._worker is not None and self._worker is not threading.current_thread():
            self._worker.join(timeout=5.0)
            # still inside native code (a model loading or running on a starved CPU)
            self.worker_stuck = self._worker.is_alive()
        self._worker = None

    def destroy_node(self) -> None:
        """Stop the worker thread before the node goes."""
        self._stop_worker()
        self._close_intake()
        super().destroy_node()

    # -- data path ------------------------------------------------------------------------------
    def _grid_selects(self) -> bool:
        """Tell whether the grid rate skips images: one is set and the camera is faster."""
        return grid_selects(self._rate_hz, frame_period_ns(self._taken))

    def _rate_label(self) -> Union[float, str]:
        """Return the grid rate in use for /diagnostics, or what replaces it."""
        with self._cv:
            if self._grid_selects():
                return self._rate_hz
            return f'{self._rate_hz:g}: every image (camera not faster)' if self._rate_hz \
                else 'every image'

    def _on_grid(self, stamp: Optional[int]) -> bool:
        """Tell whether an image opens a new inference_rate_hz window of header stamps."""
        if stamp is None or stamp <= 0:
            return True                          # rejected later, with the reason
        if not on_new_window(stamp, self._grid_stamp, grid_period_ns(self._rate_hz)):
            return False                          # same window, or slightly out of order
        self._grid_stamp = stamp
        return True

    def _missed_windows(self, stamp: Optional[int], untaken: int) -> int:
        """
        Return the grid windows none of whose images was taken, of ``untaken`` images.

        Between the image that opened the last window and this one: those windows' first
        images were lost (the model was busy for longer than a window), not skipped by the
        grid, so they count as dropped.
        """
        last = self._grid_stamp
        if not untaken or stamp is None or last is None or stamp <= last:
            return 0
        period = grid_period_ns(self._rate_hz)
        return min(untaken, max(0, stamp // period - last // period - 1))

    def _on_taken(self, msg: bytes, info: Any) -> None:
        """Take one image from the intake; count the camera's images never taken before it."""
        seq = info.get('publication_sequence_number') if isinstance(info, dict) else None
        seq = seq if isinstance(seq, int) and seq > 0 else None
        frames = 1
        if seq is not None:
            last, self._last_seq = self._last_seq, seq
            if last is not None and 0 < seq - last < 100_000:     # else a new publisher
                frames = seq - last
        received = info.get('received_timestamp') if isinstance(info, dict) else None
        self._on_image(msg, frames, received if isinstance(received, int) and received > 0
                       else None, seq)

    def _on_image(self, msg: Union[Image, bytes], frames: int = 1,
                  arrived_ns: Optional[int] = None, seq: Optional[int] = None) -> None:
        """
        Keep only the newest image; count the ones it replaces as dropped.

        On a grid, untaken images of windows already inferred count as skipped; those of a
        window none of whose images was taken, as dropped.

        ``frames``: images the camera published since the last one taken (the ones between
        were never taken: skipped by the grid, or superseded while the model was busy);
        ``arrived_ns``: when DDS received it (wall clock; default now); ``seq``: its
        publication sequence number (None when DDS gives none).
        """
        now = self.get_clock().now().nanoseconds
        arrived = arrived_ns or time.time_ns()
        untaken = max(0, frames - 1)
        with self._cv:
            stamp = header_stamp_ns(msg)
            if stamp is not None and stamp > 0:
                if self._auto is not None:
                    self._auto.add_stamp(stamp, frames, time.monotonic())
                self._taken.append((arrived, stamp, frames))
            self.received += frames
            self.taken += 1
            self._last_input_ns = now
            self._in_freq.tick(frames)
            if self._grid_selects():
                missed = self._missed_windows(stamp, untaken)
                self.skipped += untaken - missed
                self.dropped += missed
                if not self._on_grid(stamp):
                    self.skipped += 1
                    return
            else:
                self.dropped += untaken
                if self._auto is not None and untaken:
                    self._auto.add_replaced(untaken, time.monotonic())
            if self._pending is not None:
                self.dropped += 1
                if self._auto is not None:
                    self._auto.add_replaced(1, time.monotonic())
            self._pending, self._pending_ns, self._pending_seq = msg, arrived, seq
            self._cv.notify()

    def _doze_s(self) -> float:
        """
        Return how long to wait before taking the next image, in grid mode.

        The camera's images of the window already inferred are not needed: wait until half a
        frame before the next window's first image can arrive (predicted from the stamps and
        the arrival times of the images taken, with the shortest transport seen, so replays
        faster or slower than real time work), at most one window. Waking early costs one
        take of an image still in the old window; waking up to a frame late still takes the
        window's first image (the newest then). Each image not taken is one 6 MB copy less.
        """
        with self._cv:
            rate, last = self._rate_hz, self._grid_stamp
            taken = list(self._taken)
        frame_ns = frame_period_ns(taken)
        if not grid_selects(rate, frame_ns) or last is None or frame_ns is None:
            return 0.0
        (w0, s0, _), (w1, s1, _) = taken[0], taken[-1]
        period = grid_period_ns(rate)
        start = (last // period + 1) * period             # stamp opening the next window
        if start <= s1:
            return 0.0
        speed = (s1 - s0) / (w1 - w0) if w1 - w0 > NS_PER_S // 2 and s1 > s0 else 1.0
        speed = min(10.0, max(0.1, speed))                 # stamp ns per wall-clock ns
        transport = min(w - s / speed for w, s, _ in taken)   # wall arrival - stamp, shortest
        wake = transport + (start - frame_ns / 2) / speed
        return min(max(0.0, (wake - time.time_ns()) / 1e9), period / speed / 1e9)

    def _take_next(self) -> None:
        """Wait up to 0.1 s for an image and take it (the newest; see on_activate)."""
        doze = self._doze_s()
        if doze > 0.002:
            with self._cv:
                if not self._stop:
                    self._cv.wait(min(doze, 1.0))
            return
        ex = self._intake_exec
        if ex is None:
            with self._cv:
                self._cv.wait(0.1)
            return
        try:
            ex.spin_once(timeout_sec=0.1)
        except Exception as exc:  # noqa: B902 - e.g. shut down while deactivating
            if self._stop:
                return
            if self.context.ok():                # else Ctrl-C shut the context down: no error
                self._rl('intake', f'camera {self.camera_id}: taking an image failed: {exc!r}',
                         self.get_clock().now().nanoseconds)
            time.sleep(0.1)

    def _work(self) -> None:
        nice = int(self._param('inference_nice'))
        if nice > 0 and hasattr(os, 'setpriority'):
            # Only this thread (and onnxruntime's work in it, with 1 intra-op thread): DDS
            # receipt, publishing and the fusion node then get a shared CPU first.
            try:
                os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), nice)
            except OSError as exc:
                self.get_logger().warning(f'camera {self.camera_id}: inference_nice {nice} not '
                                          f'applied: {exc}')
        while True:
            with self._cv:
                if self._stop:
                    return
                msg, self._pending = self._pending, None
                arrived, seq = self._pending_ns, self._pending_seq
            if msg is None:
                self._take_next()
                continue
            t0 = time.monotonic()
            try:
                out = self.process(msg, arrived, seq)
            except Exception as exc:  # noqa: B902 - one bad frame must never stop the node
                out = None
                if not self.context.ok():        # Ctrl-C shut the context down: publish failed
                    continue
                self.failed += 1
                self._rl('failed', f'camera {self.camera_id}: inference failed: {exc!r}',
                         self.get_clock().now().nanoseconds)
            if out is not None:
                self._adapt_rate(time.monotonic() - t0)

    def _adapt_rate(self, seconds: float) -> None:
        """Auto mode: record one image's processing time; apply and log a new size or rate."""
        with self._cv:
            auto = self._auto
            if auto is None:
                return
            auto.add_processing(seconds, time.monotonic())
            old_rate, old_size = auto.rate_hz, auto.size
            if not auto.update(time.monotonic()):
                return
        if auto.rate_hz != old_rate:
            self._announce_rate()
        self._apply_rig_rate()
        if auto.size != old_size:
            self.get_logger().info(
                f'camera {self.camera_id}: model.input_size auto: {size_tag(auto.size)} (was '
                f'{size_tag(old_size)}; steps {", ".join(size_tag(s) for s in auto.sizes)}): '
                f'{auto.reason}')
        if auto.rate_hz != old_rate:
            what = f'{auto.rate_hz:g} Hz' if auto.rate_hz else 'every image'
            self.get_logger().info(
                f'camera {self.camera_id}: inference_rate_hz auto: {what} (was '
                f'{f"{old_rate:g} Hz" if old_rate else "every image"}): {auto.reason}')

    def _announce_rate(self) -> None:
        """Auto mode: tell the rig's other cameras the grid rate this one can sustain."""
        auto, pub = self._auto, self._rig_pub
        if auto is not None and pub is not None:
            pub.publish(Float64(data=float(auto.rate_hz)))

    def _on_rig_rate(self, msg: Float64) -> None:
        if not self._rig.hear(float(msg.data), time.monotonic()):
            self._rl('rig_rate', f'camera {self.camera_id}: ignored a rate of {msg.data!r} Hz '
                                 f'on {self._param("rig_rate_topic")} (0 or a finite rate > 0 '
                                 'expected)', self.get_clock().now().nanoseconds)
            return
        self._apply_rig_rate()

    def _rig_tick(self) -> None:
        self._announce_rate()
        self._apply_rig_rate()              # announcements expire

    def _apply_rig_rate(self) -> None:
        """Auto mode: use the slowest of this camera's rate and the rig's; log a change."""
        with self._cv:
            auto = self._auto
            if auto is None:
                return
            old = self._rate_hz
            common = self._rig.common(auto.rate_hz, time.monotonic())
            # Snapped to this node's grid rates, so every camera computes the same period.
            self._rate_hz = auto.fastest(common) if common > 0 else 0.0
            new, own = self._rate_hz, auto.rate_hz
        if new != old:
            what = f'{new:g} Hz' if new else 'every image'
            why = ('its own choice' if new == own else
                   f'the slowest camera of the rig on {self._param("rig_rate_topic")} (its own '
                   f'choice: {f"{own:g} Hz" if own else "every image"})')
            self.get_logger().info(f'camera {self.camera_id}: inference rate {what}: {why}')

    def _fit_to(self, image_hw: Tuple[int, int]) -> None:
        """At the first image: choose the fetched input size that fits it, and the ladder."""
        self._fit_pending = False
        spec = get_spec(self._param('model.name'))
        est = self.estimator
        best = fit_size(spec.sizes, image_hw)
        have = self._fetched_sizes()
        usable = fit_size(have, image_hw) if have else tuple(est.input_size)
        h, w = image_hw
        if best != usable:
            self.get_logger().warning(
                f'camera {self.camera_id}: {w}x{h} images fit the {size_tag(best)} input of '
                f'{spec.name} best (same detail, less padding, faster); it is not fetched: '
                f'run `mv3dpose model fetch --model {spec.name} --size {size_tag(best)}`')
        ladder = size_ladder(image_hw, usable, have, int(self._param('model.min_input_side')))
        with self._cv:
            self._ladder = ladder
            if self._auto is not None:
                self._auto.set_sizes(ladder)
        steps = (f'; under load inference_rate_hz auto may step down to '
                 f'{", ".join(size_tag(s) for s in ladder[1:])}' if len(ladder) > 1 else '')
        self._use_size(usable)
        self.get_logger().info(f'camera {self.camera_id}: input size {size_tag(usable)} for '
                               f'{w}x{h} images (model.input_size auto){steps}')

    def _use_size(self, size: Tuple[int, int]) -> None:
        """Make ``size`` the input size in use (a registered model's file, opened once)."""
        est = self.estimator
        if est is None or tuple(est.input_size) == tuple(size):
            return
        self._estimators.setdefault(tuple(est.input_size), est)
        new = self._estimators.get(tuple(size))
        if new is None:
            new = self._estimators[tuple(size)] = self._open(self._registered_path(size))
        for name in ('score_threshold', 'keypoint_threshold', 'nms_iou', 'max_people'):
            setattr(new, name, getattr(est, name))      # dynamic values set since configure
        self.estimator = new

    def _wanted_size(self) -> Optional[Tuple[int, int]]:
        """Return the input size auto mode wants now (None: keep the one in use)."""
        auto = self._auto
        if auto is not None and auto.size is not None:
            return auto.size
        return self._ladder[0] if self._ladder else None

    def process(self, msg: Union[Image, bytes], arrived_ns: Optional[int] = None,
                seq: Optional[int] = None) -> Optional[Person2DArray]:
        """
        Run the whole path on one image and publish; return the message (None if rejected).

        ``msg`` is an ``Image`` or its serialised CDR bytes (what the raw subscription gets);
        ``arrived_ns`` the wall-clock time it was received (for the transport/wait stages),
        ``seq`` its publication sequence number (images skipped since the last published one
        are announced on persons_2d/skipped before the model runs).
        """
        t0 = time.perf_counter()
        started_ns = time.time_ns()
        data = None
        if isinstance(msg, (bytes, bytearray, memoryview)):
            msg, data = decode_image_bytes(msg, self._compressed)
        now = self.get_clock().now().nanoseconds
        stamp = stamp_to_ns(msg.header.stamp)
        with self._stats_lock:
            self._stamps.record(stamp, now)
        if stamp == 0:
            self.rejected_stamp += 1
            self._rl('stamp', f'camera {self.camera_id}: image with a zero header stamp on '
                     f'{self.resolve_topic_name("image")} rejected: the driver must stamp images '
                     'with their capture time (fusion synchronises on it)', now)
            return None
        self._announce_skipped(msg.header, stamp, seq)
        try:
            image, order = message_to_numpy(msg, data)
        except ImageError as exc:
            self.rejected_encoding += 1
            self._rl('image', f'camera {self.camera_id}: image on '
                     f'{self.resolve_topic_name("image")} rejected: {exc}', now)
            return None
        t_decoded = time.perf_counter()
        if self._fit_pending:
            try:
                self._fit_to(image.shape[:2])
            except (ModelError, ModelNotFound, ValueError) as exc:
                self.get_logger().warning(f'camera {self.camera_id}: keeping input size '
                                          f'{size_tag(self.estimator.input_size)}: {exc}')
            t0 += time.perf_counter() - t_decoded          # a one-off, not image path time
            t_decoded = time.perf_counter()
        wanted = self._wanted_size()
        if wanted is not None and wanted != tuple(self.estimator.input_size):
            try:
                self._use_size(wanted)
            except (ModelError, ModelNotFound, ValueError) as exc:
                self._ladder = [tuple(self.estimator.input_size)]
                if self._auto is not None:
                    self._auto.set_sizes(self._ladder)
                self.get_logger().warning(f'camera {self.camera_id}: keeping input size '
                                          f'{size_tag(self.estimator.input_size)}: {exc}')
            t0 += time.perf_counter() - t_decoded          # a one-off (cached after)
            t_decoded = time.perf_counter()
        est = self.estimator
        det = est.infer(image, order)
        t_inferred = time.perf_counter()
        out = numpy_to_person2d_array(det.keypoints, msg.header, self.camera_id, image.shape[1],
                                      image.shape[0], self.layout.name, det.boxes, det.scores)
        pub = self._pub
        if pub is None:
            return out
        pub.publish(out)
        self._published = (seq, stamp)
        debug = self._debug_pub
        if debug is not None and debug.get_subscription_count() > 0:
            drawn = draw_people(image if order != 'rgb' else image[..., ::-1], det.keypoints,
                                det.boxes, det.scores, self.layout.bones,
                                float(self._param('debug_min_confidence')))
            debug.publish(numpy_to_image(drawn, msg.header, 'bgr8'))
        t_end = time.perf_counter()
        capture_ms = (time.time_ns() - stamp) / 1e6
        timing = est.last_timing
        stages = {'decode': (t_decoded - t0) * 1e3, 'pre': timing.pre_ms,
                  'inference': timing.infer_ms, 'post': timing.post_ms,
                  'publish': (t_end - t_inferred) * 1e3}
        if arrived_ns is not None:
            # Capture stamp -> receipt; meaningful when the camera stamps with this clock.
            stages['transport'] = (arrived_ns - stamp) / 1e6
            stages['wait'] = (started_ns - arrived_ns) / 1e6
        with self._stats_lock:
            self.processed += 1
            self.people_last = len(det)
            self._out_freq.tick()
            self._infer_ms.add(timing.infer_ms)
            self._path_ms.add((t_end - t0) * 1e3)
            for name, ms in stages.items():
                self._stage_ms[name].add(ms)
            self._capture_ms.add(capture_ms)
        return out

    def _announce_skipped(self, header: Any, stamp: int, seq: Optional[int]) -> None:
        """
        Tell the fusion node that no persons will come for the images before this one.

        Only when this image does not follow the last one published (by the camera's
        publication sequence numbers): the ones between were replaced while the model was
        busy, skipped by the grid, rejected or failed. The fusion node then stops waiting
        for them. Needs the sequence numbers (a raw subscription's message info).
        """
        last_seq, last_stamp = self._published
        pub = self._skipped_pub
        if pub is None or seq is None or (last_seq is not None and seq == last_seq + 1) or \
                stamp <= last_stamp:
            return
        note = SkippedImages(header=header, camera_id=self.camera_id,
                             after=ns_to_stamp(last_stamp))
        pub.publish(note)
        with self._stats_lock:
            self.skips_announced += 1

    # -- diagnostics ----------------------------------------------------------------------------
    def _diagnose(self) -> list:
        now = self.get_clock().now().nanoseconds
        with self._stats_lock:
            out_level, out_text, values = self._out_freq.sample(now)
            _, _, in_values = self._in_freq.sample(now)
            ts_level, ts_text, ts_values = self._stamps.sample()
            infer50, infer95 = self._infer_ms.percentile(50), self._infer_ms.percentile(95)
            path50 = self._path_ms.percentile(50)
            stage50 = {f'Stage {name} median (ms)': st.percentile(50)
                       for name, st in self._stage_ms.items()}
            stage50['Capture to publish median (ms)'] = self._capture_ms.percentile(50)
            stage50['Capture to publish p95 (ms)'] = self._capture_ms.percentile(95)
        rate_in = in_values['Actual frequency (Hz)']
        values = {'Input frequency (Hz)': rate_in, **values, **ts_values,
                  'Inference latency median (ms)': infer50, 'Inference latency p95 (ms)': infer95,
                  'Whole path median (ms)': path50, **stage50, 'Images received': self.received,
                  'Images taken from DDS (copied)': self.taken,
                  'Images processed': self.processed,
                  'Dropped before inference (newer image arrived)': self.dropped,
                  'Skipped (inference_rate_hz grid)': self.skipped,
                  'Skips announced (persons_2d/skipped)': self.skips_announced,
                  'Inference rate mode': ('auto' if self._auto is not None else
                                          'fixed' if self._rate_hz else 'every image'),
                  'Inference rate (Hz)': self._rate_label(),
                  'Inference rate, own choice (auto)': (
                      'n/a' if self._auto is None else self._auto.rate_hz or 'every image'),
                  'Inference rate, rig slowest (auto)': (
                      self._rig.slowest(time.monotonic()) or 'none announced'),
                  'Rejected (encoding/size)': self.rejected_encoding,
                  'Rejected (zero stamp)': self.rejected_stamp, 'Inference failures': self.failed,
                  'People in last image': self.people_last}
        est = self.estimator
        if est is not None:
            values.update({'Model': est.path, 'Model family': est.family,
                           'Input size (HxW)': f'{est.input_size[0]}x{est.input_size[1]}',
                           'Input size steps (auto)': ', '.join(size_tag(z) for z in self._ladder)
                           or 'fixed',
                           'Precision': est.precision, 'Execution provider': est.provider,
                           'Intra-op threads': int(self._param('model.threads')),
                           'Weights licence': est.licence})
        level, text = OK, out_text
        rejects = self.rejected_encoding + self.failed
        timeout = float(self._param('no_input_timeout_s'))
        min_rate = float(self._param('min_rate_hz'))
        if level_value(ts_level) >= level_value(ERROR):
            level, text = ERROR, ts_text
        if rejects > self._rejects_reported:
            level, text = ERROR, 'images rejected (see the log for why)'
            self._rejects_reported = rejects
        elif self._last_input_ns is None or now - self._last_input_ns > timeout * 1e9:
            if level_value(level) < level_value(WARN):
                level = WARN
                text = (f'no input on {self.resolve_topic_name("image")} for {timeout:g} s '
                        '(check the remapping, and the QoS: the publisher must be compatible '
                        f'with {self._param("image_qos.reliability")})')
        elif (min_rate > 0 and math.isfinite(values['Actual frequency (Hz)'])
              and values['Actual frequency (Hz)'] < min_rate
              and level_value(level) == level_value(OK)):
            level, text = WARN, f'output rate below {min_rate:g} Hz'
        elif self.dropped and level_value(level) == level_value(OK):
            share = 100.0 * self.dropped / max(1, self.received)
            text = (f'{out_text}; inference slower than the input: {self.dropped} of '
                    f'{self.received} images ({share:.0f} %) dropped before inference, '
                    'newest kept')
        return [make_status(self._diag.name(f'{self.camera_id} inference'), level, text,
                            hardware_id=self.camera_id, values=values)]


def main(args: Optional[List[str]] = None) -> int:
    """Run one pose2d node until interrupted; exit 1 when the model cannot be loaded."""
    if args is None:
        reexec_with_hugepages()         # 6 MB images with 2 MiB page faults (ros/memory.py)
    rclpy.init(args=args)
    node = None
    code = 0
    try:
        node = Pose2DNode()
        if node.get_parameter('autostart').value and not node.active:
            node.get_logger().fatal(f'not started: {node.error}')
            code = 1
        else:
            executor = SingleThreadedExecutor()
            executor.add_node(node)
            spin_until_shutdown(executor)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    if node is not None and node.worker_stuck:
        # Exiting normally would run onnxruntime's and DDS's C++ destructors under the thread
        # still inside them, which can hang the process until SIGKILL.
        print('[pose2d_node] the inference thread did not stop within 5 s (inside the model); '
              'exiting without waiting for it', file=sys.stderr, flush=True)
        sys.stdout.flush()
        os._exit(code)
    return code


if __name__ == '__main__':
    sys.exit(main())
