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
``sensor_msgs/Image``, ``CompressedImage`` and ``CameraInfo`` <-> numpy without cv_bridge.

``image_to_numpy`` returns what the pose estimators take (uint8, order 'bgr' | 'rgb' | 'gray')
from the encodings camera drivers publish: ``bgr8``, ``rgb8``, ``mono8``, ``bgra8``, ``rgba8``
(alpha dropped), ``mono16`` (scaled to 8 bits by its bit depth: 10-, 12- and 16-bit sensors keep
their brightness), ``yuv422`` (UYVY) and ``yuv422_yuy2`` (YUYV), plus the OpenCV aliases
``8UC1``, ``8UC3`` (= bgr8), ``8UC4`` (= bgra8) and ``16UC1`` (= mono16). Row padding
(``step`` > width x bytes per pixel) is handled; 8-bit colour and grey arrays are views on the
message buffer (no copy).

``compressed_to_numpy`` decodes ``image_transport``'s ``<image>/compressed`` (JPEG or PNG;
``format`` like ``bgr8; jpeg compressed bgr8``); ``numpy_to_compressed`` writes the same.
"""

from typing import Any, Optional, Tuple, Union

from builtin_interfaces.msg import Time
import cv2
from mv3dpose_ros.ros.cdr import CdrError, CdrReader, PLAIN_CDR
import numpy as np
from sensor_msgs.msg import CameraInfo, CompressedImage, Image
from std_msgs.msg import Header

#: encodings numpy_to_image writes: encoding -> (channels, channel order)
ENCODINGS = {'bgr8': (3, 'bgr'), 'rgb8': (3, 'rgb'), 'mono8': (1, 'gray'),
             '8UC3': (3, 'bgr'), '8UC1': (1, 'gray')}

#: every encoding image_to_numpy reads: encoding -> (bytes per pixel, channels in the buffer)
READ_ENCODINGS = {**{k: (c, c) for k, (c, _) in ENCODINGS.items()},
                  'bgra8': (4, 4), 'rgba8': (4, 4), '8UC4': (4, 4),
                  'mono16': (2, 1), '16UC1': (2, 1),
                  'yuv422': (2, 2), 'uyvy': (2, 2), 'yuv422_yuy2': (2, 2), 'yuyv': (2, 2)}
_ORDER = {'bgr8': 'bgr', '8UC3': 'bgr', 'rgb8': 'rgb', 'mono8': 'gray', '8UC1': 'gray',
          'bgra8': 'bgr', '8UC4': 'bgr', 'rgba8': 'rgb', 'mono16': 'gray', '16UC1': 'gray',
          'yuv422': 'bgr', 'uyvy': 'bgr', 'yuv422_yuy2': 'bgr', 'yuyv': 'bgr'}
_YUV = {'yuv422': cv2.COLOR_YUV2BGR_UYVY, 'uyvy': cv2.COLOR_YUV2BGR_UYVY,
        'yuv422_yuy2': cv2.COLOR_YUV2BGR_YUY2, 'yuyv': cv2.COLOR_YUV2BGR_YUY2}


class ImageError(ValueError):
    """An image message the pipeline cannot read; the text says which field and why."""


def _reader(buf: bytes, what: str) -> CdrReader:
    try:
        return CdrReader(buf, PLAIN_CDR)
    except CdrError:
        raise ImageError(f'not a plain CDR {what}') from None


def parse_image_cdr(buf: bytes) -> Tuple[Image, memoryview]:
    """
    Read a serialised ``sensor_msgs/Image`` (plain CDR) without copying its pixels.

    Returns the message with empty ``data`` plus a view of the pixel bytes. A subscription with
    ``raw=True`` then skips rclpy's two copies of the pixels (C struct, then ``array``), about
    1 ms per 1080p frame. Raises ``ImageError`` for anything but plain little/big-endian CDR
    (callers fall back to ``rclpy.serialization.deserialize_message``).
    """
    r = _reader(buf, 'sensor_msgs/Image')
    try:
        sec, nanosec, frame_id = r.header()
        height, width = r.unpack('II')
        encoding = r.string()
        (is_bigendian,) = r.unpack('B', align=1)
        step, size = r.unpack('II')
    except CdrError as exc:
        raise ImageError(f'truncated or malformed sensor_msgs/Image CDR: {exc}') from None
    if size > r.remaining:
        raise ImageError(f'Image CDR declares {size} data bytes, {r.remaining} present')
    msg = Image(header=Header(stamp=Time(sec=sec, nanosec=nanosec), frame_id=frame_id),
                height=height, width=width, encoding=encoding, is_bigendian=is_bigendian,
                step=step)
    return msg, r.take(size)


def parse_compressed_cdr(buf: bytes) -> Tuple[CompressedImage, memoryview]:
    """
    Read a serialised ``sensor_msgs/CompressedImage`` (plain CDR) without copying its data.

    Returns the message with empty ``data`` plus a view of the compressed bytes; raises
    ``ImageError`` for anything but plain CDR (fall back to ``deserialize_message``).
    """
    r = _reader(buf, 'sensor_msgs/CompressedImage')
    try:
        sec, nanosec, frame_id = r.header()
        fmt = r.string()
        size = r.u32()
    except CdrError as exc:
        raise ImageError(f'truncated or malformed sensor_msgs/CompressedImage CDR: '
                         f'{exc}') from None
    if size > r.remaining:
        raise ImageError(f'CompressedImage CDR declares {size} data bytes, {r.remaining} '
                         'present')
    msg = CompressedImage(header=Header(stamp=Time(sec=sec, nanosec=nanosec),
                                        frame_id=frame_id), format=fmt)
    return msg, r.take(size)


def _unsupported(encoding: str) -> ImageError:
    return ImageError(f'unsupported image encoding {encoding!r}; supported: '
                      f'{", ".join(READ_ENCODINGS)} (convert upstream, e.g. debayer with '
                      'image_proc, or publish bgr8)')


def image_to_numpy(msg: Image, data: Union[bytes, memoryview, None] = None
                   ) -> Tuple[np.ndarray, str]:
    """
    Return ``(array, order)``: uint8 ``[H, W, 3]`` or ``[H, W]`` and 'bgr' | 'rgb' | 'gray'.

    ``data`` replaces ``msg.data`` (the pixel view from ``parse_image_cdr``). Raises
    ``ImageError`` for unsupported encodings and inconsistent sizes.
    """
    encoding = msg.encoding
    if encoding not in READ_ENCODINGS:
        raise _unsupported(encoding)
    size, channels = READ_ENCODINGS[encoding]
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    if h <= 0 or w <= 0:
        raise ImageError(f'empty image {w}x{h}')
    if step < w * size:
        raise ImageError(f'step {step} < width {w} x {size} bytes per pixel ({encoding})')
    if encoding in _YUV and w % 2:
        raise ImageError(f'{encoding} needs an even width, got {w}')
    buf = np.frombuffer(msg.data if data is None else data, dtype=np.uint8)
    if buf.size < h * step:
        raise ImageError(f'image data has {buf.size} bytes, expected height {h} x step {step}'
                         f' = {h * step}')
    rows = buf[:h * step].reshape(h, step)[:, :w * size]
    order = _ORDER[encoding]
    if size == 2 and channels == 1:                   # mono16: to 8 bits by its bit depth
        wide = rows.view('>u2' if msg.is_bigendian else '<u2').reshape(h, w)
        bits = max(8, int(wide.max()).bit_length())
        return (wide >> (bits - 8)).astype(np.uint8), order
    if encoding in _YUV:
        return cv2.cvtColor(rows.reshape(h, w, 2), _YUV[encoding]), order
    if channels == 1:
        return rows.reshape(h, w), order
    if channels == 4:                                 # bgra8 / rgba8: drop alpha (one copy)
        return np.ascontiguousarray(rows.reshape(h, w, 4)[:, :, :3]), order
    return rows.reshape(h, w, 3), order


def compressed_to_numpy(msg: CompressedImage, data: Union[bytes, memoryview, None] = None
                        ) -> Tuple[np.ndarray, str]:
    """
    Decode a ``CompressedImage`` (JPEG or PNG) to ``(array, order)`` like ``image_to_numpy``.

    ``format`` is image_transport's ``'<encoding>; jpeg compressed <encoding>'`` (or just
    ``jpeg`` / ``png``); mono sources decode to grey, others to BGR. ``compressedDepth`` and
    bytes OpenCV cannot decode raise ``ImageError``.
    """
    fmt = str(msg.format).strip()
    if 'compressedDepth' in fmt:
        raise ImageError(f'CompressedImage format {fmt!r} is a depth image, not a camera image')
    raw = np.frombuffer(msg.data if data is None else data, dtype=np.uint8)
    if raw.size == 0:
        raise ImageError(f'empty CompressedImage (format {fmt!r})')
    source = fmt.split(';', 1)[0].strip().lower()
    gray = source.startswith('mono') or source in ('8uc1', '16uc1')
    image = cv2.imdecode(raw, cv2.IMREAD_GRAYSCALE if gray else cv2.IMREAD_COLOR)
    if image is None:
        raise ImageError(f'cannot decode CompressedImage ({raw.size} bytes, format {fmt!r}): '
                         'not JPEG or PNG, or truncated')
    return image, 'gray' if image.ndim == 2 else 'bgr'


def decode_image_bytes(buf: Union[bytes, memoryview], compressed: bool = False
                       ) -> Tuple[Union[Image, CompressedImage], Optional[memoryview]]:
    """
    Return ``(message, data)`` of a serialised ``Image`` (or ``CompressedImage``).

    Plain CDR is read in place (``data`` is a view of the pixel / compressed bytes); anything
    else goes through rclpy's deserialiser (``data`` None). What a ``raw=True`` image
    subscription gets goes here, then to ``message_to_numpy``.
    """
    try:
        return parse_compressed_cdr(buf) if compressed else parse_image_cdr(buf)
    except ImageError:                  # not plain CDR: let rclpy decode it
        from rclpy.serialization import deserialize_message
        try:
            return deserialize_message(bytes(buf), CompressedImage if compressed else Image), None
        except Exception as exc:  # noqa: B902 - rclpy raises several error types
            raise ImageError(f'undecodable {"CompressedImage" if compressed else "Image"} '
                             f'bytes: {exc}') from None


def message_to_numpy(msg: Union[Image, CompressedImage],
                     data: Union[bytes, memoryview, None] = None) -> Tuple[np.ndarray, str]:
    """Decode an ``Image`` or ``CompressedImage`` (``image_to_numpy``, ``compressed_to_numpy``)."""
    if isinstance(msg, CompressedImage):
        return compressed_to_numpy(msg, data)
    return image_to_numpy(msg, data)


def numpy_to_compressed(array: np.ndarray, header: Optional[Header] = None,
                        fmt: str = 'jpeg', quality: int = 90) -> CompressedImage:
    """
    Build a ``CompressedImage`` as ``compressed_image_transport`` does (format string included).

    ``array`` is uint8 BGR ``[H, W, 3]`` or grey ``[H, W]``; ``fmt`` 'jpeg' or 'png'.
    """
    if fmt not in ('jpeg', 'png'):
        raise ImageError(f"compressed format must be 'jpeg' or 'png', got {fmt!r}")
    array = np.ascontiguousarray(array)
    if array.dtype != np.uint8 or array.ndim not in (2, 3):
        raise ImageError(f'image array must be uint8 [H, W(, 3)], got {array.dtype} '
                         f'{array.shape}')
    encoding = 'mono8' if array.ndim == 2 else 'bgr8'
    params = ([cv2.IMWRITE_JPEG_QUALITY, int(quality)] if fmt == 'jpeg' else
              [cv2.IMWRITE_PNG_COMPRESSION, 1])
    ok, data = cv2.imencode('.jpg' if fmt == 'jpeg' else '.png', array, params)
    if not ok:
        raise ImageError(f'OpenCV could not encode a {array.shape} image as {fmt}')
    msg = CompressedImage(header=header or Header(),
                          format=f'{encoding}; {fmt} compressed {encoding}')
    msg.data = data.tobytes()
    return msg


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


def bgr_to_image(bgr: np.ndarray, encoding: str = 'bgr8', header: Optional[Header] = None
                 ) -> Image:
    """
    Build an ``Image`` of any encoding ``image_to_numpy`` reads from a uint8 BGR frame.

    What a camera driver would publish: ``bgra8`` / ``rgba8`` (alpha 255), ``mono16`` (8 bits
    shifted to 16), ``yuv422`` (UYVY) / ``yuv422_yuy2`` (YUYV), BT.601 video range as OpenCV
    decodes it. Used by image_publisher and the tests.
    """
    bgr = np.ascontiguousarray(bgr)
    if bgr.dtype != np.uint8 or bgr.ndim != 3 or bgr.shape[2] != 3:
        raise ImageError(f'expected a uint8 [H, W, 3] BGR frame, got {bgr.dtype} {bgr.shape}')
    h, w = bgr.shape[:2]
    if encoding in ('bgr8', '8UC3'):
        return numpy_to_image(bgr, header, encoding)
    if encoding == 'rgb8':
        return numpy_to_image(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), header, 'rgb8')
    if encoding in ('mono8', '8UC1'):
        return numpy_to_image(cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY), header, encoding)
    if encoding in ('bgra8', 'rgba8', '8UC4'):
        out = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGBA if encoding == 'rgba8' else cv2.COLOR_BGR2BGRA)
    elif encoding in ('mono16', '16UC1'):
        out = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY).astype('<u2') << 8
    elif encoding in _YUV:
        if w % 2 or h % 2:
            raise ImageError(f'{encoding} needs an even size, got {w}x{h}')
        i420 = cv2.cvtColor(bgr, cv2.COLOR_BGR2YUV_I420)      # Y, then U and V at h/2 x w/2
        u, v = (np.repeat(c, 2, axis=0) for c in i420[h:].reshape(2, h // 2, w // 2))
        yuy2 = _YUV[encoding] == cv2.COLOR_YUV2BGR_YUY2
        out = np.empty((h, w, 2), np.uint8)
        out[..., 0 if yuy2 else 1] = i420[:h]
        out[:, 0::2, 1 if yuy2 else 0] = u
        out[:, 1::2, 1 if yuy2 else 0] = v
    else:
        raise _unsupported(encoding)
    msg = Image(header=header or Header(), height=h, width=w, encoding=encoding,
                is_bigendian=0, step=int(out.strides[0]))
    msg.data = out.tobytes()
    return msg


def camera_info_from_camera(camera: Any, header: Optional[Header] = None) -> CameraInfo:
    """
    Build a ``CameraInfo`` (plumb_bob, raw image) from a ``core.geometry.camera.Camera``.

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


def image_from_message(msg: Any) -> np.ndarray:
    """
    Return a BGR (or grey) uint8 array of a ``sensor_msgs/Image``, rclpy's or a rosbags one.

    ``image_to_numpy`` reads it; RGB orders are swapped to BGR, what OpenCV draws and writes.
    """
    image, order = image_to_numpy(msg)
    if order == 'rgb':
        image = cv2.cvtColor(image, cv2.COLOR_RGB2BGR)
    return np.ascontiguousarray(image)
