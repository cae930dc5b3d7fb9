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

This is the ROS wiring. Parameters: ``pose2d.config``; logic: ``pose2d.intake``,
``.scheduling``, ``.auto_rate``, ``.sizing``; this node's ROS parts beside it in
``nodes.pose2d``: ``.image_intake``, ``.rig_rate``, ``.diagnostics``.
"""

import sys
import threading
import time
from typing import Any, List, Optional, Tuple, Union

from mv3dpose_msgs.msg import Person2DArray, SkeletonInfo, SkippedImages
from mv3dpose_ros.core.skeleton import get_layout
from mv3dpose_ros.nodes.pose2d.diagnostics import Pose2DStats, Pose2DStatus
from mv3dpose_ros.nodes.pose2d.image_intake import ImageIntake
from mv3dpose_ros.nodes.pose2d.rig_rate import RigRateLink
from mv3dpose_ros.pose2d.auto_rate import GridRate, RIG_RATE_PERIOD_S
from mv3dpose_ros.pose2d.config import ModelConfig, parameter_error, Pose2DConfig
from mv3dpose_ros.pose2d.draw import draw_people
from mv3dpose_ros.pose2d.estimator import (CPU, ModelError, open_estimator, PoseEstimator,
                                           resolve_providers)
from mv3dpose_ros.pose2d.intake import (header_stamp_ns, ImageMailbox, InferenceThread,
                                        skipped_before)
from mv3dpose_ros.pose2d.models import ModelNotFound
from mv3dpose_ros.pose2d.scheduling import parse_inference_rate
from mv3dpose_ros.pose2d.sizing import describe, EstimatorCache
from mv3dpose_ros.ros import params as P
from mv3dpose_ros.ros.diagnostics import Diagnostics, RateLimitedLog
from mv3dpose_ros.ros.images import (decode_image_bytes, ImageError, message_to_numpy,
                                     numpy_to_image)
from mv3dpose_ros.ros.messages import (ns_to_stamp, numpy_to_person2d_array, skeleton_info_msg,
                                       stamp_to_ns)
from mv3dpose_ros.ros.qos import describe as describe_qos
from mv3dpose_ros.ros.qos import latched_qos, publisher_events, reliable_qos, sensor_qos
from mv3dpose_ros.ros.spin import run_node
from rcl_interfaces.msg import SetParametersResult
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from sensor_msgs.msg import CompressedImage, Image

__all__ = ['header_stamp_ns', 'main', 'parse_inference_rate', 'Pose2DNode']
SUCCESS, FAILURE = TransitionCallbackReturn.SUCCESS, TransitionCallbackReturn.FAILURE


class Pose2DNode(LifecycleNode):
    """Run a 2D multi-person pose model on one camera's images."""

    estimator = property(lambda self: self._sizes and self._sizes.estimator,
                         doc='The estimator in use (None unless configured).')

    def __init__(self, node_name: str = 'pose2d_node', **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        P.declare_config(self, Pose2DConfig)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.layout = get_layout('coco17')
        self.error = self.camera_id = ''
        self._sizes: Optional[EstimatorCache] = None
        self._intake: Optional[ImageIntake] = None   # images, taken by the inference thread
        self._compressed = False        # image_transport: compressed
        self._pub = self._info_pub = self._debug_pub = self._skipped_pub = None
        self._rig: Optional[RigRateLink] = None
        #: (publication sequence number, stamp) of the last image whose persons were published
        self._published: Tuple[Optional[int], int] = (None, 0)
        self._diag: Optional[Diagnostics] = None
        self._rate = GridRate(shared=bool(self._param('rig_rate_topic')))
        self._mailbox = ImageMailbox(self._rate)
        self._worker: Optional[InferenceThread] = None
        self.worker_stuck = False            # the inference thread outlived _stop_worker
        self._status = Pose2DStatus()
        self._rl = RateLimitedLog(lambda text: self.get_logger().error(text), 5.0)
        self._rate_error = parameter_error('inference_rate_hz', self._param('inference_rate_hz'))
        if not self._rate_error:
            self._rate.use(parse_inference_rate(self._param('inference_rate_hz')))
        if self._param('autostart') and self.trigger_configure() == SUCCESS:
            self.trigger_activate()

    @property
    def active(self) -> bool:
        """Tell whether the node is in the active lifecycle state."""
        return self._state_machine.current_state[1] == 'active'

    @property
    def stats(self) -> Pose2DStats:
        """Return the camera's image counts and inference rate now, as /diagnostics has them."""
        return self._status.stats(self._mailbox, self._rate)

    def _param(self, name: str) -> Any:
        return self.get_parameter(name).value

    def _say(self, level: str, text: str) -> None:
        """Log at 'info' or 'warning' (rclpy wants one severity per call site)."""
        if level == 'warning':
            self.get_logger().warning(f'camera {self.camera_id}: {text}')
        else:
            self.get_logger().info(f'camera {self.camera_id}: {text}')

    def _complain(self, key: str, text: str) -> None:
        """Log an error at most every 5 s per ``key``."""
        self._rl(key, f'camera {self.camera_id}: {text}', self.get_clock().now().nanoseconds)

    def _on_set_parameters(self, params: List[Any]) -> SetParametersResult:
        for p in params:
            reason = parameter_error(p.name, p.value)
            if reason:
                return SetParametersResult(successful=False, reason=reason)
        for p in params:
            if p.name == 'inference_rate_hz':
                self._rate.use(parse_inference_rate(p.value),
                               self._sizes.ladder if self._sizes else [])
            elif self._sizes is not None:
                self._sizes.set_value(p.name, p.value)
        return SetParametersResult(successful=True)

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
            self._say('warning', text)
        # A GPU provider sets itself up on its first run (0.2-0.6 s on CUDA, during which the
        # camera's images would be replaced): make that run here, before this model is used.
        ready_ms = est.warm_up() if est.provider != CPU else None
        self._say('info', describe(est, self._param('model.threads'), ready_ms))
        return est

    def _on_cpu(self) -> bool:
        """Tell whether ``model.providers`` puts the model on the CPU (for precision auto)."""
        try:
            return resolve_providers(self._param('model.providers'))[0][0] == CPU
        except ValueError:                   # reported when the model is opened
            return True

    # -- lifecycle --------------------------------------------------------------------------------
    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Load the model and create the publishers."""
        ns_last = self.get_namespace().strip('/').split('/')[-1]
        self.camera_id = self._param('camera_id') or ns_last or self.get_name()
        if self._rate_error:
            self.error = self._rate_error
            self.get_logger().error(self.error)
            return FAILURE
        try:
            self._sizes = EstimatorCache(P.build_config(self, ModelConfig, 'model'), self._open,
                                         self._on_cpu, self._rate.set_sizes)
            self._sizes.load()
        except (ModelError, ModelNotFound, ValueError) as exc:
            self._sizes, self.error = None, str(exc)
            self.get_logger().error(f'cannot load the pose model: {exc}')
            return FAILURE
        qos = reliable_qos(int(self._param('output_qos.depth')))
        self._pub = self.create_publisher(Person2DArray, 'persons_2d', qos, event_callbacks=(
            publisher_events(self, 'persons_2d', qos)))
        self._skipped_pub = self.create_publisher(SkippedImages, 'persons_2d/skipped',
                                                  reliable_qos(10))
        self._info_pub = self.create_publisher(SkeletonInfo, 'skeleton_info', latched_qos())
        if self._param('debug_image'):
            self._debug_pub = self.create_publisher(Image, '~/debug_image', reliable_qos(1))
        self._diag = Diagnostics(self, float(self._param('diagnostics_period_s')))
        self._diag.add_task(self._diagnose)
        if self._param('rig_rate_topic'):
            self._rig = RigRateLink(self, self._param('rig_rate_topic'), self._rate,
                                    RIG_RATE_PERIOD_S, self._share_rate,
                                    lambda text: self._complain('rig_rate', text))
        return SUCCESS

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
            return FAILURE
        self._compressed = transport == 'compressed'
        topic = self.resolve_topic_name('image') + '/compressed' if self._compressed else 'image'
        self._mailbox.start()
        self._intake = ImageIntake(self, topic, CompressedImage if self._compressed else Image,
                                   qos, self._on_taken)
        self._worker = InferenceThread(
            self._mailbox, f'pose2d-{self.camera_id}', int(self._param('inference_nice')),
            lambda timeout_s: self._intake is not None and self._intake.take(timeout_s),
            self.process, self._adapt_rate, self._worker_trouble)
        self._worker.start()
        self.get_logger().info(
            f'{self.resolve_topic_name(topic)} [{describe_qos(qos)}] -> '
            f'{self.resolve_topic_name("persons_2d")} [{describe_qos(reliable_qos())}]')
        return SUCCESS

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Stop the inference thread and stop taking images."""
        self._stop_worker()
        return SUCCESS

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Release the model and the publishers."""
        self._release()
        return SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Stop everything."""
        self._stop_worker()
        self._release()
        return SUCCESS

    def _release(self) -> None:
        for pub in (self._pub, self._info_pub, self._debug_pub, self._skipped_pub):
            if pub is not None:
                self.destroy_publisher(pub)
        self._pub = self._info_pub = self._debug_pub = self._skipped_pub = None
        for part in (self._rig, self._diag):
            if part is not None:
                part.destroy()
        self._rig = self._diag = self._sizes = None

    def _stop_worker(self) -> None:
        """Stop the inference thread (5 s at most), then the intake."""
        self._mailbox.close()
        worker, self._worker = self._worker, None
        if worker is not None and worker is not threading.current_thread():
            worker.join(timeout=5.0)
            # still inside native code (a model loading or running on a starved CPU)
            self.worker_stuck = worker.is_alive()
        intake, self._intake = self._intake, None
        if intake is not None:
            intake.close()

    def destroy_node(self) -> None:
        """Stop the worker thread before the node goes."""
        self._stop_worker()
        super().destroy_node()

    # -- data path --------------------------------------------------------------------------------
    def _on_taken(self, msg: bytes, info: Any) -> None:
        """Take one image from the intake; count the camera's images never taken before it."""
        self.offer(msg, *self._mailbox.arrival(info))

    def offer(self, msg: Union[Image, bytes], frames: int = 1, arrived_ns: Optional[int] = None,
              seq: Optional[int] = None) -> None:
        """
        Offer one image to the model, as the intake does (``pose2d.intake.ImageMailbox.offer``).

        ``frames``: the camera images it stands for (those never taken before it counted);
        ``arrived_ns``: when it was received (default now); ``seq``: its sequence number.
        """
        self._status.received(frames, self.get_clock().now().nanoseconds)
        self._mailbox.offer(msg, frames, arrived_ns or time.time_ns(), seq, time.monotonic())

    def _worker_trouble(self, what: str, exc: BaseException) -> None:
        """Inference thread: log trouble ('nice', 'intake', 'failed'); count failures."""
        if what == 'nice':
            self._say('warning', f'inference_nice {self._param("inference_nice")} not applied: '
                      f'{exc}')
        elif self.context.ok():             # else Ctrl-C shut the context down: no error
            if what == 'failed':
                with self._status.lock:
                    self._status.failed += 1
            text = 'inference failed' if what == 'failed' else 'taking an image failed'
            self._complain(what, f'{text}: {exc!r}')

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
        stamp = stamp_to_ns(msg.header.stamp)
        self._status.stamp(stamp, self.get_clock().now().nanoseconds)
        if stamp == 0:
            with self._status.lock:
                self._status.rejected_stamp += 1
            self._complain('stamp', f'image with a zero header stamp on '
                           f'{self.resolve_topic_name("image")} rejected: the driver must stamp '
                           'images with their capture time (fusion synchronises on it)')
            return None
        self._announce_skipped(msg.header, stamp, seq)
        try:
            image, order = message_to_numpy(msg, data)
        except ImageError as exc:
            with self._status.lock:
                self._status.rejected_encoding += 1
            self._complain('image', f'image on {self.resolve_topic_name("image")} rejected: '
                           f'{exc}')
            return None
        t_decoded = time.perf_counter()
        notes = self._sizes.follow(image.shape[:2], lambda: self._rate.size)
        if notes is not None:                  # a one-off (fitted, or opened once), not path
            for level, text in notes:
                self._say(level, text)
            t0 += time.perf_counter() - t_decoded
            t_decoded = time.perf_counter()
        est = self._sizes.estimator
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
        self._status.published(len(det), est.last_timing, (t0, t_decoded, t_inferred,
                               time.perf_counter()), stamp, arrived_ns, started_ns)
        return out

    def _announce_skipped(self, header: Any, stamp: int, seq: Optional[int]) -> None:
        """Tell the fusion node that no persons will come for images before this one."""
        pub, (last_seq, last_stamp) = self._skipped_pub, self._published
        if pub is not None and skipped_before(last_seq, last_stamp, seq, stamp):
            pub.publish(SkippedImages(header=header, camera_id=self.camera_id,
                                      after=ns_to_stamp(last_stamp)))
            with self._status.lock:
                self._status.skips_announced += 1

    # -- inference rate: auto mode and the rig's shared rate ------------------------------------
    def _adapt_rate(self, seconds: float) -> None:
        """Auto mode: record one image's processing time; apply and log a new size or rate."""
        change = self._rate.adapt(seconds, time.monotonic())
        if change is None:
            return
        announce, notes = change
        if announce and self._rig is not None:
            self._rig.announce()
        self._share_rate()
        for text in notes:
            self._say('info', text)

    def _share_rate(self) -> None:
        """Auto mode: use the slowest of this camera's rate and the rig's; log a change."""
        text = self._rate.share(time.monotonic(), self._param('rig_rate_topic'))
        if text:
            self._say('info', text)

    def _diagnose(self) -> list:
        return [self._status.status(
            self._diag.name(f'{self.camera_id} inference'), self.camera_id,
            self.get_clock().now().nanoseconds, self._mailbox, self._mailbox.rate_values(),
            self._sizes.values() if self._sizes is not None else {},
            float(self._param('no_input_timeout_s')), float(self._param('min_rate_hz')),
            self.resolve_topic_name('image'), self._param('image_qos.reliability'))]


def _not_started(node: Pose2DNode) -> Optional[str]:
    """Return why an autostarting node is not active (the model could not be loaded...)."""
    return node.error if node.get_parameter('autostart').value and not node.active else None


def _stuck(node: Pose2DNode) -> str:
    return ('the inference thread did not stop within 5 s (inside the model); exiting without '
            'waiting for it') if node.worker_stuck else ''


def main(args: Optional[List[str]] = None) -> int:
    """Run one pose2d node until interrupted; exit 1 when the model cannot be loaded."""
    return run_node('pose2d_node', lambda overrides: Pose2DNode(), args,
                    not_started=_not_started, stuck=_stuck)


if __name__ == '__main__':
    sys.exit(main())
