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
Conversions between the core's numpy arrays / ``Track`` objects and ``mv3dpose_msgs``.

The one place where NaN (the core's "missing") becomes explicit validity (``confidence == 0``,
``Joint3D.MISSING``, ``velocity_valid``), so no published field ever carries NaN or inf.
"""

from dataclasses import dataclass
import math
import struct
from typing import Any, Iterable, List, Optional, Sequence, Tuple, Union

from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point, Vector3
from mv3dpose_msgs.msg import (Joint3D, Keypoint2D, Person2D, Person2DArray, SkeletonInfo,
                               TrackedSkeleton, TrackedSkeletonArray)
from mv3dpose_ros.core.types import JointState, Track, TrackState
import numpy as np
from sensor_msgs.msg import RegionOfInterest
from std_msgs.msg import Header


class InvalidMessage(ValueError):
    """
    A message that cannot be used; the text says what and why.

    ``reason`` is a short code for counters and log throttling: 'keypoint_count',
    'non_finite', 'confidence_range' (unusable content) or 'malformed' (bytes that are no
    valid serialisation of the type).
    """

    def __init__(self, text: str, reason: str = 'invalid') -> None:
        super().__init__(text)
        self.reason = reason


def stamp_to_ns(stamp: Time) -> int:
    """Return a ``builtin_interfaces/Time`` as integer nanoseconds (exact)."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def stamp_to_sec(stamp: Time) -> float:
    """Return a ``builtin_interfaces/Time`` in seconds."""
    return stamp_to_ns(stamp) * 1e-9


def ns_to_stamp(ns: int) -> Time:
    """Build a ``builtin_interfaces/Time`` from integer nanoseconds."""
    ns = int(ns)
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def sec_to_stamp(sec: float) -> Time:
    """Build a ``builtin_interfaces/Time`` from seconds (rounded to the nanosecond)."""
    if not math.isfinite(sec):
        return Time()
    return ns_to_stamp(round(sec * 1e9))


# --- 2D people -------------------------------------------------------------------------------

@dataclass
class Persons2D:
    """
    A ``Person2DArray`` as arrays, decoded from CDR without one Python object per keypoint.

    ``keypoints`` holds every person's keypoints back to back (``counts[i]`` of person i).
    Carries the fields ``person2d_array_to_numpy`` and the fusion node's checks read, so
    either this or a ``Person2DArray`` can be passed to them.
    """

    stamp_ns: int
    frame_id: str
    camera_id: str
    image_width: int
    image_height: int
    layout: str
    counts: np.ndarray      # [P] int64 keypoints per person
    keypoints: np.ndarray   # [sum(counts), 3] float32 x, y, confidence
    rois: np.ndarray        # [P, 5] int64 x_offset, y_offset, height, width, do_rectify
    scores: np.ndarray      # [P] float32
    ids: List[str]


# Plain (XCDR1) CDR encapsulations: little / big endian. Anything else goes to rclpy.
_ENCAPSULATIONS = {b'\x00\x01': '<', b'\x00\x00': '>'}
_PERSON_MIN_BYTES = 32   # roi 17 + pad 3 + score 4 + id length 4 + keypoint count 4


def _malformed(text: str) -> InvalidMessage:
    return InvalidMessage(f'malformed Person2DArray CDR: {text}', 'malformed')


def _cdr_string(buf: memoryview, pos: int, u32: struct.Struct) -> Tuple[str, int]:
    """Return ``(text, end)`` of the CDR string whose length field is at or after ``pos``."""
    pos += -pos % 4
    (n,) = u32.unpack_from(buf, pos)
    pos += 4
    end = pos + n
    if end > len(buf):
        raise _malformed(f'string of {n} bytes at offset {pos} runs past the end '
                         f'({len(buf)} bytes)')
    if n == 0:
        return '', end
    if buf[end - 1] != 0:
        raise _malformed(f'string at offset {pos} is not NUL-terminated')
    return bytes(buf[pos:end - 1]).decode('utf-8'), end


