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
mv3dpose_image_publisher: a folder of images or a video file as a free-running camera.

For users without a camera driver. It publishes what a driver does: ``image_raw`` (and
``camera_info`` with ``--calibration``, same header) under the camera's namespace, so
``mv3dpose_image_publisher DIR --camera 00_03`` publishes ``/cam00_03/image_raw``, the default
image topic of mv3dpose_bringup (camera names map to ROS names as in ``ros/names.py``; a
``-r __ns:=/x`` remap wins). It runs free at ``--rate`` on the system clock and stamps each
frame with its capture instant, like a driver: with ``--trigger grid`` (default) the instants
are the multiples of the period, as for cameras triggered from one synchronised clock, so
publishers of the same rate stamp the same instants whenever each process started, and with
``--loop`` an image folder or a video shows frame ``(instant / period) mod N`` at each
instant, so all cameras of a recorded rig show the same moment together (a video is stepped
or seeked to it; one whose container gives no frame count plays in order); with
``--trigger free`` each publisher has its own phase and plays from the first frame. With
``--start-stamp S`` frame ``k`` is stamped ``S + k / rate`` instead (reproducible stamps).

``--bounce`` (implies ``--loop``) plays the source forward then backward, frames ``0 .. N-1,
N-2 .. 1, 0, 1 ..``: instant ``i`` shows frame ``i mod (2N - 2)`` reflected at ``N - 1``, still
the same frame in every publisher of a rig at the same instant (with ``--trigger free`` or
``--start-stamp``, from frame 0). A short clip of a walking person then has no jump at the
wrap, where plain ``--loop`` puts him back where he started in one frame (a tracker sees a
teleport and gives a new id); he walks backward on the way back. Looping, each frame is
decoded, converted and serialised once, and the serialised messages are kept up to
``WIRE_CACHE_BYTES`` (512 MiB: 86 frames of 1080x1920 bgr8); a video's frames beyond that are
decoded again each time. A decoder only seeks to keyframes (often one per clip), so going
backward frame by frame would decode again from the keyframe before each frame (0.3-0.5 s for
a 1080p frame near the end of a 100-frame clip); bouncing, the decoded frames that are not
cached are kept up to ``BACK_BUFFER_BYTES`` (128 MiB, 21 such frames) and a frame before them
is read with the ones before it in one seek. A 100-frame 1080x1920 clip then bounces from
memory after its first cycle, nothing decoded (Pose2Sim cam01.mp4 at 10 Hz: 865 MB resident
against 757 MB with ``--loop``, the same CPU; the first cycle's reads back can skip a few
instants); a longer video seeks once per buffer on its way back, which can make publishing
fall behind (skipped instants, warned): extract its frames to a folder, or ``--preload`` it
if memory allows. A video whose container gives no frame count needs ``--preload`` to bounce.

``--encoding`` publishes any encoding camera drivers use (bgr8, rgb8, mono8, bgra8, rgba8,
mono16, yuv422, yuv422_yuy2); ``--compressed jpeg|png`` publishes ``sensor_msgs/CompressedImage``
on ``image_raw/compressed`` instead, as image_transport's compressed plugin does.

    mv3dpose_image_publisher ../shared/data/panoptic_demo/00_03 --rate 5 --loop \
        --calibration ../shared/data/panoptic_demo/camera_parameters.json --camera 00_03

    mv3dpose_image_publisher ../shared/data/pose2sim_singleperson/videos/cam01.mp4 \
        --camera cam_01 --rate 10 --bounce \
        --calibration ../shared/data/pose2sim_multiperson/Calib_qualisys.toml

