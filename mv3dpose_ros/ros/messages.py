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

import math
from typing import Any, Dict, Iterable, List, Optional, Sequence

from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point, Vector3
from mv3dpose_msgs.msg import (Joint3D, Keypoint2D, Person2D, Person2DArray, SkeletonInfo,
                               TrackedSkeleton, TrackedSkeletonArray)
from mv3dpose_ros.core.types import JointState, Track, TrackState
import numpy as np
from sensor_msgs.msg import RegionOfInterest
from std_msgs.msg import Header


class InvalidMessage(ValueError):
    """A message that cannot be used; the text says what and why."""


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

def person2d_array_to_numpy(msg: Person2DArray,
                            num_joints: Optional[int] = None) -> np.ndarray:
    """
    Return the people of ``msg`` as a ``[P, J, 3]`` float64 array (x px, y px, confidence).

    Raises ``InvalidMessage`` for a keypoint count that differs between people or from
    ``num_joints``, for NaN/inf values, and for confidences outside [0, 1]. Keypoints with
    confidence 0 keep confidence 0 (their x, y are meaningless and zeroed).
    """
    persons = msg.persons
    if not persons:
        return np.zeros((0, num_joints or 0, 3))
    counts = {len(p.keypoints) for p in persons}
    if len(counts) != 1:
        raise InvalidMessage(f'people have different keypoint counts {sorted(counts)}')
    count = counts.pop()
    if num_joints is not None and count != num_joints:
        raise InvalidMessage(
            f'{count} keypoints per person, layout {msg.layout!r} has {num_joints}')
    flat = [v for p in persons for k in p.keypoints for v in (k.x, k.y, k.confidence)]
    poses = np.asarray(flat, dtype=np.float64).reshape(len(persons), count, 3)
    if not np.all(np.isfinite(poses)):
        raise InvalidMessage('NaN or inf in keypoints')
    conf = poses[..., 2]
    if np.any(conf < 0.0) or np.any(conf > 1.0):
        raise InvalidMessage(
            f'keypoint confidence outside [0, 1] (min {conf.min():.3g}, max {conf.max():.3g})')
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