def decode_person2d_array(data: Union[bytes, bytearray, memoryview]) -> Persons2D:
    """
    Decode serialised ``Person2DArray`` bytes (what a ``raw=True`` subscription receives).

    About ten times faster than ``rclpy.serialization.deserialize_message`` followed by
    ``person2d_array_to_numpy``, whose cost is one Python object per keypoint. The layout is
    fixed by the .msg files; strict: raises ``InvalidMessage`` (reason 'malformed') for
    truncated bytes, impossible lengths, bad strings, trailing data or an encapsulation other
    than plain CDR, so callers can fall back to rclpy, which has the last word.
    """
    buf = memoryview(data).cast('B')
    size = len(buf)
    endian = _ENCAPSULATIONS.get(bytes(buf[:2])) if size >= 4 else None
    if endian is None:
        raise _malformed(f'{size} bytes with encapsulation {bytes(buf[:4]).hex() or "none"}, '
                         'expected plain CDR (0001 or 0000)')
    u32 = struct.Struct(endian + 'I')
    person = struct.Struct(endian + 'IIIIB3xf')   # roi, score
    try:
        sec, nanosec = struct.unpack_from(endian + 'iI', buf, 4)
        frame_id, pos = _cdr_string(buf, 12, u32)
        camera_id, pos = _cdr_string(buf, pos, u32)
        pos += -pos % 4
        width, height = struct.unpack_from(endian + 'II', buf, pos)
        layout, pos = _cdr_string(buf, pos + 8, u32)
        pos += -pos % 4
        (num,) = u32.unpack_from(buf, pos)
        pos += 4
        if num * _PERSON_MIN_BYTES > size - pos:
            raise _malformed(f'{num} persons cannot fit in the remaining {size - pos} bytes')
        counts, starts, rois, scores, ids = [], [], [], [], []
        for _ in range(num):
            pos += -pos % 4
            x0, y0, h, w, rect, score = person.unpack_from(buf, pos)
            rois.append((x0, y0, h, w, rect))
            scores.append(score)
            text, pos = _cdr_string(buf, pos + 24, u32)
            ids.append(text)
            pos += -pos % 4
            (k,) = u32.unpack_from(buf, pos)
            pos += 4
            if 12 * k > size - pos:
                raise _malformed(f'{k} keypoints at offset {pos} cannot fit in the remaining '
                                 f'{size - pos} bytes')
            counts.append(k)
            starts.append(pos // 4)
            pos += 12 * k
    except struct.error as exc:
        raise _malformed(f'truncated ({size} bytes): {exc}') from None
    except UnicodeDecodeError as exc:
        raise _malformed(f'string is not UTF-8: {exc}') from None
    if size - pos > 3:                 # at most padding to a multiple of 4 may follow
        raise _malformed(f'{size - pos} bytes after the last person (expected {pos})')
    if num:
        words = np.frombuffer(buf, dtype=endian + 'f4', count=size // 4)
        kps = np.concatenate([words[s:s + 3 * k] for s, k in zip(starts, counts)])
    else:
        kps = np.zeros(0, np.float32)
    return Persons2D(stamp_ns=sec * 1_000_000_000 + nanosec, frame_id=frame_id,
                     camera_id=camera_id, image_width=width, image_height=height,
                     layout=layout, counts=np.asarray(counts, dtype=np.int64),
                     keypoints=kps.astype(np.float32).reshape(-1, 3),
                     rois=np.asarray(rois, dtype=np.int64).reshape(-1, 5),
                     scores=np.asarray(scores, dtype=np.float32), ids=ids)


def person2d_array_to_numpy(msg: Union[Person2DArray, Persons2D],
                            num_joints: Optional[int] = None) -> np.ndarray:
    """
    Return the people of ``msg`` as a ``[P, J, 3]`` float64 array (x px, y px, confidence).

    ``msg`` is a ``Person2DArray`` or its decoded ``Persons2D``. Raises ``InvalidMessage``
    for a keypoint count that differs between people or from ``num_joints`` (reason
    'keypoint_count'), for NaN/inf values ('non_finite') and for confidences outside [0, 1]
    ('confidence_range'). Keypoints with confidence 0 keep confidence 0 (their x, y are
    meaningless and zeroed).
    """
    if isinstance(msg, Persons2D):
        counts = msg.counts.tolist()
        flat = msg.keypoints
    else:
        persons = msg.persons
        counts = [len(p.keypoints) for p in persons]
        flat = None
    if not counts:
        return np.zeros((0, num_joints or 0, 3))
    distinct = set(counts)
    if len(distinct) != 1:
        raise InvalidMessage(f'people have different keypoint counts {sorted(distinct)}',
                             'keypoint_count')
    count = distinct.pop()
    if num_joints is not None and count != num_joints:
        raise InvalidMessage(
            f'{count} keypoints per person, layout {msg.layout!r} has {num_joints}',
            'keypoint_count')
    if flat is None:
        flat = [v for p in persons for k in p.keypoints for v in (k.x, k.y, k.confidence)]
    poses = np.asarray(flat, dtype=np.float64).reshape(len(counts), count, 3)
    if not np.all(np.isfinite(poses)):
        raise InvalidMessage('NaN or inf in keypoints', 'non_finite')
    conf = poses[..., 2]
    if np.any(conf < 0.0) or np.any(conf > 1.0):
        raise InvalidMessage(
            f'keypoint confidence outside [0, 1] (min {conf.min():.3g}, max {conf.max():.3g})',
            'confidence_range')
    poses[conf == 0.0, :2] = 0.0
    return poses


def numpy_to_person2d_array(poses: np.ndarray, header: Header, camera_id: str,
                            image_width: int, image_height: int, layout: str,
                            boxes: Optional[np.ndarray] = None,
                            scores: Optional[np.ndarray] = None) -> Person2DArray:
    """
    Build a ``Person2DArray`` from ``[P, J, 3]`` poses; NaN or missing joints get conf 0.

    ``boxes`` are ``[P, 4]`` (x0, y0, x1, y1) pixels; when absent the box of the visible
    keypoints is used. ``scores`` default to the mean keypoint confidence.
    """
    poses = np.asarray(poses, dtype=np.float64)
    if poses.size == 0:
        poses = np.zeros((0, 0, 3))
    valid = np.all(np.isfinite(poses), axis=-1) & (np.nan_to_num(poses[..., 2]) > 0.0)
    clean = np.where(valid[..., None], poses, 0.0)
    clean[..., 2] = np.clip(clean[..., 2], 0.0, 1.0)
    msg = Person2DArray(header=header, camera_id=camera_id, image_width=int(image_width),
                        image_height=int(image_height), layout=layout)
    for i in range(clean.shape[0]):
        person = Person2D()
        person.keypoints = [Keypoint2D(x=float(x), y=float(y), confidence=float(c))
                            for x, y, c in clean[i].tolist()]
        if boxes is not None and np.all(np.isfinite(boxes[i])):
            x0, y0, x1, y1 = (float(v) for v in boxes[i])
        elif valid[i].any():
            pts = clean[i, valid[i], :2]
            (x0, y0), (x1, y1) = pts.min(axis=0), pts.max(axis=0)
        else:
            x0 = y0 = x1 = y1 = 0.0
        x0, y0 = max(0.0, x0), max(0.0, y0)
        x1, y1 = min(float(image_width), x1), min(float(image_height), y1)
        person.roi = RegionOfInterest(x_offset=int(x0), y_offset=int(y0),
                                      width=int(max(0.0, x1 - x0)),
                                      height=int(max(0.0, y1 - y0)), do_rectify=False)
        if scores is not None and math.isfinite(float(scores[i])):
            person.score = float(np.clip(scores[i], 0.0, 1.0))
        else:
            person.score = float(clean[i, valid[i], 2].mean()) if valid[i].any() else 0.0
        msg.persons.append(person)
    return msg


def skeleton_info_msg(layout: Any, header: Optional[Header] = None) -> SkeletonInfo:
    """Build the latched ``SkeletonInfo`` of a ``core.skeleton.Layout``."""
    return SkeletonInfo(header=header or Header(), layout=layout.name,
                        joint_names=list(layout.joint_names),
                        bones=[int(i) for bone in layout.bones for i in bone])


# --- 3D tracks -------------------------------------------------------------------------------

def _finite(value: float, default: float = 0.0) -> float:
    value = float(value)
    return value if math.isfinite(value) else default


def track_to_msg(track: Track) -> TrackedSkeleton:
    """Convert one core ``Track`` to a ``TrackedSkeleton`` (NaN becomes explicit validity)."""
    msg = TrackedSkeleton(track_id=int(track.track_id), state=int(track.state),
                          confidence=float(np.clip(_finite(track.score), 0.0, 1.0)),
                          first_seen=sec_to_stamp(track.first_seen),
                          last_observed=sec_to_stamp(track.last_observed),
                          age=int(track.age), missed=int(track.missed))
    root = np.asarray(track.position, dtype=np.float64)
    if np.all(np.isfinite(root)):
        msg.position = Point(x=float(root[0]), y=float(root[1]), z=float(root[2]))
    vel = np.asarray(track.velocity, dtype=np.float64)
    msg.velocity_valid = bool(np.all(np.isfinite(vel)))
    if msg.velocity_valid:
        msg.velocity = Vector3(x=float(vel[0]), y=float(vel[1]), z=float(vel[2]))
    msg.position_covariance = [-1.0] + [0.0] * 8
    states = np.asarray(track.joint_state, dtype=np.uint8)
    xyz = np.asarray(track.joints, dtype=np.float64)
    usable = (states != JointState.MISSING) & np.all(np.isfinite(xyz), axis=1)
    xyz = np.where(usable[:, None], xyz, 0.0).tolist()
    conf = np.clip(np.nan_to_num(np.asarray(track.confidence, dtype=np.float64)), 0.0, 1.0)
    err = np.nan_to_num(np.asarray(track.reprojection_error, dtype=np.float64), nan=-1.0,
                        posinf=-1.0, neginf=-1.0)
    views = np.asarray(track.num_views).astype(np.int64).clip(0, 255)
    joints = []
    for j, (x, y, z) in enumerate(xyz):
        ok = bool(usable[j])
        joints.append(Joint3D(
            position=Point(x=x, y=y, z=z), confidence=float(conf[j]) if ok else 0.0,
            state=int(states[j]) if ok else JointState.MISSING,
            num_views=int(views[j]) if ok else 0,
            reprojection_error=float(err[j]) if ok else -1.0))
    msg.joints = joints
    msg.source_cameras = list(track.source_cameras)
    return msg


def tracks_to_msg(tracks: Iterable[Track], header: Header, layout: str) -> TrackedSkeletonArray:
    """Build the ``TrackedSkeletonArray`` of one synchronised set."""
    return TrackedSkeletonArray(header=header, layout=layout,
                                skeletons=[track_to_msg(t) for t in tracks])


def msg_to_tracks(msg: TrackedSkeletonArray) -> List[Track]:
    """Convert a ``TrackedSkeletonArray`` back to core ``Track`` objects (MISSING -> NaN)."""
    tracks = []
    for s in msg.skeletons:
        states = np.array([j.state for j in s.joints], dtype=np.uint8)
        joints = np.array([[j.position.x, j.position.y, j.position.z] for j in s.joints],
                          dtype=np.float64).reshape(-1, 3)
        joints[states == JointState.MISSING] = np.nan
        err = np.array([j.reprojection_error for j in s.joints], dtype=np.float64)
        err[err < 0] = np.nan
        velocity = (np.array([s.velocity.x, s.velocity.y, s.velocity.z]) if s.velocity_valid
                    else np.full(3, np.nan))
        tracks.append(Track(
            track_id=int(s.track_id), state=TrackState(s.state), joints=joints,
            confidence=np.array([j.confidence for j in s.joints], dtype=np.float64),
            joint_state=states, num_views=np.array([j.num_views for j in s.joints], np.uint8),
            reprojection_error=err,
            position=np.array([s.position.x, s.position.y, s.position.z], dtype=np.float64),
            velocity=velocity, first_seen=stamp_to_sec(s.first_seen),
            last_observed=stamp_to_sec(s.last_observed), age=int(s.age), missed=int(s.missed),
            score=float(s.confidence), source_cameras=tuple(s.source_cameras)))
    return tracks


# --- generic ---------------------------------------------------------------------------------

def message_to_dict(msg: Any) -> Any:
    """Convert any ROS message to plain Python values, recursively (for comparison / JSON)."""
    if hasattr(msg, 'get_fields_and_field_types'):
        return {name: message_to_dict(getattr(msg, name))
                for name in msg.get_fields_and_field_types()}
    if isinstance(msg, (list, tuple)) or type(msg).__name__ in ('array', 'ndarray'):
        return [message_to_dict(v) for v in msg]
    if isinstance(msg, (bytes, bytearray)):
        return list(msg)
    if isinstance(msg, np.generic):
        return msg.item()
    return msg


def float32_exact(values: Sequence[float]) -> List[float]:
    """Round values to float32 so that they survive a float32 message field unchanged."""
    return np.asarray(values, dtype=np.float32).astype(np.float64).tolist()
