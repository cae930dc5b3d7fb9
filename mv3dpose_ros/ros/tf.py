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
TF for fusion_node where ``tf2_ros`` exists (a full ROS install); a no-op where it does not.

The ``tf2_ros`` module is used exactly as a node on a full install uses it:
``StaticTransformBroadcaster(node).sendTransform([...])`` for the cameras (once at start),
``TransformBroadcaster(node).sendTransform([...])`` for the people, and ``Buffer`` +
``TransformListener(buffer, node, spin_thread=False)`` + ``Buffer.lookup_transform`` for
``extrinsics_source: tf``. The lookup runs on a helper node spun by its own executor, so the
fusion node is never in two executors. The PyPI wheels have no tf2, so there the bridge says
once that TF is off and everything else runs unchanged; tests pass a fake module with the same
four classes.

Parameters (declared here, read once at start):

- ``extrinsics_source``: ``rig`` (camera poses from ``rig_config``) or ``tf`` (looked up as
  ``world_frame`` -> ``tf.camera_frame`` at start, e.g. from a URDF via robot_state_publisher;
  intrinsics still come from the rig or CameraInfo);
- ``tf.publish_cameras``: broadcast the rig's camera poses as static transforms;
- ``tf.publish_tracks``: broadcast one frame per confirmed track, ``<tf.track_frame_prefix><id>``;
- ``tf.camera_frame``, ``tf.track_frame_prefix``, ``tf.lookup_timeout_s``.
"""

import time
from typing import Any, Dict, List, Mapping, Optional, Sequence

from mv3dpose_ros.core.geometry.camera import CalibrationError, Camera
from mv3dpose_ros.core.types import Track
from mv3dpose_ros.ros import params as P
from mv3dpose_ros.ros.frames import (camera_from_transform, camera_transforms, OPTICAL_FRAME,
                                     optical_frame, track_transforms)
from std_msgs.msg import Header

EXTRINSICS_SOURCES = ('rig', 'tf')
_AUTO = object()


class TfError(ValueError):
    """A TF setting or lookup that prevents the node from starting (the text says why)."""


def import_tf2() -> Optional[Any]:
    """Return the ``tf2_ros`` module, or None where it is not installed (PyPI wheels)."""
    try:
        import tf2_ros
    except ImportError:
        return None
    return tf2_ros


def declare_parameters(node: Any) -> None:
    """Declare the TF parameters on ``node`` (all read-only)."""
    d = P.declare
    d(node, 'extrinsics_source', 'rig', 'rig: camera poses from rig_config; tf: looked up '
      'as world_frame -> tf.camera_frame at start (needs tf2_ros)', read_only=True)
    d(node, 'tf.publish_cameras', True, 'Broadcast each camera pose of the rig as a static '
      'transform world_frame -> tf.camera_frame (where tf2_ros exists)', read_only=True)
    d(node, 'tf.publish_tracks', False, 'Broadcast one frame per confirmed track at its root '
      'joint, heading from the hips (where tf2_ros exists)', read_only=True)
    d(node, 'tf.camera_frame', OPTICAL_FRAME, 'Frame id of a camera; {camera} is replaced by '
      'the camera id', read_only=True)
    d(node, 'tf.track_frame_prefix', 'body_', 'Track frames are <prefix><track_id> (REP-155 '
      'body_<id>)', read_only=True)
    d(node, 'tf.lookup_timeout_s', 5.0, 'Time [s] to wait for the camera transforms with '
      'extrinsics_source tf', read_only=True)


class TfBridge:
    """The optional TF side of fusion_node: static camera poses, track frames, extrinsics."""

    def __init__(self, node: Any, world_frame: str, tf2: Any = _AUTO) -> None:
        declare_parameters(node)

        def v(name: str) -> Any:
            return P.value(node, name)

        self.node = node
        self.world_frame = world_frame
        self.extrinsics_source = v('extrinsics_source')
        self.publish_cameras = bool(v('tf.publish_cameras'))
        self.publish_tracks_enabled = bool(v('tf.publish_tracks'))
        self.camera_frame = v('tf.camera_frame')
        self.track_prefix = v('tf.track_frame_prefix')
        self.lookup_timeout_s = float(v('tf.lookup_timeout_s'))
        if self.extrinsics_source not in EXTRINSICS_SOURCES:
            raise TfError(f'extrinsics_source {self.extrinsics_source!r} is not one of '
                          f'{", ".join(EXTRINSICS_SOURCES)}')
        if '{camera}' not in self.camera_frame:
            raise TfError(f'tf.camera_frame {self.camera_frame!r} must contain {{camera}}')
        self.tf2 = import_tf2() if tf2 is _AUTO else tf2
        self.static_broadcaster = None
        self.broadcaster = None
        self.sent_static: List[Any] = []
        if self.tf2 is None:
            if self.extrinsics_source == 'tf':
                raise TfError('extrinsics_source is tf, but tf2_ros is not importable (not in '
                              'the PyPI wheels; use a full ROS install, or extrinsics_source: '
                              'rig)')
            node.get_logger().info('TF is off: tf2_ros is not importable here; camera poses '
                                   'come from rig_config and no transforms are broadcast')
            return
        if self.publish_cameras and self.extrinsics_source == 'rig':
            self.static_broadcaster = self.tf2.StaticTransformBroadcaster(node)
        if self.publish_tracks_enabled:
            self.broadcaster = self.tf2.TransformBroadcaster(node)

    @property
    def enabled(self) -> bool:
        """Tell whether tf2_ros is in use."""
        return self.tf2 is not None

    def start(self, rig: Mapping[str, Camera], camera_ids: Sequence[str],
              stamp: Any) -> Dict[str, Camera]:
        """
        Return the rig to fuse with; publish the camera poses, or look them up in TF.

        ``stamp`` is a ``builtin_interfaces/Time`` for the static transforms.
        """
        rig = dict(rig)
        if self.tf2 is None:
            return rig
        if self.extrinsics_source == 'tf':
            rig.update(self._lookup_cameras({c: rig[c] for c in camera_ids}))
            self.node.get_logger().info(
                f'extrinsics of {len(camera_ids)} cameras from TF ({self.world_frame} -> '
                f'{optical_frame("<camera>", self.camera_frame)})')
        elif self.static_broadcaster is not None:
            header = Header(stamp=stamp, frame_id=self.world_frame)
            self.sent_static = camera_transforms({c: rig[c] for c in camera_ids}, header,
                                                 self.camera_frame)
            self.static_broadcaster.sendTransform(self.sent_static)
            self.node.get_logger().info(
                f'static TF: {self.world_frame} -> '
                f'{", ".join(t.child_frame_id for t in self.sent_static)}')
        return rig

    def republish_cameras(self, rig: Mapping[str, Camera], camera_ids: Sequence[str],
                          stamp: Any) -> None:
        """Broadcast the camera poses again (a corrected rig); nothing with extrinsics from TF."""
        if self.static_broadcaster is None or self.extrinsics_source == 'tf':
            return
        header = Header(stamp=stamp, frame_id=self.world_frame)
        self.sent_static = camera_transforms({c: rig[c] for c in camera_ids}, header,
                                             self.camera_frame)
        self.static_broadcaster.sendTransform(self.sent_static)

    def publish_tracks(self, tracks: Sequence[Track], yaws: Sequence[Optional[float]],
                       header: Header) -> int:
        """Broadcast the frames of the confirmed tracks; return how many were sent."""
        if self.broadcaster is None:
            return 0
        transforms = track_transforms(tracks, yaws, header, self.track_prefix)
        if transforms:
            self.broadcaster.sendTransform(transforms)
        return len(transforms)

    def _lookup_cameras(self, cameras: Mapping[str, Camera]) -> Dict[str, Camera]:
        """Look up ``world_frame`` -> camera frame for every camera (TfError on failure)."""
        import rclpy
        from rclpy.duration import Duration
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.time import Time
        tf2 = self.tf2
        helper = rclpy.create_node(f'{self.node.get_name()}_tf_lookup',
                                   namespace=self.node.get_namespace(),
                                   context=self.node.context)
        executor = SingleThreadedExecutor(context=self.node.context)
        executor.add_node(helper)
        buffer = tf2.Buffer()
        listener = tf2.TransformListener(buffer, helper, spin_thread=False)
        frames = {c: optical_frame(c, self.camera_frame) for c in cameras}
        try:
            deadline = time.monotonic() + self.lookup_timeout_s
            while True:
                missing = [c for c, f in frames.items()
                           if not buffer.can_transform(self.world_frame, f, Time())]
                if not missing or time.monotonic() >= deadline:
                    break
                executor.spin_once(timeout_sec=0.05)
            if missing:
                raise TfError(
                    f'extrinsics_source tf: no transform {self.world_frame} -> '
                    f'{", ".join(frames[c] for c in missing)} within {self.lookup_timeout_s} s '
                    f'(publish the camera frames, e.g. robot_state_publisher with the rig '
                    f'URDF, or use extrinsics_source: rig)')
            out = {}
            for cam, frame in frames.items():
                try:
                    tf = buffer.lookup_transform(self.world_frame, frame, Time(),
                                                 timeout=Duration(seconds=0.0))
                    out[cam] = camera_from_transform(cameras[cam], tf)
                except CalibrationError as exc:
                    raise TfError(f'extrinsics_source tf: {exc}') from exc
                except tf2.TransformException as exc:
                    raise TfError(f'extrinsics_source tf: lookup {self.world_frame} -> {frame} '
                                  f'failed: {exc}') from exc
            return out
        finally:
            if hasattr(listener, 'unregister'):
                listener.unregister()
            executor.shutdown()
            helper.destroy_node()
