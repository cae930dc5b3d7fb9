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
fusion_node's inputs: per-camera input statistics and the checks of each ``Person2DArray``.

Every input is validated before it reaches the synchroniser (``PersonsInputCheck``): a bad
message raises ``InvalidMessage`` with a reason code (counted per camera in
``CameraInputStats.rejected`` and named in ``/diagnostics``) and a text naming what is wrong,
so it can neither stop the node nor reach the tracker. ``camera_from_info`` reads a
``CameraInfo``'s intrinsics (``intrinsics_source: camera_info``).
"""

from collections import Counter
from typing import Any, Callable, Dict, Optional, Set, Tuple

from mv3dpose_ros.core.geometry.camera import CalibrationError, Camera, fit_image_size
from mv3dpose_ros.core.skeleton import convert_poses, get_layout, Layout, LAYOUT_NAMES
from mv3dpose_ros.core.types import NS_PER_S
from mv3dpose_ros.ros.diagnostics import FrequencyStats, TimestampStats
from mv3dpose_ros.ros.messages import (decode_person2d_array, InvalidMessage,
                                       person2d_array_to_numpy, Persons2D, stamp_to_ns)
import numpy as np


class CameraInputStats:
    """One camera's input statistics and counters (for /diagnostics and the tests)."""

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

    def arrived(self, now_ns: int) -> None:
        """Count a message that arrived at ``now_ns`` (steady clock), usable or not."""
        self.received += 1
        self.freq.tick()
        self.last_rx_ns = now_ns

    @property
    def calibration_problem(self) -> str:
        """Return what disagrees with the calibration ('' when nothing)."""
        return '; '.join(p for p in (self.info_problem, self.size_problem) if p)


class PersonsInputCheck:
    """Decode and validate ``Person2DArray`` inputs against the rig, layout and limits."""

    def __init__(self, rig: Dict[str, Camera], layout: Layout, rig_path: str,
                 max_persons: int, max_message_bytes: int, max_future_ns: int,
                 tolerance_px: int, warn: Callable[[str], None]) -> None:
        self.rig = rig                         # calibration per camera (CameraInfo may update)
        self.layout, self.rig_path = layout, rig_path
        self.max_persons, self.max_message_bytes = max_persons, max_message_bytes
        self.max_future_ns, self.tolerance_px = max_future_ns, tolerance_px
        self._warn = warn
        self.size_logged: Set[tuple] = set()   # (camera, image and calibration sizes) logged

    def read(self, msg: Any) -> Tuple[Any, int]:
        """Return ``(message, stamp_ns)`` of raw CDR or a ``Person2DArray``; InvalidMessage."""
        if not isinstance(msg, (bytes, bytearray, memoryview)):
            return msg, stamp_to_ns(msg.header.stamp)
        if len(msg) > self.max_message_bytes:
            raise InvalidMessage(f'{len(msg)} bytes > limits.max_message_bytes '
                                 f'{self.max_message_bytes}', 'too_large')
        # rclpy refuses what the decoder refuses ('malformed'): no object per keypoint.
        msg = decode_person2d_array(msg)
        stamp_ns = msg.stamp_ns if isinstance(msg, Persons2D) else stamp_to_ns(msg.header.stamp)
        return msg, stamp_ns

    def validate(self, state: CameraInputStats, msg: Any, stamp_ns: int,
                 now_ns: int) -> np.ndarray:
        """Return the poses ``[P, J, 3]`` in the fused layout; InvalidMessage when unusable."""
        cam = state.name
        if msg.camera_id and msg.camera_id != cam:
            if msg.camera_id not in self.rig:
                raise InvalidMessage(f'camera_id {msg.camera_id!r} is not in the rig '
                                     f'({", ".join(self.rig)})', 'unknown_camera')
            raise InvalidMessage(f'camera_id {msg.camera_id!r} arrived on the topic of camera '
                                 f'{cam!r} (remapping mistake?)', 'wrong_camera')
        if stamp_ns <= 0:
            raise InvalidMessage('header stamp is zero (the publisher must copy the image '
                                 'capture stamp)', 'zero_stamp')
        if now_ns > 0 and stamp_ns > now_ns + self.max_future_ns:
            raise InvalidMessage(f'stamp {stamp_ns / NS_PER_S:.3f} s is '
                                 f'{(stamp_ns - now_ns) / NS_PER_S:.3f} s ahead of the node '
                                 f'clock (limit input_max_future_s)', 'future_stamp')
        calib = self.rig[cam]
        fit = None
        if msg.image_width and msg.image_height and (
                msg.image_width != calib.width or msg.image_height != calib.height):
            # A codec's crop/padding or a resized stream is mapped into the calibration's
            # pixels (core.camera.fit_image_size); only what cannot be explained is dropped.
            fit = fit_image_size(calib.width, calib.height, msg.image_width, msg.image_height,
                                 self.tolerance_px)
            source = 'CameraInfo' if state.camera_info_received else self.rig_path
            if not fit.accepted:
                state.size_problem = (
                    f'image_width x image_height differs from the calibration ({source}): '
                    f'{fit.note}; parameter input_image_size_tolerance_px '
                    f'({self.tolerance_px}) sets the crop or padding accepted')
                raise InvalidMessage(state.size_problem, 'image_size')
            key = (cam, fit.image_size, fit.calib_size)
            if key not in self.size_logged:
                self.size_logged.add(key)
                self._warn(f'camera {cam} on {state.topic}: {fit.note} ({fit.kind}; calibration '
                           f'from {source}; parameter input_image_size_tolerance_px '
                           f'{self.tolerance_px}); logged once per size')
        state.size_problem = ''
        persons = len(msg.counts) if isinstance(msg, Persons2D) else len(msg.persons)
        if persons > self.max_persons:
            raise InvalidMessage(f'{persons} persons > limits.max_persons {self.max_persons} '
                                 '(dropped whole, not clipped)', 'too_many_persons')
        try:
            src = get_layout(msg.layout or self.layout.name)
        except ValueError:
            raise InvalidMessage(f'layout {msg.layout!r} unknown (known: '
                                 f'{", ".join(LAYOUT_NAMES)})', 'unknown_layout') from None
        poses = person2d_array_to_numpy(msg, src.num_joints)
        if fit is not None:
            poses = fit.apply(poses)
        if src.name != self.layout.name and len(poses):
            poses = convert_poses(poses, src, self.layout)
            poses[~np.isfinite(poses).all(axis=-1)] = 0.0
        elif src.name != self.layout.name:
            poses = np.zeros((0, self.layout.num_joints, 3))
        if len(poses) == 0:
            poses = poses.reshape(0, self.layout.num_joints, 3)
        return poses


def camera_from_info(rig_camera: Camera, msg: Any) -> Camera:
    """Return ``rig_camera`` with the intrinsics of a ``CameraInfo`` (errors name the field)."""
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
