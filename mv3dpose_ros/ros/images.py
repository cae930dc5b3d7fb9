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
``sensor_msgs/Image`` and ``CameraInfo`` <-> numpy without cv_bridge (not in the wheels).

Only 8-bit encodings are supported: ``bgr8``, ``rgb8``, ``mono8`` (and their OpenCV aliases
``8UC3`` = bgr8, ``8UC1`` = mono8). Row padding (``step`` > width x channels) is handled; the
returned array is a view on the message buffer when possible (no copy).
"""

import struct
from typing import Any, Optional, Tuple, Union

from builtin_interfaces.msg import Time
import numpy as np
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import Header

#: encoding -> (channels, channel order understood by the pose estimators)
ENCODINGS = {'bgr8': (3, 'bgr'), 'rgb8': (3, 'rgb'), 'mono8': (1, 'gray'),
             '8UC3': (3, 'bgr'), '8UC1': (1, 'gray')}


class ImageError(ValueError):
    """An image message the pipeline cannot read; the text says which field and why."""


def parse_image_cdr(buf: bytes) -> Tuple[Image, memoryview]:
    """
    Read a serialised ``sensor_msgs/Image`` (plain CDR) without copying its pixels.

    Returns the message with empty ``data`` plus a view of the pixel bytes. A subscription with
    ``raw=True`` then skips rclpy's two copies of the pixels (C struct, then ``array``), about
    1 ms per 1080p frame. Raises ``ImageError`` for anything but plain little/big-endian CDR
    (callers fall back to ``rclpy.serialization.deserialize_message``).
    """
    view = memoryview(buf)
    if len(view) < 8 or view[0] != 0 or view[1] not in (0, 1):
        raise ImageError('not a plain CDR sensor_msgs/Image')
    end = '<' if view[1] == 1 else '>'
    pos = 4

    def align4(p: int) -> int:
        return 4 + ((p - 4 + 3) & ~3)

    def string(p: int) -> Tuple[str, int]:
        p = align4(p)
        (n,) = struct.unpack_from(end + 'I', view, p)
        text = bytes(view[p + 4:p + 4 + max(0, n - 1)]).decode('utf-8')
        return text, p + 4 + n

    try:
        sec, nanosec = struct.unpack_from(end + 'iI', view, pos)
        frame_id, pos = string(pos + 8)
        pos = align4(pos)
        height, width = struct.unpack_from(end + 'II', view, pos)
        encoding, pos = string(pos + 8)
        is_bigendian = view[pos]
        pos = align4(pos + 1)
        step, size = struct.unpack_from(end + 'II', view, pos)
    except (struct.error, IndexError, UnicodeDecodeError) as exc:
        raise ImageError(f'truncated or malformed sensor_msgs/Image CDR: {exc}') from None
    pos += 8
    if pos + size > len(view):
        raise ImageError(f'Image CDR declares {size} data bytes, {len(view) - pos} present')
    msg = Image(header=Header(stamp=Time(sec=sec, nanosec=nanosec), frame_id=frame_id),
                height=height, width=width, encoding=encoding, is_bigendian=is_bigendian,
                step=step)
    return msg, view[pos:pos + size]


def image_to_numpy(msg: Image, data: Union[bytes, memoryview, None] = None
                   ) -> Tuple[np.ndarray, str]:
    """
    Return ``(array, order)``: uint8 ``[H, W, 3]`` or ``[H, W]`` and 'bgr' | 'rgb' | 'gray'.

    ``data`` replaces ``msg.data`` (the pixel view from ``parse_image_cdr``). Raises
    ``ImageError`` for unsupported encodings and inconsistent sizes.
    """
    if msg.encoding not in ENCODINGS:
        raise ImageError(f'unsupported image encoding {msg.encoding!r}; supported: '
                         f'{", ".join(ENCODINGS)} (convert upstream, e.g. debayer / '
                         f'image_proc, or publish bgr8)')
    channels, order = ENCODINGS[msg.encoding]
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    if h <= 0 or w <= 0:
        raise ImageError(f'empty image {w}x{h}')
    if step < w * channels:
        raise ImageError(f'step {step} < width {w} x {channels} channels')
    buf = np.frombuffer(msg.data if data is None else data, dtype=np.uint8)
    if buf.size < h * step:
        raise ImageError(f'image data has {buf.size} bytes, expected height {h} x step {step}'
                         f' = {h * step}')
    rows = buf[:h * step].reshape(h, step)[:, :w * channels]
    arr = rows.reshape(h, w, channels) if channels == 3 else rows.reshape(h, w)
    return arr, order


def numpy_to_image(array: np.ndarray, header: Optional[Header] = None,
                   encoding: str = 'bgr8') -> Image:
    """Build an ``Image`` from a uint8 ``[H, W, 3]`` (bgr8 / rgb8) or ``[H, W]`` (mono8)."""
    array = np.ascontiguousarray(array)
    if array.dtype != np.uint8:
        raise ImageError(f'image array must be uint8, got {array.dtype}')
    channels = 1 if array.ndim == 2 else array.shape[2]
    if encoding not in ENCODINGS or ENCODINGS[encoding][0] != channels:
        raise ImageError(f'encoding {encoding!r} does not fit an array of shape {array.shape}')
    msg = Image(header=header or Header(), height=int(array.shape[0]),
                width=int(array.shape[1]), encoding=encoding, is_bigendian=0,
                step=int(array.shape[1] * channels))
    msg.data = array.tobytes()
    return msg


def camera_info_from_camera(camera: Any, header: Optional[Header] = None) -> CameraInfo:
    """
    Build a ``CameraInfo`` (plumb_bob, raw image) from a ``core.camera.Camera``.

    R is identity and P = [K | 0]: the keypoints refer to the raw, unrectified image.
    """
    k = np.asarray(camera.K, dtype=np.float64).reshape(3, 3)
    dist = np.zeros(5)
    src = np.asarray(camera.dist, dtype=np.float64).reshape(-1)
    dist[:min(5, src.size)] = src[:5]
    p = np.zeros((3, 4))
    p[:, :3] = k
    return CameraInfo(header=header or Header(), width=int(camera.width),
                      height=int(camera.height), distortion_model='plumb_bob',
                      d=dist.tolist(), k=k.reshape(-1).tolist(),
                      r=np.eye(3).reshape(-1).tolist(), p=p.reshape(-1).tolist())
