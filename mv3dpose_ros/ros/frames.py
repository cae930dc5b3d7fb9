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
Coordinate frames of the rig and of the tracked people, as ``geometry_msgs``.

- Cameras: ``world_frame`` -> ``<camera>_optical_frame`` (REP-103 optical frame: x right,
  y down, z forward; ``<camera>`` is the camera's ROS name, ``ros/names.py``: ``00_03`` ->
  ``cam00_03``), translation = camera centre, rotation = camera -> world. The rig YAML's
  ``T_world_cam`` is exactly this transform, so a static TF of it and the rig agree.
- People: ``world_frame`` -> ``<prefix><track_id>`` at the track's ``position`` (the hip
  midpoint, or the body centre when a hip is unknown: ``Track.position_source``, as
  ``TrackedSkeleton.position_source``) with the REP-155 body convention: x forward, y left,
  z up (the world's). A track without a position (source NONE or not finite) gets no frame,
  never one at the origin. The heading is the yaw of the
  left-minus-right hip vector turned by -90 degrees; when the hips are missing or too close
  (< 5 cm apart horizontally) it falls back to the direction of motion (> 0.3 m/s), then to the
  last heading seen for that track, then to the world's x axis.
- ``root_poses`` / ``pose_array_cdr``: the standard ``geometry_msgs/PoseArray`` output, one
  pose per skeleton of ``~/tracks`` that has a root (DELETED tombstones and position source
  NONE left out, so not index-aligned), in the same order and header, serialised straight to
  CDR like ``~/tracks`` (``root_pose_array`` builds the same as a message object).

No rclpy here: only message classes, so the functions are testable without a node or DDS.
"""

import math
from typing import Dict, Iterable, List, Mapping, Optional, Sequence, Tuple

from geometry_msgs.msg import Pose, PoseArray, Quaternion, TransformStamped
from mv3dpose_ros.core.geometry.calibration import matrix_to_quaternion, quaternion_to_matrix
from mv3dpose_ros.core.geometry.camera import CalibrationError, Camera
from mv3dpose_ros.core.skeleton import Layout
from mv3dpose_ros.core.types import JointState, PositionSource, Track, TrackState
from mv3dpose_ros.ros.cdr import CdrWriter
from mv3dpose_ros.ros.names import camera_namespace
import numpy as np
from std_msgs.msg import Header

MIN_HIP_WIDTH_M = 0.05       # horizontal hip distance below which the hips give no heading
MIN_SPEED_MPS = 0.3          # speed above which the direction of motion gives the heading
OPTICAL_FRAME = '{camera}_optical_frame'


def optical_frame(camera: str, template: str = OPTICAL_FRAME) -> str:
    """Return the frame id of ``camera``: ``{camera}`` in ``template`` is its ROS name."""
    return template.replace('{camera}', camera_namespace(camera))


def quaternion_from_yaw(yaw: float) -> Quaternion:
    """Return the rotation by ``yaw`` radians about +z as a ``geometry_msgs/Quaternion``."""
    return Quaternion(x=0.0, y=0.0, z=math.sin(0.5 * yaw), w=math.cos(0.5 * yaw))


def yaw_from_quaternion(q: Quaternion) -> float:
    """Return the yaw (rotation about +z) of a quaternion, in radians."""
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def body_yaw(track: Track, layout: Layout) -> Optional[float]:
    """Return the heading of a person (REP-155 body x axis) in radians, None when unknown."""
    left, right = layout.root_joints
    states = track.joint_state
    if states[left] != JointState.MISSING and states[right] != JointState.MISSING:
        lx, ly = float(track.joints[left][0]), float(track.joints[left][1])
        rx, ry = float(track.joints[right][0]), float(track.joints[right][1])
        if math.hypot(lx - rx, ly - ry) >= MIN_HIP_WIDTH_M:     # False for NaN
            return math.atan2(ly - ry, lx - rx) - 0.5 * math.pi   # y (left) axis -> x
    vx, vy = float(track.velocity[0]), float(track.velocity[1])
    if math.hypot(vx, vy) >= MIN_SPEED_MPS:
        return math.atan2(vy, vx)
    return None


class Headings:
    """Per-track heading with memory: a track keeps its last heading while its hips are unseen."""

    def __init__(self, layout: Layout) -> None:
        self.layout = layout
        self._last: Dict[int, float] = {}

    def update(self, tracks: Iterable[Track]) -> List[Optional[float]]:
        """
        Return one yaw (or None) per track.

        Call it with every track of each output: tracks absent from the call or DELETED are
        forgotten, so the memory holds only the live tracks.
        """
        out: List[Optional[float]] = []
        last: Dict[int, float] = {}
        for t in tracks:
            if t.state == TrackState.DELETED:
                out.append(None)
                continue
            yaw = body_yaw(t, self.layout)
            if yaw is None:
                yaw = self._last.get(t.track_id)
            if yaw is not None:
                last[t.track_id] = yaw
            out.append(yaw)
        self._last = last
        return out

    def clear(self) -> None:
        """Forget every track."""
        self._last.clear()


def _transform(header: Header, child: str, xyz: Sequence[float],
               q: Quaternion) -> TransformStamped:
    msg = TransformStamped(header=Header(stamp=header.stamp, frame_id=header.frame_id),
                           child_frame_id=child)
    tr = msg.transform.translation
    tr.x, tr.y, tr.z = (float(v) for v in xyz)
    msg.transform.rotation = q
    return msg


def camera_transforms(cameras: Mapping[str, Camera], header: Header,
                      template: str = OPTICAL_FRAME) -> List[TransformStamped]:
    """Return ``header.frame_id`` -> optical frame of each camera (pose of the camera)."""
    out = []
    for name, cam in cameras.items():
        x, y, z, w = (float(v) for v in matrix_to_quaternion(cam.R_world_cam))
        out.append(_transform(header, optical_frame(name, template), cam.center,
                              Quaternion(x=x, y=y, z=z, w=w)))
    return out


def camera_from_transform(camera: Camera, tf: TransformStamped) -> Camera:
    """Return ``camera`` (intrinsics kept) placed at the pose ``tf`` (world -> optical frame)."""
    r, p = tf.transform.rotation, tf.transform.translation
    q = np.array([r.x, r.y, r.z, r.w], dtype=np.float64)
    norm = float(np.linalg.norm(q))
    if not math.isfinite(norm) or abs(norm - 1.0) > 1e-3:
        raise CalibrationError(f'rotation of {tf.header.frame_id} -> {tf.child_frame_id} is not '
                               f'a unit quaternion (norm {norm:.6g})', camera=camera.name,
                               field='tf rotation')
    return Camera.from_pose(camera.name, camera.K, camera.dist, quaternion_to_matrix(q),
                            [p.x, p.y, p.z], camera.width, camera.height)


def _root(track: Track) -> Optional[Tuple[float, float, float]]:
    """Return the published position (hips or body centre), None when there is none."""
    if track.position_source == PositionSource.NONE:
        return None
    x, y, z = (float(v) for v in track.position)
    if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
        return None
    return x, y, z


def track_transforms(tracks: Sequence[Track], yaws: Sequence[Optional[float]], header: Header,
                     prefix: str) -> List[TransformStamped]:
    """Return ``header.frame_id`` -> ``<prefix><id>`` for each CONFIRMED/COASTING track."""
    out = []
    for t, yaw in zip(tracks, yaws):
        root = _root(t)
        if t.state not in (TrackState.CONFIRMED, TrackState.COASTING) or root is None:
            continue
        out.append(_transform(header, f'{prefix}{t.track_id}', root,
                              quaternion_from_yaw(yaw or 0.0)))
    return out


def root_poses(tracks: Sequence[Track], yaws: Sequence[Optional[float]]) -> np.ndarray:
    """
    Return the standard output's poses ``[K, 7]`` (x, y, z, qx, qy, qz, qw), float64.

    One row per non-DELETED track with a known root (hips or body centre; position source NONE
    or a non-finite position gives no row), in the order of ``tracks`` (the order of
    ``TrackedSkeletonArray.skeletons``); orientation = heading (identity when unknown).
    """
    rows = []
    for t, yaw in zip(tracks, yaws):
        root = _root(t)
        if t.state == TrackState.DELETED or root is None:
            continue
        half = 0.5 * (yaw or 0.0)
        rows.append((*root, 0.0, 0.0, math.sin(half), math.cos(half)))
    return np.array(rows, dtype='<f8').reshape(-1, 7)


def pose_array_cdr(poses: np.ndarray, header: Header) -> bytes:
    """Serialise ``geometry_msgs/PoseArray`` with ``poses`` (``root_poses`` rows) to CDR."""
    w = CdrWriter()
    w.header(header)
    w.sequence(np.ascontiguousarray(poses, dtype='<f8'), align=8)
    return w.getvalue()


def root_pose_array(tracks: Sequence[Track], yaws: Sequence[Optional[float]],
                    header: Header) -> PoseArray:
    """Return the standard output as a ``PoseArray`` message (the rows of ``root_poses``)."""
    msg = PoseArray(header=header)
    for x, y, z, qx, qy, qz, qw in root_poses(tracks, yaws).tolist():
        pose = Pose()
        pose.position.x, pose.position.y, pose.position.z = x, y, z
        o = pose.orientation
        o.x, o.y, o.z, o.w = qx, qy, qz, qw
        msg.poses.append(pose)
    return msg
