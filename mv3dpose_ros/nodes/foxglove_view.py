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
foxglove_view: a live web view of the pipeline over the Foxglove WebSocket protocol.

Subscribes over DDS to the tracks, the per-camera 2D detections and (optionally) the camera
images, and serves them with ``foxglove-sdk`` on ``ws://127.0.0.1:8765`` (loopback by default),
so Foxglove (desktop, or the web app) connects with no ROS install:

- ``/mv3dpose/scene`` (``foxglove.SceneUpdate``): one skeleton entity per track, coloured by id,
  with a label; ended tracks deleted (``viz/scene.py``);
- ``/mv3dpose/cameras`` (``foxglove.SceneUpdate``): the camera frustums of ``rig_config``,
  re-sent every ``cameras_period_s`` so a client that connects later gets them;
- the tracks topic and each camera's detections topic, forwarded byte for byte as ROS 2 channels
  (``cdr`` messages, ``ros2msg`` schemas with every nested definition), which Foxglove's Raw
  Messages and Plot panels decode;
- with ``image_topic`` set, ``/<camera>/image_skeletons`` (``foxglove.CompressedImage``, JPEG):
  each image with the 2D skeletons of the detections carrying its stamp drawn on it. A
  camera's images are subscribed only while a client subscribes to its channel: receiving a
  1080p image costs 8-10 ms of CPU whether it is drawn or not.

