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
``Joint3D.MISSING``, ``velocity_valid``, ``position_source == POSITION_NONE``), so no published
field ever carries NaN or inf.
"""

from dataclasses import dataclass
import math
import struct
from typing import Any, Iterable, List, NamedTuple, Optional, Sequence, Tuple, Union

from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point, Vector3
from mv3dpose_msgs.msg import (Joint3D, Keypoint2D, Person2D, Person2DArray, SkeletonInfo,
                               TrackedSkeleton, TrackedSkeletonArray)
from mv3dpose_ros.core.types import JointState, PositionSource, Track, TrackState
from mv3dpose_ros.ros.cdr import ANY_CDR, CdrError, CdrReader, CdrWriter, U32
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


def _malformed(text: str) -> InvalidMessage:
    return InvalidMessage(f'malformed Person2DArray CDR: {text}', 'malformed')


def decode_person2d_array(data: Union[bytes, bytearray, memoryview]) -> Persons2D:
    """
    Decode serialised ``Person2DArray`` bytes (what a ``raw=True`` subscription receives).

    About ten times faster than ``rclpy.serialization.deserialize_message`` followed by
    ``person2d_array_to_numpy``, whose cost is one Python object per keypoint, and the only
    input decoder of the fusion node: it accepts exactly the bytes rclpy (rmw_fastrtps and the
    generated C type support) accepts and decodes them to the same values, quirks included,
    which ``test_messages_cdr`` checks on a corpus of mutated buffers. Accepted like rclpy:
    any encapsulation kind rmw_fastrtps reads (big and little endian), trailing bytes, strings
    without a terminating NUL (cut at the first NUL, invalid UTF-8 replaced), any non-zero
    bool, and a keypoint sequence whose length exceeds the bytes left, which the type
    support reads as empty before going on with the next person. Everything else rclpy refuses
    (truncation, a persons count beyond the bytes left, a string running past the end) raises
    ``InvalidMessage`` with reason 'malformed'.
    """
    try:
        r = CdrReader(data, ANY_CDR)
        sec, nanosec, frame_id = r.header()
        camera_id = r.string()
        width, height = r.unpack('II')
        layout = r.string()
        num = r.u32()
        if num > r.remaining:
            raise _malformed(f'{num} persons cannot fit in the remaining {r.remaining} bytes')
        counts, starts, rois, scores, ids = [], [], [], [], []
        for _ in range(num):
            x0, y0, h, w, rect, score = r.unpack('IIIIB3xf')      # roi, score
            rois.append((x0, y0, h, w, 1 if rect else 0))
            scores.append(score)
            ids.append(r.string())
            k = r.u32()
            left = r.size - r.pos
            if k > left:
                k = 0      # the type support's 'sequence size exceeds remaining buffer'
            elif 12 * k > left:
                raise _malformed(f'{k} keypoints at offset {r.pos} cannot fit in the remaining '
                                 f'{r.remaining} bytes')
            counts.append(k)
            starts.append(r.pos // 4)
            r.pos += 12 * k
    except CdrError as exc:
        raise _malformed(str(exc)) from None
    if num:
        words = np.frombuffer(r.buf, dtype=r.order + 'f4', count=r.size // 4)
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


def _split_stamp(sec: float, ns: Optional[int] = None) -> Tuple[int, int]:
    """Return the stamp as ``(sec, nanosec)``: ``ns`` exactly when given, else ``sec`` rounded."""
    if ns is not None:                    # a Time holds int32 seconds: else unknown (0)
        return divmod(int(ns), 1_000_000_000) if 0 <= ns < _NS_LIMIT else (0, 0)
    if not math.isfinite(sec):
        return 0, 0
    return divmod(round(sec * 1e9), 1_000_000_000)


F32_MAX = float(np.finfo(np.float32).max)
_NS_LIMIT = 2**31 * 1_000_000_000


class _TrackFields(NamedTuple):
    """The values one ``TrackedSkeleton`` carries: NaN already turned into validity."""

    track_id: int
    state: int
    confidence: float
    first_seen: Tuple[int, int]
    last_observed: Tuple[int, int]
    age: int
    missed: int
    position: List[float]                    # zeros when not finite (then source NONE)
    velocity: List[float]                    # zeros unless velocity_valid
    velocity_valid: bool
    covariance: Tuple[float, ...]            # 9 values; _COVARIANCE_UNKNOWN when not finite
    position_source: int                     # PositionSource; NONE when position is not finite
    source_cameras: Tuple[str, ...]


class _JointFields(NamedTuple):
    """Per-joint values of tracks with equal joint counts, ``[T, J]``; MISSING made explicit."""

    xyz: np.ndarray             # [T, J, 3] float64, zeros where MISSING
    confidence: np.ndarray      # [T, J] float64 in [0, 1], 0 where MISSING
    state: np.ndarray           # [T, J] uint8, MISSING where unusable
    num_views: np.ndarray       # [T, J] uint8, 0 where MISSING
    error: np.ndarray           # [T, J] float64 px, -1 where not applicable
    variance: np.ndarray        # [T, J] float64 m^2 per axis, -1 where unknown


def _track_fields(track: Track) -> _TrackFields:
    """Return the per-track values ``track`` publishes."""
    root = np.asarray(track.position, dtype=np.float64).tolist()
    source = int(track.position_source) if track.position_source in _SOURCES else _NONE
    root_ok = source != _NONE and all(map(math.isfinite, root))
    if not root_ok:                  # an unknown root is said so, never a silent origin
        source = _NONE
    vel = np.asarray(track.velocity, dtype=np.float64).tolist()
    vel_ok = all(map(math.isfinite, vel))
    cov = _COVARIANCE_UNKNOWN
    if track.position_covariance is not None and root_ok:
        c = np.asarray(track.position_covariance, dtype=np.float64).reshape(-1)
        if c.size == 9 and (np.abs(c) <= F32_MAX).all() and c[0] >= 0:
            cov = tuple(c.tolist())
    return _TrackFields(
        track_id=int(track.track_id), state=int(track.state),
        confidence=min(max(_finite(track.score), 0.0), 1.0),
        first_seen=_split_stamp(track.first_seen, track.first_seen_ns),
        last_observed=_split_stamp(track.last_observed, track.last_observed_ns),
        age=int(track.age),
        missed=int(track.missed),
        position=root if root_ok else [0.0, 0.0, 0.0],
        velocity=vel if vel_ok else [0.0, 0.0, 0.0], velocity_valid=vel_ok, covariance=cov,
        position_source=source, source_cameras=tuple(track.source_cameras))


def _joint_fields(tracks: Sequence[Track]) -> _JointFields:
    """Return the per-joint values of ``tracks`` (equal joint counts), vectorised over all."""
    num = len(tracks)
    states = np.array([t.joint_state for t in tracks], dtype=np.uint8).reshape(num, -1)
    xyz = np.array([t.joints for t in tracks], dtype=np.float64).reshape(num, -1, 3)
    conf = np.array([t.confidence for t in tracks], dtype=np.float64).reshape(num, -1)
    err = np.array([t.reprojection_error for t in tracks], dtype=np.float64).reshape(num, -1)
    views = np.array([t.num_views for t in tracks]).reshape(num, -1)
    var = np.array([t.joint_variance if t.joint_variance is not None
                    else np.full(len(t.joint_state), np.nan) for t in tracks],
                   dtype=np.float64).reshape(num, -1)
    var[~((var >= 0) & (var <= F32_MAX))] = -1.0     # NaN, negative, inf, beyond float32
    usable = (states != JointState.MISSING) & np.isfinite(xyz).all(axis=-1)
    conf = np.clip(conf, 0.0, 1.0)            # NaN stays NaN, +-inf -> 1 / 0
    err[~(np.abs(err) <= F32_MAX)] = -1.0        # NaN, inf and what float32 cannot hold
    return _JointFields(
        xyz=np.where(usable[..., None], xyz, 0.0),
        confidence=np.where(usable & ~np.isnan(conf), conf, 0.0),
        state=np.where(usable, states, np.uint8(JointState.MISSING)).astype(np.uint8),
        num_views=np.where(usable, views.astype(np.int64).clip(0, 255), 0).astype(np.uint8),
        error=np.where(usable, err, -1.0), variance=np.where(usable, var, -1.0))


def _all_joint_fields(tracks: Sequence[Track]) -> List[_JointFields]:
    """Return ``_joint_fields`` per track: one vectorised pass when joint counts agree."""
    counts = {len(t.joint_state) for t in tracks}
    if len(counts) == 1:
        f = _joint_fields(tracks)
        return [_JointFields(*(a[i] for a in f)) for i in range(len(tracks))]
    return [_JointFields(*(a[0] for a in _joint_fields([t]))) for t in tracks]


def _skeleton_msg(f: _TrackFields, j: _JointFields) -> TrackedSkeleton:
    msg = TrackedSkeleton(track_id=f.track_id, state=f.state, confidence=f.confidence,
                          first_seen=Time(sec=f.first_seen[0], nanosec=f.first_seen[1]),
                          last_observed=Time(sec=f.last_observed[0],
                                             nanosec=f.last_observed[1]),
                          age=f.age, missed=f.missed, velocity_valid=f.velocity_valid,
                          source_cameras=list(f.source_cameras))
    x, y, z = f.position
    msg.position = Point(x=x, y=y, z=z)
    x, y, z = f.velocity
    msg.velocity = Vector3(x=x, y=y, z=z)
    msg.position_covariance = f.covariance
    msg.position_source = f.position_source
    msg.joints = [Joint3D(position=Point(x=x, y=y, z=z), confidence=c, state=s, num_views=v,
                          reprojection_error=e, position_variance=pv)
                  for (x, y, z), c, s, v, e, pv in zip(
                      j.xyz.tolist(), j.confidence.tolist(), j.state.tolist(),
                      j.num_views.tolist(), j.error.tolist(), j.variance.tolist())]
    return msg


def tracks_to_msg(tracks: Iterable[Track], header: Header, layout: str) -> TrackedSkeletonArray:
    """Build the ``TrackedSkeletonArray`` of one synchronised set."""
    tracks = list(tracks)
    return TrackedSkeletonArray(
        header=header, layout=layout,
        skeletons=[_skeleton_msg(_track_fields(t), j)
                   for t, j in zip(tracks, _all_joint_fields(tracks))])


_COVARIANCE_UNKNOWN = (-1.0,) + (0.0,) * 8
_SOURCES = frozenset(int(s) for s in PositionSource)
_NONE = int(PositionSource.NONE)
# TrackedSkeleton up to its joint count, from an 8-aligned start (little-endian CDR):
# track_id, state, confidence, first_seen, last_observed, age, missed, position, velocity,
# velocity_valid, position_covariance, position_source, len(joints).
_SKELETON_HEAD = struct.Struct('<QB3xfiIiIII3d3d?7x9dB3xI')
# One Joint3D from an 8-aligned start: 40 bytes, no padding (the next one starts right after).
_JOINT3D = np.dtype({'names': ['position', 'confidence', 'state', 'num_views',
                               'reprojection_error', 'position_variance'],
                     'formats': [('<f8', (3,)), '<f4', 'u1', 'u1', '<f4', '<f4'],
                     'offsets': [0, 24, 28, 29, 32, 36], 'itemsize': 40})


def tracks_to_cdr(tracks: Iterable[Track], header: Header, layout: str) -> bytes:
    """
    Serialise the ``TrackedSkeletonArray`` of ``tracks_to_msg`` directly to CDR bytes.

    Same values (``_track_fields`` / ``_joint_fields``), about 8x faster (0.1 ms instead of
    0.8 ms for 6 people x 17 joints).
    """
    w = CdrWriter()
    w.header(header, layout)
    tracks = list(tracks)
    w.pack(U32, len(tracks))
    for track, j in zip(tracks, _all_joint_fields(tracks)):
        f = _track_fields(track)
        num = len(j.state)
        w.pack(_SKELETON_HEAD, f.track_id, f.state, f.confidence, *f.first_seen,
               *f.last_observed, f.age, f.missed, *f.position, *f.velocity, f.velocity_valid,
               *f.covariance, f.position_source, num, align=8)
        joints = np.zeros(num, _JOINT3D)
        joints['position'] = j.xyz
        joints['confidence'] = j.confidence
        joints['state'] = j.state
        joints['num_views'] = j.num_views
        joints['reprojection_error'] = j.error
        joints['position_variance'] = j.variance
        if num:                       # the joint count is the head's last field
            w.raw(memoryview(joints).cast('B'), align=8)
        w.strings(f.source_cameras)
    return w.getvalue()


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
        var = np.array([j.position_variance for j in s.joints], dtype=np.float64)
        var[var < 0] = np.nan
        cov = np.array(s.position_covariance, dtype=np.float64).reshape(3, 3)
        if cov[0, 0] < 0:
            cov[:] = np.nan
        velocity = (np.array([s.velocity.x, s.velocity.y, s.velocity.z]) if s.velocity_valid
                    else np.full(3, np.nan))
        source = (PositionSource(s.position_source) if s.position_source in _SOURCES
                  else PositionSource.NONE)
        position = (np.full(3, np.nan) if source == PositionSource.NONE
                    else np.array([s.position.x, s.position.y, s.position.z], dtype=np.float64))
        tracks.append(Track(
            track_id=int(s.track_id), state=TrackState(s.state), joints=joints,
            confidence=np.array([j.confidence for j in s.joints], dtype=np.float64),
            joint_state=states, num_views=np.array([j.num_views for j in s.joints], np.uint8),
            reprojection_error=err,
            position=position,
            velocity=velocity, first_seen=stamp_to_sec(s.first_seen),
            last_observed=stamp_to_sec(s.last_observed), age=int(s.age), missed=int(s.missed),
            score=float(s.confidence), source_cameras=tuple(s.source_cameras),
            joint_variance=var, position_covariance=cov,
            first_seen_ns=stamp_to_ns(s.first_seen),
            last_observed_ns=stamp_to_ns(s.last_observed), position_source=source))
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
