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
image_publisher: replay a folder of images or a video file as ``sensor_msgs/Image``.

For users without a camera driver. Frame ``k`` is stamped ``start_stamp + k / rate_hz``
(integer nanoseconds), so several publishers started with the same ``--start-stamp`` and
``--rate`` produce identical stamps frame for frame and the fusion node's synchroniser pairs
them exactly, whenever each process started. With ``--calibration`` (any format
``core.calibration.load_calibration`` reads) a matching ``CameraInfo`` is published on
``camera_info`` with the same header as each image.

    image_publisher ../shared/data/panoptic_demo/00_03 --rate 2 --start-stamp 1000 \
        --calibration ../shared/data/panoptic_demo/camera_parameters.json --camera 00_03 \
        --ros-args -r __ns:=/cam0

Every option is also a ROS parameter (``source``, ``rate_hz``, ``loop``, ``start_stamp``,
``frame_id``, ``encoding``, ``calibration``, ``camera_name``, ``reliability``, ``max_frames``,
``wait_for_subscribers``, ``preload``), so ``--params-file`` works too.
"""

import argparse
import os
import sys
import threading
from typing import Any, List, Optional

import cv2
from mv3dpose_ros.ros.images import camera_info_from_camera, numpy_to_image
from mv3dpose_ros.ros.messages import ns_to_stamp
from mv3dpose_ros.ros.qos import describe, sensor_qos
import numpy as np
from rcl_interfaces.msg import ParameterDescriptor
import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import Header

IMAGE_EXTENSIONS = ('.jpg', '.jpeg', '.png', '.bmp', '.tif', '.tiff', '.webp', '.ppm', '.pgm')

PARAMETERS = {
    'source': ('', 'folder of images (sorted by name) or a video file'),
    'rate_hz': (10.0, 'publish rate; also the stamp spacing (1 / rate_hz)'),
    'loop': (False, 'start again after the last frame (stamps keep increasing)'),
    'start_stamp': (0.0, 'stamp of frame 0 [s]; 0 = the node clock at the first frame'),
    'frame_id': ('', 'header.frame_id; empty = <camera_name>_optical_frame'),
    'encoding': ('bgr8', 'bgr8 | rgb8 | mono8'),
    'calibration': ('', 'calibration file for CameraInfo (rig YAML, camera_info YAML, '
                        'Panoptic / VoxelPose JSON, Pose2Sim TOML); empty = none'),
    'camera_name': ('', 'camera in the calibration file; empty = the only one, else the '
                        'last namespace component'),
    'reliability': ('best_effort', 'best_effort (sensor data QoS) | reliable'),
    'max_frames': (0, 'stop after this many frames (0 = all)'),
    'wait_for_subscribers': (0, 'hold the first frame until this many subscribers match'),
    'preload': (False, 'decode every frame before starting (steady timing)'),
}


class FrameSource:
    """Frames of a folder or a video, in order, as BGR uint8 arrays."""

    def __init__(self, path: str, preload: bool = False) -> None:
        self.path = path
        self._cap = None
        if os.path.isdir(path):
            self.files = sorted(os.path.join(path, f) for f in os.listdir(path)
                                if f.lower().endswith(IMAGE_EXTENSIONS))
            if not self.files:
                raise ValueError(f'no images ({", ".join(IMAGE_EXTENSIONS)}) in folder {path}')
        elif os.path.isfile(path):
            self.files = None
            self._cap = cv2.VideoCapture(path)
            if not self._cap.isOpened():
                raise ValueError(f'cannot open video {path} (not a video OpenCV can read?)')
        else:
            raise ValueError(f'source not found: {path!r} (give an image folder or a video)')
        self._index = 0
        self._cache: Optional[List[np.ndarray]] = None
        if preload:
            self._cache = []
            frame = self._read()
            while frame is not None:
                self._cache.append(frame)
                frame = self._read()
            self._index = 0

    def _read(self) -> Optional[np.ndarray]:
        if self.files is not None:
            if self._index >= len(self.files):
                return None
            name = self.files[self._index]
            self._index += 1
            image = cv2.imread(name, cv2.IMREAD_COLOR)
            if image is None:
                raise ValueError(f'cannot decode image {name}')
            return image
        ok, frame = self._cap.read()
        return frame if ok else None

    def read_next(self) -> Optional[np.ndarray]:
        """Return the next frame, or None at the end."""
        if self._cache is not None:
            if self._index >= len(self._cache):
                return None
            self._index += 1
            return self._cache[self._index - 1]
        return self._read()

    def rewind(self) -> None:
        """Go back to the first frame."""
        self._index = 0
        if self._cap is not None and self._cache is None:
            self._cap.set(cv2.CAP_PROP_POS_FRAMES, 0)


class ImagePublisher(Node):
    """Publish a folder or a video at a fixed rate with stamps ``start + k / rate``."""

    def __init__(self, node_name: str = 'image_publisher', **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        for name, (default, text) in PARAMETERS.items():
            self.declare_parameter(name, default, ParameterDescriptor(description=text,
                                                                      read_only=True))
        p = {name: self.get_parameter(name).value for name in PARAMETERS}
        if float(p['rate_hz']) <= 0:
            raise ValueError(f'rate_hz must be > 0, got {p["rate_hz"]}')
        if p['encoding'] not in ('bgr8', 'rgb8', 'mono8'):
            raise ValueError(f'encoding must be bgr8, rgb8 or mono8, got {p["encoding"]!r}')
        self.params = p
        self.source = FrameSource(p['source'], bool(p['preload']))
        ns_last = self.get_namespace().strip('/').split('/')[-1]
        self.camera_info = None
        name = p['camera_name']
        if p['calibration']:
            from mv3dpose_ros.core.calibration import load_calibration
            cameras = load_calibration(p['calibration'])
            if not name:
                name = next(iter(cameras)) if len(cameras) == 1 else ns_last
            if name not in cameras:
                raise ValueError(f'camera {name!r} not in {p["calibration"]}; it has: '
                                 f'{", ".join(cameras)} (set camera_name)')
            self.camera = cameras[name]
            self.camera_info = camera_info_from_camera(self.camera)
        self.camera_name = name or ns_last or 'camera'
        self.frame_id = p['frame_id'] or f'{self.camera_name}_optical_frame'
        qos = sensor_qos(p['reliability'], 5)
        self.image_pub = self.create_publisher(Image, 'image', qos)
        self.info_pub = (self.create_publisher(CameraInfo, 'camera_info', qos)
                         if self.camera_info is not None else None)
        self.period_ns = int(round(1e9 / float(p['rate_hz'])))
        self.start_ns = int(round(float(p['start_stamp']) * 1e9)) or None
        self.count = 0
        self.done = threading.Event()
        self.timer = self.create_timer(1.0 / float(p['rate_hz']), self._tick)
        self.get_logger().info(
            f'{p["source"]} -> {self.resolve_topic_name("image")} [{describe(qos)}] at '
            f'{p["rate_hz"]:g} Hz, frame_id {self.frame_id}'
            + (f', CameraInfo of {self.camera_name}' if self.camera_info else ''))

    def stamp_ns(self, k: int) -> int:
        """Return the stamp of frame ``k`` in nanoseconds."""
        return self.start_ns + k * self.period_ns

    def _tick(self) -> None:
        if self.done.is_set():
            return
        need = int(self.params['wait_for_subscribers'])
        if self.count == 0 and self.image_pub.get_subscription_count() < need:
            return
        limit = int(self.params['max_frames'])
        frame = self.source.read_next() if not (limit and self.count >= limit) else None
        if frame is None and self.params['loop'] and not (limit and self.count >= limit):
            self.source.rewind()
            frame = self.source.read_next()
        if frame is None:
            self.get_logger().info(f'published {self.count} frames; end of {self.source.path}')
            self.done.set()
            return
        if self.start_ns is None:
            self.start_ns = self.get_clock().now().nanoseconds
        if self.camera_info is not None and (frame.shape[1], frame.shape[0]) != (
                self.camera_info.width, self.camera_info.height):
            self.get_logger().warn(
                f'frame {self.count} is {frame.shape[1]}x{frame.shape[0]} but the calibration '
                f'of {self.camera_name} is {self.camera_info.width}x{self.camera_info.height}',
                throttle_duration_sec=10.0)
        header = Header(stamp=ns_to_stamp(self.stamp_ns(self.count)), frame_id=self.frame_id)
        encoding = self.params['encoding']
        if encoding == 'rgb8':
            frame = cv2.cvtColor(frame, cv2.COLOR_BGR2RGB)
        elif encoding == 'mono8':
            frame = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
        self.image_pub.publish(numpy_to_image(frame, header, encoding))
        if self.info_pub is not None:
            self.camera_info.header = header
            self.info_pub.publish(self.camera_info)
        self.count += 1


def _parse_cli(argv: List[str]) -> List[Parameter]:
    """Turn the convenience options into parameter overrides (--ros-args still work)."""
    parser = argparse.ArgumentParser(prog='image_publisher', description=__doc__.splitlines()[1])
    parser.add_argument('source', nargs='?', help='image folder or video file')
    parser.add_argument('--rate', type=float, dest='rate_hz')
    parser.add_argument('--loop', action='store_true', default=None)
    parser.add_argument('--start-stamp', type=float, dest='start_stamp',
                        help='stamp of the first frame [s]; give the same to every camera')
    parser.add_argument('--frame-id', dest='frame_id')
    parser.add_argument('--encoding', choices=('bgr8', 'rgb8', 'mono8'))
    parser.add_argument('--calibration', help='calibration file for CameraInfo')
    parser.add_argument('--camera', dest='camera_name', help='camera name in the calibration')
    parser.add_argument('--reliable', action='store_const', const='reliable',
                        dest='reliability')
    parser.add_argument('--count', type=int, dest='max_frames', help='stop after N frames')
    parser.add_argument('--wait-for-subscribers', type=int, dest='wait_for_subscribers')
    parser.add_argument('--preload', action='store_true', default=None)
    args = parser.parse_args(argv)
    return [Parameter(k, value=v) for k, v in vars(args).items() if v is not None]


def main(args: Optional[List[str]] = None) -> int:
    """Publish until the source ends (or forever with ``--loop``)."""
    argv = sys.argv if args is None else args
    rclpy.init(args=argv)
    node = None
    try:
        overrides = _parse_cli(rclpy.utilities.remove_ros_args(argv)[1:])
        node = ImagePublisher(parameter_overrides=overrides)
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        while rclpy.ok() and not node.done.is_set():
            executor.spin_once(timeout_sec=0.1)
        for _ in range(5):             # let the last messages go out
            executor.spin_once(timeout_sec=0.1)
    except ValueError as exc:
        print(f'image_publisher: error: {exc}', file=sys.stderr)
        return 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