A separate process, so fusion_node stays lean and the WebSocket server cannot stall it. A message
that cannot be read is logged (rate-limited, naming topic and reason), dropped, and counted on
``/diagnostics`` (``foxglove_view: web view``, WARN in the cycle that saw new drops).
"""

import argparse
from collections import Counter, deque
import sys
import time
from typing import Any, Deque, Dict, List, Optional, Tuple

import cv2
import foxglove
from foxglove.channels import CompressedImageChannel, SceneUpdateChannel
from foxglove.messages import CompressedImage as FoxgloveCompressedImage
from mv3dpose_msgs.msg import Person2DArray, TrackedSkeletonArray
from mv3dpose_ros.core.geometry.calibration import load_calibration, rig_metadata
from mv3dpose_ros.core.skeleton import get_layout
from mv3dpose_ros.io.bag import get_typestore
from mv3dpose_ros.pose2d.draw import draw_people
from mv3dpose_ros.ros import params as P
from mv3dpose_ros.ros.diagnostics import Diagnostics, make_status, OK, RateLimitedLog, WARN
from mv3dpose_ros.ros.images import decode_image_bytes, ImageError, message_to_numpy
from mv3dpose_ros.ros.messages import (decode_person2d_array, InvalidMessage, msg_to_tracks,
                                       person2d_array_to_numpy, stamp_to_ns)
from mv3dpose_ros.ros.names import camera_topic
from mv3dpose_ros.ros.qos import reliable_qos, sensor_qos
from mv3dpose_ros.ros.spin import run_node
from mv3dpose_ros.viz.scene import camera_update, skeleton_update
import numpy as np
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import Image

SCENE_TOPIC = '/mv3dpose/scene'
CAMERAS_TOPIC = '/mv3dpose/cameras'
TRACKS_TYPE = 'mv3dpose_msgs/msg/TrackedSkeletonArray'
PERSONS_TYPE = 'mv3dpose_msgs/msg/Person2DArray'
IMAGES_KEPT = 6      # per camera, waiting for their detections (0.2 s at 30 Hz; 36 MB at 1080p)
IMAGE_WATCH_S = 0.2  # how often the image subscriptions follow the clients' subscriptions


def ros2_schema(msgtype: str) -> foxglove.Schema:
    """Return the ``ros2msg`` schema of ``msgtype`` with its nested definitions."""
    text, _ = get_typestore().generate_msgdef(msgtype, ros_version=2)
    return foxglove.Schema(name=msgtype, encoding='ros2msg', data=text.encode())


class FoxgloveView(Node):
    """DDS subscriptions in, Foxglove WebSocket channels out."""

    def __init__(self, node_name: str = 'foxglove_view', **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        d = P.declare
        d(self, 'host', '127.0.0.1', 'Address the WebSocket server binds (loopback by default; '
          '0.0.0.0 serves the network)', read_only=True)
        d(self, 'port', 8765, 'WebSocket port (Foxglove default 8765)', read_only=True)
        d(self, 'tracks_topic', '/fusion_node/tracks', 'TrackedSkeletonArray topic',
          read_only=True)
        d(self, 'rig_config', '', 'Rig calibration: camera frustums and the cameras whose '
          'detections are forwarded; empty = no cameras', read_only=True)
        d(self, 'camera_ids', [], 'Cameras of the rig to show; empty = all', read_only=True)
        d(self, 'detections_topic', '/{camera}/persons_2d', 'Person2DArray topic per camera '
          '({camera} = its ROS name); empty = not forwarded', read_only=True)
        d(self, 'image_topic', '', 'sensor_msgs/Image topic per camera to draw the 2D '
          'skeletons on (e.g. /{camera}/image_raw); empty = no images', read_only=True)
        d(self, 'image_max_width', 960, 'Images wider than this are scaled down [px]',
          read_only=True)
        d(self, 'world_frame', '', 'Frame of the camera frustums (tracks keep theirs); empty = '
          "the rig file's world_frame, else map (as fusion_node)", read_only=True)
        d(self, 'frustum_depth_m', 0.5, 'Depth of the drawn camera frustums [m]',
          read_only=True)
        d(self, 'scene_lifetime_s', 0.5, 'Lifetime of skeleton entities [s] (safety net)',
          read_only=True)
        d(self, 'cameras_period_s', 1.0, 'Period [s] of re-sending the camera frustums',
          read_only=True)

        def v(name: str) -> Any:
            return P.value(self, name)

        self.counts: Counter = Counter()
        self._rlog = RateLimitedLog(self.get_logger().warning, 5.0)
        self.world_frame = v('world_frame') or 'map'
        self.lifetime_s = float(v('scene_lifetime_s'))
        self.max_width = int(v('image_max_width'))
        self.frustum_depth_m = float(v('frustum_depth_m'))
        self.cameras: Dict[str, Any] = {}
        if v('rig_config'):
            try:
                rig = load_calibration(v('rig_config'))
            except (OSError, ValueError) as exc:
                raise ValueError(f'rig_config {v("rig_config")!r}: {exc}') from exc
            ids = [c for c in (v('camera_ids') or []) if c] or list(rig)
            unknown = [c for c in ids if c not in rig]
            if unknown:
                raise ValueError(f'camera_ids {unknown} are not in {v("rig_config")}')
            self.cameras = {c: rig[c] for c in ids}
            self.world_frame = v('world_frame') or rig_metadata(v('rig_config'))[0] or 'map'

        # Every channel exists before the server accepts a client: a client already waiting
        # (Foxglove reconnecting after a restart) gets them all in its first advertisement,
        # never a channel it may subscribe to before the server has registered it.
        self.fg_context = foxglove.Context()
        self.scene = SceneUpdateChannel(SCENE_TOPIC, context=self.fg_context)
        self.camera_scene = SceneUpdateChannel(CAMERAS_TOPIC, context=self.fg_context)
        tracks_topic = self.resolve_topic_name(v('tracks_topic'))
        self.tracks_channel = foxglove.Channel(tracks_topic, schema=ros2_schema(TRACKS_TYPE),
                                               message_encoding='cdr', context=self.fg_context)
        self._subs = [self.create_subscription(TrackedSkeletonArray, tracks_topic,
                                               self._on_tracks, reliable_qos(10), raw=True)]
        self.det_channels: Dict[str, foxglove.Channel] = {}
        self.image_channels: Dict[str, CompressedImageChannel] = {}
        self._images: Dict[str, Deque[Tuple[int, bytes]]] = {}
        self._image_topics: Dict[str, str] = {}
        self._image_subs: Dict[str, Any] = {}
        det_pattern, image_pattern = v('detections_topic'), v('image_topic')
        persons_schema = ros2_schema(PERSONS_TYPE) if det_pattern else None
        for cam in self.cameras:
            if det_pattern:
                topic = self.resolve_topic_name(camera_topic(det_pattern, cam))
                self.det_channels[cam] = foxglove.Channel(
                    topic, schema=persons_schema, message_encoding='cdr', context=self.fg_context)
                self._subs.append(self.create_subscription(
                    Person2DArray, topic, lambda data, c=cam: self._on_persons(c, data),
                    reliable_qos(20), raw=True))
            if image_pattern:
                topic = self.resolve_topic_name(camera_topic(image_pattern, cam))
                out = topic.rsplit('/', 1)[0] + '/image_skeletons'
                self.image_channels[cam] = CompressedImageChannel(out, context=self.fg_context)
                self._images[cam] = deque(maxlen=IMAGES_KEPT)
                self._image_topics[cam] = topic
        self.server = foxglove.start_server(name='mv3dpose', host=v('host'), port=v('port'),
                                            context=self.fg_context)
        self.port = self.server.port
        self._send_cameras()
        self._timer = self.create_timer(float(v('cameras_period_s')), self._send_cameras)
        if self.image_channels:
            self._watch_timer = self.create_timer(IMAGE_WATCH_S, self._watch_images)
        self._url = f'ws://{v("host")}:{self.port}'
        self.diagnostics = Diagnostics(self, 1.0)
        self.diagnostics.add_task(self._diag)
        self._dropped_reported = 0
        self.get_logger().info(
            f'Foxglove WebSocket on ws://{v("host")}:{self.port} (Foxglove: Open connection -> '
            f'Foxglove WebSocket); channels {SCENE_TOPIC}, {CAMERAS_TOPIC}, {tracks_topic}'
            + ''.join(f', {c.topic()}' for c in self.det_channels.values())
            + ''.join(f', {c.topic()}' for c in self.image_channels.values()))

    # ------------------------------------------------------------------ callbacks
    def _drop(self, key: str, text: str) -> None:
        self.counts[f'dropped {key}'] += 1
        self._rlog(key, text, time.monotonic_ns())

    def _send_cameras(self) -> None:
        if self.cameras:
            self.camera_scene.log(camera_update(self.cameras, self.world_frame,
                                                time.time_ns(), self.frustum_depth_m))

    def _on_tracks(self, data: bytes) -> None:
        self.counts['tracks'] += 1
        try:
            msg = deserialize_message(bytes(data), TrackedSkeletonArray)
            layout = get_layout(msg.layout)
            tracks = msg_to_tracks(msg)
        except Exception as exc:  # noqa: B902 - rclpy and the converters raise several types
            self._drop('tracks', f'{self.tracks_channel.topic()}: unreadable '
                       f'TrackedSkeletonArray dropped ({exc})')
            return
        stamp_ns = stamp_to_ns(msg.header.stamp)
        self.tracks_channel.log(bytes(data), log_time=stamp_ns)
        self.scene.log(skeleton_update(tracks, layout.bones, msg.header.frame_id, stamp_ns,
                                       self.lifetime_s), log_time=stamp_ns)

    def _on_persons(self, cam: str, data: bytes) -> None:
        self.counts[f'{cam} detections'] += 1
        try:
            msg = decode_person2d_array(data)
        except InvalidMessage as exc:
            self._drop(f'{cam} detections', f'{self.det_channels[cam].topic()}: '
                       f'Person2DArray dropped ({exc})')
            return
        self.det_channels[cam].log(bytes(data), log_time=msg.stamp_ns)
        if cam in self.image_channels:
            self._draw(cam, msg)

    def _watch_images(self) -> None:
        """Subscribe to a camera's images while a client watches its channel, else not."""
        for cam, channel in self.image_channels.items():
            watched, sub = channel.has_sinks(), self._image_subs.get(cam)
            if watched and sub is None:
                self._image_subs[cam] = self.create_subscription(
                    Image, self._image_topics[cam], lambda data, c=cam: self._on_image(c, data),
                    sensor_qos('best_effort', 5), raw=True)
                self.get_logger().info(f'{channel.topic()} watched: taking '
                                       f'{self._image_topics[cam]}')
            elif sub is not None and not watched:
                self.destroy_subscription(self._image_subs.pop(cam))
                self._images[cam].clear()
                self.get_logger().info(f'{channel.topic()} no longer watched: '
                                       f'{self._image_topics[cam]} released')

    def _on_image(self, cam: str, data: bytes) -> None:
        try:
            header, _ = decode_image_bytes(data)
        except ImageError as exc:
            self._drop(f'{cam} image', f'camera {cam}: image dropped ({exc})')
            return
        self._images[cam].append((stamp_to_ns(header.header.stamp), bytes(data)))

    def _draw(self, cam: str, persons: Any) -> None:
        """Publish the image with the stamp of ``persons`` with their skeletons drawn."""
        match = next((raw for ns, raw in self._images[cam] if ns == persons.stamp_ns), None)
        if match is None:
            return
        try:
            layout = get_layout(persons.layout)
            poses = person2d_array_to_numpy(persons, layout.num_joints)
            msg, pixels = decode_image_bytes(match)
            image, order = message_to_numpy(msg, pixels)
        except (ImageError, InvalidMessage, ValueError) as exc:
            self._drop(f'{cam} image', f'camera {cam}: cannot draw the detections ({exc})')
            return
        if order == 'rgb':
            image = cv2.cvtColor(image, cv2.COLOR_RGB2BGR)
        rois = np.asarray(persons.rois, dtype=np.float64).reshape(-1, 5)
        boxes = np.stack([rois[:, 0], rois[:, 1], rois[:, 0] + rois[:, 3],
                          rois[:, 1] + rois[:, 2]], axis=1)
        drawn = draw_people(image, poses, boxes, np.asarray(persons.scores), layout.bones)
        if drawn.shape[1] > self.max_width:
            scale = self.max_width / drawn.shape[1]
            drawn = cv2.resize(drawn, (self.max_width, int(round(drawn.shape[0] * scale))),
                               interpolation=cv2.INTER_AREA)
        ok, jpeg = cv2.imencode('.jpg', drawn, [cv2.IMWRITE_JPEG_QUALITY, 80])
        if not ok:
            self._drop(f'{cam} image', f'camera {cam}: JPEG encoding failed')
            return
        stamp = msg.header.stamp
        self.image_channels[cam].log(
            FoxgloveCompressedImage(timestamp=foxglove.messages.Timestamp(
                sec=stamp.sec, nsec=stamp.nanosec), frame_id=msg.header.frame_id,
                data=jpeg.tobytes(), format='jpeg'), log_time=persons.stamp_ns)
        self.counts[f'{cam} images drawn'] += 1

    def _diag(self) -> List[Any]:
        """Report what arrived and what was dropped (WARN while new drops appear)."""
        dropped = sum(n for k, n in self.counts.items() if k.startswith('dropped '))
        level, message = OK, f'serving {self._url}'
        if dropped > self._dropped_reported:
            level = WARN
            message = f'dropped {dropped - self._dropped_reported} unreadable messages'
        self._dropped_reported = dropped
        values = {'url': self._url, 'image topics taken': len(self._image_subs),
                  **dict(sorted(self.counts.items()))}
        return [make_status(self.diagnostics.name('web view'), level, message, values=values)]

    def destroy_node(self) -> None:
        """Stop the WebSocket server, then destroy the node."""
        self.server.stop()
        super().destroy_node()


def _parse_cli(argv: List[str]) -> List[Parameter]:
    parser = argparse.ArgumentParser(prog='mv3dpose_foxglove_view', description=__doc__
                                     .strip().splitlines()[0])
    parser.add_argument('--rig', dest='rig_config', help='rig calibration (camera frustums)')
    parser.add_argument('--port', type=int, help='WebSocket port (default 8765)')
    parser.add_argument('--host', help='bind address (default 127.0.0.1)')
    parser.add_argument('--tracks-topic', dest='tracks_topic')
    parser.add_argument('--image-topic', dest='image_topic',
                        help="e.g. '/{camera}/image_raw': draw the 2D skeletons on the images")
    args = parser.parse_args(argv)
    return [Parameter(k, value=v) for k, v in vars(args).items() if v is not None]


def main(args: Optional[List[str]] = None) -> int:
    """Entry point of the ``mv3dpose_foxglove_view`` console script."""
    return run_node('mv3dpose_foxglove_view',
                    lambda overrides: FoxgloveView(parameter_overrides=overrides), args,
                    parse_cli=_parse_cli, usage_errors=(ValueError, RuntimeError))


if __name__ == '__main__':
    sys.exit(main())