Every option is also a ROS parameter (``source``, ``rate_hz``, ``loop``, ``bounce``,
``start_stamp``, ``trigger``, ``frame_id``, ``encoding``, ``compressed``, ``calibration``,
``camera_name``, ``reliability``, ``max_frames``, ``wait_for_subscribers``, ``preload``,
``hold_s``), so ``--params-file`` works too.
"""

import argparse
import math
import struct
import sys
import threading
from typing import Any, Dict, List, Optional, Tuple

import cv2
from mv3dpose_ros.io.media import FrameSource
from mv3dpose_ros.ros.images import bgr_to_image, camera_info_from_camera, numpy_to_compressed
from mv3dpose_ros.ros.messages import ns_to_stamp
from mv3dpose_ros.ros.names import camera_namespace
from mv3dpose_ros.ros.qos import describe, sensor_qos
from mv3dpose_ros.ros.spin import run_node, spin_until_shutdown
import numpy as np
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.serialization import serialize_message
from sensor_msgs.msg import CameraInfo, CompressedImage, Image
from std_msgs.msg import Header

PUBLISH_ENCODINGS = ('bgr8', 'rgb8', 'mono8', 'bgra8', 'rgba8', 'mono16', 'yuv422',
                     'yuv422_yuy2')
#: most bytes of serialised messages kept for looping (beyond it frames are re-encoded)
WIRE_CACHE_BYTES = 512 * 1024 * 1024
#: most bytes of decoded video frames kept for playing backward (--bounce; frames not cached
#: as serialised messages): a decoder only seeks to keyframes, so reading a video backward
#: frame by frame decodes again from the keyframe before each one (0.3-0.5 s for a 1080p frame
#: near the end of a 100-frame clip with one keyframe)
BACK_BUFFER_BYTES = 128 * 1024 * 1024

PARAMETERS = {
    'source': ('', 'folder of images (sorted by name) or a video file'),
    'rate_hz': (10.0, 'publish rate; also the stamp spacing (1 / rate_hz)'),
    'loop': (False, 'start again after the last frame (stamps keep increasing)'),
    'bounce': (False, 'loop forward then backward (frames 0 .. N-1, N-2 .. 1, 0 ..: no jump at '
                      'the wrap, a moving person turns back); implies loop'),
    'start_stamp': (0.0, 'stamp of frame 0 [s], frame k at start + k / rate_hz; 0 = each frame '
                         'stamped with its capture instant on the node clock (like a driver)'),
    'trigger': ('grid', 'grid: capture instants on the multiples of 1 / rate_hz of the clock '
                        '(cameras triggered from one synchronised clock: all publishers of a '
                        'rate stamp the same instants) | free: every 1 / rate_hz from the '
                        'start (unsynchronised cameras)'),
    'frame_id': ('', 'header.frame_id; empty = <camera ROS name>_optical_frame'),
    'encoding': ('bgr8', 'bgr8 | rgb8 | mono8 | bgra8 | rgba8 | mono16 | yuv422 | yuv422_yuy2'),
    'compressed': ('', "'' = raw Image on image_raw; jpeg | png = CompressedImage on "
                       'image_raw/compressed'),
    'calibration': ('', 'calibration file for CameraInfo (rig YAML, camera_info YAML, '
                        'Panoptic / VoxelPose JSON, Pose2Sim TOML); empty = none'),
    'camera_name': ('', 'camera in the calibration file; empty = the only one, else the '
                        'last namespace component'),
    'reliability': ('best_effort', 'best_effort (sensor data QoS) | reliable'),
    'max_frames': (0, 'stop after this many frames (0 = all)'),
    'wait_for_subscribers': (0, 'hold the first frame until this many subscribers match'),
    'preload': (False, 'decode every frame before starting (steady timing)'),
    'hold_s': (0.0, 'looping grid mode: show each image of the source this long [s] (a still '
                    'scene per image, e.g. for tracking on a few photos); 0 = one per instant'),
    'stamp_offset_s': (0.0, 'added to every stamp [s]: a camera host whose clock is off, for '
                            'testing what fusion_node reports'),
}


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
        if p['encoding'] not in PUBLISH_ENCODINGS:
            raise ValueError(f'encoding must be one of {", ".join(PUBLISH_ENCODINGS)}, got '
                             f'{p["encoding"]!r}')
        if p['trigger'] not in ('grid', 'free'):
            raise ValueError(f"trigger must be 'grid' or 'free', got {p['trigger']!r}")
        if p['compressed'] not in ('', 'jpeg', 'png'):
            raise ValueError(f"compressed must be '', 'jpeg' or 'png', got {p['compressed']!r}")
        p['loop'] = bool(p['loop'] or p['bounce'])
        self.params = p
        self.bounce = bool(p['bounce'])
        self.source = FrameSource(p['source'], bool(p['preload']),
                                  BACK_BUFFER_BYTES if self.bounce else 0)
        if self.bounce and not self.source.seekable:
            raise ValueError(f'bounce plays frames by index, and the container of {p["source"]} '
                             'gives no frame count: add --preload (decodes every frame first)')
        ns_last = self.get_namespace().strip('/').split('/')[-1]
        self.camera_info = None
        name = p['camera_name']
        if p['calibration']:
            from mv3dpose_ros.core.geometry.calibration import load_calibration
            cameras = load_calibration(p['calibration'])
            if not name:
                name = next(iter(cameras)) if len(cameras) == 1 else ns_last
            if name not in cameras:
                raise ValueError(f'camera {name!r} not in {p["calibration"]}; it has: '
                                 f'{", ".join(cameras)} (set camera_name)')
            self.camera = cameras[name]
            self.camera_info = camera_info_from_camera(self.camera)
        self.camera_name = name or ns_last or 'camera'
        self.frame_id = p['frame_id'] or f'{camera_namespace(self.camera_name)}_optical_frame'
        # Under the camera's namespace unless the node was put in one (-r __ns:=...).
        prefix = (f'/{camera_namespace(self.camera_name)}/'
                  if self.get_namespace() == '/' and (name or p['camera_name']) else '')
        qos = sensor_qos(p['reliability'], 5)
        image_topic = prefix + ('image_raw/compressed' if p['compressed'] else 'image_raw')
        self.image_pub = self.create_publisher(
            CompressedImage if p['compressed'] else Image, image_topic, qos)
        self.info_pub = (self.create_publisher(CameraInfo, prefix + 'camera_info', qos)
                         if self.camera_info is not None else None)
        self.period_ns = int(round(1e9 / float(p['rate_hz'])))
        if not (math.isfinite(float(p['hold_s'])) and float(p['hold_s']) >= 0.0):
            raise ValueError(f"hold_s must be >= 0, got {p['hold_s']}")
        # Looping on the grid, the image shown changes every slot (a period, or hold_s).
        self.slot_ns = max(self.period_ns, int(round(float(p['hold_s']) * 1e9)))
        self.start_ns = int(round(float(p['start_stamp']) * 1e9)) or None
        self.stamp_now = self.start_ns is None
        self.stamp_offset_ns = int(round(float(p['stamp_offset_s']) * 1e9))
        self.count = self.skipped = 0
        self.done = threading.Event()
        self._wire: Dict[int, bytes] = {}      # frame index -> serialised message (loop)
        self._wire_bytes = 0
        self.get_logger().info(
            f'{p["source"]} -> {self.image_pub.topic_name} [{describe(qos)}] '
            f'{p["compressed"] or p["encoding"]} at {p["rate_hz"]:g} Hz, stamps '
            f'{p["trigger"] + " capture instants" if self.stamp_now else "start + k / rate"}, '
            f'frame_id {self.frame_id}'
            + (f', bouncing over {self.source.length} frames' if self.bounce else '')
            + (f', CameraInfo of {self.camera_name}' if self.camera_info else ''))

    def stamp_ns(self, k: int) -> int:
        """Return the stamp of frame ``k`` in nanoseconds."""
        return self.start_ns + k * self.period_ns

    def frame_of(self, slot: int) -> int:
        """
        Return the index of the frame shown in ``slot`` (looping a seekable source).

        ``slot % length``; bouncing, ``slot % (2 length - 2)`` reflected at the last frame:
        0, 1, .., N-1, N-2, .., 1, 0, 1, ..
        """
        n = self.source.length
        if not self.bounce:
            return slot % n
        if n < 2:
            return 0
        k = slot % (2 * n - 2)
        return k if k < n else 2 * n - 2 - k

    def _next_frame(self, slot: Optional[int] = None
                    ) -> Optional[Tuple[int, Optional[np.ndarray]]]:
        """
        Return ``(key, frame)`` of the next frame, or None at the end.

        ``key`` is the frame's index in a seekable source (-1 otherwise); ``frame`` is None
        when its serialised message is cached (nothing to decode). ``slot`` (the capture
        instant in periods of the clock, looping grid mode; the frame count, bouncing
        otherwise) picks frame ``frame_of(slot)``, so every publisher of a rig shows the same
        moment at the same instant, whenever it started.
        """
        limit = int(self.params['max_frames'])
        if limit and self.count >= limit:
            return None
        if slot is not None:
            key = self.frame_of(slot)
            return key, (None if key in self._wire else self.source.frame_at(key))
        for attempt in range(2):
            key = self.source.position if self.source.seekable else -1
            if key in self._wire:
                if self.source.skip():
                    return key, None
            else:
                frame = self.source.read_next()
                if frame is not None:
                    return key, frame
            if attempt or not self.params['loop']:
                return None
            self.source.rewind()
        return None

    def run(self) -> None:
        """
        Publish each frame at its capture instant until the source ends or ``done`` is set.

        ``trigger`` grid: instants are the multiples of the period on the node clock (the
        system clock), as for cameras triggered from one synchronised clock, so publishers with
        the same rate in any number of processes or hosts (chrony / PTP) stamp the same
        instants; free: one period after the previous frame, from the first one. When
        publishing falls behind, grid instants that have passed are skipped (counted) rather
        than published late, with their frames: looping on the grid, a seekable source (a
        folder, a video with a frame count) shows frame ``instant % length`` at each instant,
        the same in every publisher of a rig; read in order, their frames are stepped over.
        """
        clock = self.get_clock()
        need = int(self.params['wait_for_subscribers'])
        while need and self.image_pub.get_subscription_count() < need:
            if self.done.wait(0.05):
                return
        grid = self.params['trigger'] == 'grid' and self.stamp_now
        now = clock.now().nanoseconds
        due = (now // self.period_ns + 1) * self.period_ns if grid else now
        while not self.done.is_set():
            now = clock.now().nanoseconds
            if now < due:
                self.done.wait(min(due - now, 100_000_000) / 1e9)
                continue
            synced = grid and self.params['loop'] and self.source.seekable
            if grid and now - due >= self.period_ns:
                late = (now - due) // self.period_ns
                self.skipped += late
                due += late * self.period_ns
                if not synced:                   # the frames of those instants go by too
                    self._step_over(late)
                self.get_logger().warn(
                    f'publishing fell behind {self.params["rate_hz"]:g} Hz: {self.skipped} '
                    'frame instants skipped so far (CPU overloaded?)', throttle_duration_sec=10.0)
            nxt = self._next_frame(due // self.slot_ns if synced else
                                   self.count if self.bounce else None)
            if nxt is None:
                break
            try:
                self._publish(*nxt, self.stamp_offset_ns + (
                    due if grid else (now if self.stamp_now else self.stamp_ns(self.count))))
            except Exception:  # noqa: B902 - rclpy raises RCLError, a pybind11 type
                if self.context.ok():
                    raise
                break                # Ctrl-C shut the context down during this publish
            due += self.period_ns
        text = (f'published {self.count} frames'
                + (f', skipped {self.skipped} instants' if self.skipped else '')
                + (f'; end of {self.source.path}' if not self.done.is_set() else ''))
        if self.context.ok():
            self.get_logger().info(text)
        else:                           # stopped by a signal: rosout is gone
            print(f'[image_publisher] {text}', file=sys.stderr, flush=True)
        self.done.set()

    def _step_over(self, frames: int) -> None:
        """Step over ``frames`` frames of a source read in order (a camera drops them too)."""
        for _ in range(frames):
            if not self.source.skip():
                if not self.params['loop']:
                    return
                self.source.rewind()

    def _publish(self, key: int, frame: Optional[np.ndarray], stamp_ns: int) -> None:
        header = Header(stamp=ns_to_stamp(stamp_ns), frame_id=self.frame_id)
        if frame is None:               # cached: the same bytes with this frame's stamp
            wire = memoryview(self._wire[key])
            stamp = struct.pack('<iI' if wire[1] == 1 else '>iI', header.stamp.sec,
                                header.stamp.nanosec)
            self.image_pub.publish(b''.join((wire[:4], stamp, wire[12:])))
        else:
            self._publish_frame(key, frame, header)
        if self.info_pub is not None:
            self.camera_info.header = header
            self.info_pub.publish(self.camera_info)
        self.count += 1

    def _publish_frame(self, key: int, frame: np.ndarray, header: Header) -> None:
        if self.camera_info is not None and (frame.shape[1], frame.shape[0]) != (
                self.camera_info.width, self.camera_info.height):
            self.get_logger().warn(
                f'frame {self.count} is {frame.shape[1]}x{frame.shape[0]} but the calibration '
                f'of {self.camera_name} is {self.camera_info.width}x{self.camera_info.height}',
                throttle_duration_sec=10.0)
        if self.params['compressed']:
            gray = self.params['encoding'] in ('mono8', 'mono16')
            msg = numpy_to_compressed(cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY) if gray else frame,
                                      header, self.params['compressed'])
        else:
            msg = bgr_to_image(frame, self.params['encoding'], header)
        if key < 0 or not self.params['loop'] or self._wire_bytes >= WIRE_CACHE_BYTES:
            self.image_pub.publish(msg)
            return
        # A looped frame is decoded, converted and serialised once; later rounds publish the
        # bytes with a new stamp (a 1080p frame: ~2 ms instead of ~25 ms here).
        wire = serialize_message(msg)
        self._wire[key] = wire
        self._wire_bytes += len(wire)
        self.source.forget(key)         # bouncing: no second copy in the backward buffer
        self.image_pub.publish(wire)


def parse_cli(argv: List[str]) -> List[Parameter]:
    """Turn the convenience options into parameter overrides (--ros-args still work)."""
    parser = argparse.ArgumentParser(prog='mv3dpose_image_publisher',
                                     description=__doc__.splitlines()[1])
    parser.add_argument('source', nargs='?', help='image folder or video file')
    parser.add_argument('--rate', type=float, dest='rate_hz')
    parser.add_argument('--loop', action='store_true', default=None,
                        help='start again after the last frame (stamps keep increasing)')
    parser.add_argument('--bounce', action='store_true', default=None,
                        help='loop forward then backward: frames 0..N-1, N-2..1, 0, 1.. (no '
                        'jump at the wrap: a walking person walks back); implies --loop; on '
                        'the grid every publisher of a rig shows the same frame at an instant')
    parser.add_argument('--start-stamp', type=float, dest='start_stamp',
                        help='stamp frame k start + k / rate [s] (default: the node clock at '
                        'publication); give the same to every camera for identical stamps')
    parser.add_argument('--trigger', choices=('grid', 'free'),
                        help='grid (default): capture instants on the multiples of 1 / rate of '
                        'the clock, the same for every publisher (a synchronised rig); free: '
                        'from the start, own phase')
    parser.add_argument('--frame-id', dest='frame_id')
    parser.add_argument('--encoding', choices=PUBLISH_ENCODINGS)
    parser.add_argument('--compressed', choices=('jpeg', 'png'),
                        help='publish CompressedImage on image_raw/compressed')
    parser.add_argument('--calibration', help='calibration file for CameraInfo')
    parser.add_argument('--camera', dest='camera_name', help='camera name (in the '
                        'calibration); publishes under /<camera ROS name>/ (00_03 -> cam00_03)')
    parser.add_argument('--reliable', action='store_const', const='reliable',
                        dest='reliability')
    parser.add_argument('--count', type=int, dest='max_frames', help='stop after N frames')
    parser.add_argument('--wait-for-subscribers', type=int, dest='wait_for_subscribers')
    parser.add_argument('--preload', action='store_true', default=None)
    parser.add_argument('--stamp-offset', type=float, dest='stamp_offset_s',
                        help='add this to every stamp [s] (testing a host clock that is off)')
    parser.add_argument('--hold', type=float, dest='hold_s',
                        help='with --loop / --bounce on the grid: show each image this long '
                        '[s]')
    args = parser.parse_args(argv)
    return [Parameter(k, value=v) for k, v in vars(args).items() if v is not None]


def _publish_until_done(node: ImagePublisher, executor: Any) -> None:
    """Spin while the publisher thread runs, then let its last messages go out."""
    worker = threading.Thread(target=node.run, name='publisher', daemon=True)
    worker.start()
    try:
        spin_until_shutdown(executor, node.done.is_set)
    finally:
        node.done.set()
        worker.join(timeout=5.0)
    spin_until_shutdown(executor, spins=5)


def main(args: Optional[List[str]] = None) -> int:
    """Publish until the source ends (or forever with ``--loop``)."""
    return run_node('image_publisher',
                    lambda overrides: ImagePublisher(parameter_overrides=overrides), args,
                    parse_cli=parse_cli, spin=_publish_until_done, usage_errors=(ValueError,))


if __name__ == '__main__':
    sys.exit(main())
