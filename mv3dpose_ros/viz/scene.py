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
The Foxglove 3D scene of the tracks and the rig, and a picture of a received scene.

Building (``foxglove.messages``, protobuf; no ROS):

- ``skeleton_update``: one ``SceneEntity`` ``person/<track_id>`` per live track, replacing the
  previous one (same id, same topic): a LINE_LIST of the bones whose two joints are valid
  (``indices`` into the joint points), one sphere per valid joint, a billboard label
  ``#<id> <state>`` above the head, coloured by track id (``viz.palette``, the RViz
  colours), COASTING tracks faded; ``lifetime`` is a safety net for a stalled source.
  A DELETED track becomes a ``SceneEntityDeletion`` of its id.
- ``camera_update``: one entity ``camera/<name>`` per camera, its frustum (centre to the four
  image corners at ``depth_m``) and its name; lifetime 0 (kept until replaced).

Reading back (``render_scene``): draws what a client received, a list of decoded
``SceneUpdate`` dictionaries (protobuf field names, as ``json_format.MessageToDict`` gives),
as a top view and a side view, using only the received primitives.
"""

from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple

import cv2
from foxglove.messages import (Color, Duration, KeyValuePair, LinePrimitive, LinePrimitiveLineType,
                               Point3, Pose, Quaternion, SceneEntity, SceneEntityDeletion,
                               SceneEntityDeletionType, SceneUpdate, SpherePrimitive,
                               TextPrimitive, Timestamp, Vector3)
from mv3dpose_ros.core.geometry.camera import Camera
from mv3dpose_ros.core.types import NS_PER_S, Track, TrackState
from mv3dpose_ros.viz.palette import track_rgb
from mv3dpose_ros.viz.panels import valid_joints, View
import numpy as np

_IDENTITY = Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)


def _timestamp(ns: int) -> Timestamp:
    return Timestamp(sec=int(ns // NS_PER_S), nsec=int(ns % NS_PER_S))


def _duration(seconds: float) -> Duration:
    ns = int(round(max(0.0, seconds) * NS_PER_S))
    return Duration(sec=ns // NS_PER_S, nsec=ns % NS_PER_S)


def _pose(xyz: Sequence[float]) -> Pose:
    return Pose(position=Vector3(x=float(xyz[0]), y=float(xyz[1]), z=float(xyz[2])),
                orientation=_IDENTITY)


def _color(rgb: Sequence[float], alpha: float = 1.0) -> Color:
    return Color(r=float(rgb[0]), g=float(rgb[1]), b=float(rgb[2]), a=float(alpha))


def skeleton_entity(track: Track, bones: Sequence[Tuple[int, int]], frame_id: str,
                    stamp_ns: int, lifetime_s: float = 0.5, line_width_m: float = 0.03,
                    joint_diameter_m: float = 0.06) -> Optional[SceneEntity]:
    """Return the entity ``person/<id>`` of a live track (None when no joint is valid)."""
    ok = valid_joints(track)
    if not ok.any():
        return None
    xyz = np.asarray(track.joints, dtype=np.float64)
    index = -np.ones(len(ok), np.int64)
    index[ok] = np.arange(int(ok.sum()))
    points = [Point3(x=x, y=y, z=z) for x, y, z in xyz[ok].tolist()]
    pairs = np.asarray(bones, dtype=np.int64).reshape(-1, 2)
    pairs = pairs[ok[pairs[:, 0]] & ok[pairs[:, 1]]]
    alpha = 0.35 if track.state == TrackState.COASTING else 1.0
    color = _color(track_rgb(track.track_id), alpha)
    state = TrackState(track.state).name.lower()
    head = xyz[ok][np.argmax(xyz[ok][:, 2])]
    size = Vector3(x=joint_diameter_m, y=joint_diameter_m, z=joint_diameter_m)
    return SceneEntity(
        timestamp=_timestamp(stamp_ns), frame_id=frame_id, id=f'person/{track.track_id}',
        lifetime=_duration(lifetime_s), frame_locked=False,
        metadata=[KeyValuePair(key='track_id', value=str(track.track_id)),
                  KeyValuePair(key='state', value=state)],
        lines=[LinePrimitive(type=LinePrimitiveLineType.LineList, pose=_pose((0, 0, 0)),
                             thickness=line_width_m, scale_invariant=False, points=points,
                             color=color, indices=index[pairs.reshape(-1)].tolist())],
        spheres=[SpherePrimitive(pose=_pose(p), size=size, color=color)
                 for p in xyz[ok].tolist()],
        texts=[TextPrimitive(pose=_pose(head + [0.0, 0.0, 0.25]), billboard=True,
                             font_size=0.15, scale_invariant=False, color=color,
                             text=f'#{track.track_id} {state}')])


def skeleton_update(tracks: Sequence[Track], bones: Sequence[Tuple[int, int]], frame_id: str,
                    stamp_ns: int, lifetime_s: float = 0.5) -> SceneUpdate:
    """Return the scene update of one ``~/tracks`` message (DELETED tracks are deletions)."""
    entities, deletions = [], []
    for t in tracks:
        if t.state == TrackState.DELETED:
            deletions.append(SceneEntityDeletion(timestamp=_timestamp(stamp_ns),
                                                 type=SceneEntityDeletionType.MatchingId,
                                                 id=f'person/{t.track_id}'))
            continue
        entity = skeleton_entity(t, bones, frame_id, stamp_ns, lifetime_s)
        if entity is not None:
            entities.append(entity)
    return SceneUpdate(deletions=deletions, entities=entities)


def frustum_points(camera: Camera, depth_m: float) -> np.ndarray:
    """Return ``[5, 3]``: the camera centre and its image corners at ``depth_m`` (world)."""
    w, h = camera.width, camera.height
    uv1 = np.array([[0, 0, 1], [w, 0, 1], [w, h, 1], [0, h, 1]], dtype=np.float64)
    rays = uv1 @ np.linalg.inv(camera.K).T            # optical frame, z = 1
    corners = (rays * depth_m) @ camera.R_world_cam.T + camera.center
    return np.vstack([camera.center, corners])


def camera_update(cameras: Mapping[str, Camera], frame_id: str, stamp_ns: int,
                  depth_m: float = 0.5) -> SceneUpdate:
    """Return one frustum entity ``camera/<name>`` per camera (kept until replaced)."""
    entities = []
    grey = _color((0.55, 0.55, 0.6))
    for name, cam in cameras.items():
        pts = frustum_points(cam, depth_m)
        entities.append(SceneEntity(
            timestamp=_timestamp(stamp_ns), frame_id=frame_id, id=f'camera/{name}',
            lifetime=_duration(0.0), frame_locked=False,
            metadata=[KeyValuePair(key='camera', value=name)],
            lines=[LinePrimitive(type=LinePrimitiveLineType.LineList, pose=_pose((0, 0, 0)),
                                 thickness=2.0, scale_invariant=True,
                                 points=[Point3(x=x, y=y, z=z) for x, y, z in pts.tolist()],
                                 color=grey,
                                 indices=[0, 1, 0, 2, 0, 3, 0, 4, 1, 2, 2, 3, 3, 4, 4, 1])],
            texts=[TextPrimitive(pose=_pose(pts[0] + [0.0, 0.0, 0.15]), billboard=True,
                                 font_size=0.12, scale_invariant=False, color=grey,
                                 text=name)]))
    return SceneUpdate(entities=entities)


# ------------------------------------------------------------------------------ picture
def _xyz(d: Mapping[str, Any]) -> np.ndarray:
    return np.array([float(d.get(k, 0.0)) for k in 'xyz'])


def _bgr(color: Mapping[str, Any]) -> Tuple[int, int, int]:
    a = float(color.get('a', 0.0))
    rgb = [float(color.get(k, 0.0)) * a + (1 - a) for k in 'rgb']   # over white
    return tuple(int(round(255 * c)) for c in reversed(rgb))


def _segments(line: Mapping[str, Any]) -> List[Tuple[np.ndarray, np.ndarray]]:
    pts = [_xyz(p) for p in line.get('points', [])]
    idx = [int(i) for i in line.get('indices', [])] or list(range(len(pts)))
    kind = line.get('type', 'LINE_STRIP')
    if kind in ('LINE_LIST', 2):
        pairs = list(zip(idx[0::2], idx[1::2]))
    else:
        pairs = list(zip(idx[:-1], idx[1:]))
        if kind in ('LINE_LOOP', 1) and len(idx) > 2:
            pairs.append((idx[-1], idx[0]))
    origin = _xyz(line.get('pose', {}).get('position', {}))
    return [(pts[a] + origin, pts[b] + origin) for a, b in pairs]


def latest_entities(updates: Sequence[Mapping[str, Any]]) -> Dict[str, Mapping[str, Any]]:
    """Apply received updates in order: return the entities alive at the end, by id."""
    alive: Dict[str, Mapping[str, Any]] = {}
    for u in updates:
        for d in u.get('deletions', []):
            if d.get('type', 'MATCHING_ID') in ('ALL', 1):
                alive.clear()
            else:
                alive.pop(d.get('id', ''), None)
        for e in u.get('entities', []):
            alive[e.get('id', '')] = e
    return alive


def render_scene(entities: Mapping[str, Mapping[str, Any]], title: str = '',
                 panel: int = 640) -> np.ndarray:
    """Return a BGR picture (top view, side view) of received scene entities."""
    segs, spheres, texts = [], [], []
    for e in entities.values():
        for line in e.get('lines', []):
            colour = _bgr(line.get('color', {}))
            segs += [(a, b, colour) for a, b in _segments(line)]
        for s in e.get('spheres', []):
            spheres.append((_xyz(s.get('pose', {}).get('position', {})),
                            _bgr(s.get('color', {}))))
        for t in e.get('texts', []):
            texts.append((_xyz(t.get('pose', {}).get('position', {})), t.get('text', ''),
                          _bgr(t.get('color', {}))))
    pts = [p for a, b, _ in segs for p in (a, b)] + [p for p, _ in spheres]
    pts = np.array(pts) if pts else np.array([[-1.0, -1.0, 0.0], [1.0, 1.0, 2.0]])
    lo, hi = pts.min(axis=0) - 0.3, pts.max(axis=0) + 0.3
    top = View('top view (from the received scene)', (0, 1), lo[:2], hi[:2], (panel, panel),
               ('x', 'y'))
    side = View('side view (looking along +y)', (0, 2), np.array([lo[0], min(lo[2], 0.0)]),
                np.array([hi[0], hi[2]]), (panel, panel // 2), ('x', 'z'))
    images = []
    for view in (top, side):
        img = view.blank()
        for a, b, colour in segs:
            p, q = np.round(view.px(np.array([a, b]))).astype(int)
            cv2.line(img, tuple(map(int, p)), tuple(map(int, q)), colour, 2, cv2.LINE_AA)
        for p, colour in spheres:
            c = np.round(view.px(p)).astype(int)
            cv2.circle(img, tuple(map(int, c)), 3, colour, -1, cv2.LINE_AA)
        for p, text, colour in texts:
            c = np.round(view.px(p)).astype(int)
            cv2.putText(img, text, (int(c[0]) + 4, int(c[1]) - 4), cv2.FONT_HERSHEY_SIMPLEX,
                        0.42, colour, 1, cv2.LINE_AA)
        images.append(img)
    bar = np.full((36, panel, 3), 255, np.uint8)
    cv2.putText(bar, title or f'{len(entities)} scene entities', (8, 24),
                cv2.FONT_HERSHEY_SIMPLEX, 0.55, (30, 30, 30), 1, cv2.LINE_AA)
    return np.vstack([bar, images[0], images[1]])
