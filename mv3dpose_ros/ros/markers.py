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
RViz ``MarkerArray`` of tracked skeletons.

One array per fusion cycle, in order: a namespace-scoped ``DELETEALL`` per namespace (so the
array replaces the previous scene atomically without per-id bookkeeping), then per track a
``LINE_LIST`` of the bones whose two joints are both valid (a LINE_STRIP over the valid joints
would draw bogus bones), a ``SPHERE_LIST`` of the valid joints and a ``TEXT_VIEW_FACING`` label.
Colours are a stable function of the track id; COASTING tracks are dimmed and PREDICTED joints
half transparent. RViz rejects a whole marker with any NaN/inf, so only finite values are
emitted, and markers without points are left out. A short ``lifetime`` clears the scene if the
node stalls.
"""

import colorsys
from dataclasses import dataclass
import math
from typing import Iterable, List, Optional, Sequence, Tuple

from builtin_interfaces.msg import Duration
from geometry_msgs.msg import Point, Vector3
from mv3dpose_ros.core.types import JointState, Track, TrackState
import numpy as np
from std_msgs.msg import ColorRGBA, Header
from visualization_msgs.msg import Marker, MarkerArray

GOLDEN = 0.618033988749895


@dataclass
class MarkerOptions:
    """Marker appearance; sizes in metres, times in seconds."""

    ns: str = 'mv3dpose'             # namespaces are <ns>/bones, <ns>/joints, <ns>/labels
    lifetime_s: float = 0.5          # ~3 frame periods: a safety net for a stalled node
    line_width_m: float = 0.03
    joint_diameter_m: float = 0.06
    text_height_m: float = 0.15
    coasting_alpha: float = 0.3      # alpha of COASTING tracks (CONFIRMED: 1)
    predicted_alpha: float = 0.5     # alpha factor of PREDICTED joints
    show_labels: bool = True
    show_velocity: bool = False      # <ns>/velocity ARROW from root to root + v * 0.5 s


def track_color(track_id: int) -> Tuple[float, float, float]:
    """Return a stable, well-spread RGB colour for a track id (golden-ratio hue walk)."""
    hue = (int(track_id) * GOLDEN) % 1.0
    return colorsys.hsv_to_rgb(hue, 0.75, 0.95)


def _duration(seconds: float) -> Duration:
    seconds = max(0.0, float(seconds)) if math.isfinite(seconds) else 0.0
    sec = int(seconds)
    return Duration(sec=sec, nanosec=int(round((seconds - sec) * 1e9)) % 1_000_000_000)


def _points(xyz: np.ndarray) -> List[Point]:
    return [Point(x=x, y=y, z=z) for x, y, z in np.asarray(xyz, dtype=np.float64).tolist()]


def valid_joints(track: Track) -> np.ndarray:
    """Return the mask ``[J]`` of joints with a state other than MISSING and finite xyz."""
    xyz = np.asarray(track.joints, dtype=np.float64)
    states = np.asarray(track.joint_state)
    return (states != JointState.MISSING) & np.all(np.isfinite(xyz), axis=1)


def bone_segments(track: Track, bones: Sequence[Tuple[int, int]]) -> np.ndarray:
    """Return ``[2B', 3]`` LINE_LIST points: the bones whose two joints are both valid."""
    if len(bones) == 0:
        return np.zeros((0, 3))
    pairs = np.asarray(bones, dtype=np.int64).reshape(-1, 2)
    ok = valid_joints(track)
    keep = pairs[ok[pairs[:, 0]] & ok[pairs[:, 1]]]
    return np.asarray(track.joints, dtype=np.float64)[keep.reshape(-1)]


def _base(header: Header, ns: str, marker_id: int, mtype: int, lifetime: Duration) -> Marker:
    m = Marker(header=header, ns=ns, id=marker_id, type=mtype, action=Marker.ADD,
               lifetime=lifetime)
    m.pose.orientation.w = 1.0
    return m


def tracks_to_markers(tracks: Iterable[Track], bones: Sequence[Tuple[int, int]],
                      header: Header, options: Optional[MarkerOptions] = None) -> MarkerArray:
    """Build the MarkerArray of one cycle; DELETED tracks only disappear (via DELETEALL)."""
    opt = options or MarkerOptions()
    lifetime = _duration(opt.lifetime_s)
    namespaces = [f'{opt.ns}/bones', f'{opt.ns}/joints', f'{opt.ns}/labels',
                  f'{opt.ns}/velocity']
    out = MarkerArray()
    for ns in namespaces:
        out.markers.append(Marker(header=header, ns=ns, action=Marker.DELETEALL))
    for track in tracks:
        if track.state == TrackState.DELETED:
            continue
        mid = int(track.track_id) % 2 ** 31
        r, g, b = track_color(track.track_id)
        alpha = opt.coasting_alpha if track.state == TrackState.COASTING else 1.0
        if track.state == TrackState.TENTATIVE:
            alpha *= 0.6
        color = ColorRGBA(r=r, g=g, b=b, a=alpha)
        ok = valid_joints(track)
        xyz = np.asarray(track.joints, dtype=np.float64)

        segs = bone_segments(track, bones)
        if len(segs):
            m = _base(header, namespaces[0], mid, Marker.LINE_LIST, lifetime)
            m.scale = Vector3(x=opt.line_width_m)
            m.color = color
            m.points = _points(segs)
            out.markers.append(m)

        if ok.any():
            m = _base(header, namespaces[1], mid, Marker.SPHERE_LIST, lifetime)
            d = opt.joint_diameter_m
            m.scale = Vector3(x=d, y=d, z=d)
            m.color = color
            m.points = _points(xyz[ok])
            predicted = np.asarray(track.joint_state)[ok] == JointState.PREDICTED
            m.colors = [ColorRGBA(r=r, g=g, b=b, a=alpha * (opt.predicted_alpha if p else 1.0))
                        for p in predicted.tolist()]
            out.markers.append(m)

        anchor = _label_anchor(track, xyz, ok)
        if opt.show_labels and anchor is not None:
            m = _base(header, namespaces[2], mid, Marker.TEXT_VIEW_FACING, lifetime)
            m.pose.position = Point(x=anchor[0], y=anchor[1], z=anchor[2])
            m.scale = Vector3(z=opt.text_height_m)
            m.color = ColorRGBA(r=r, g=g, b=b, a=max(alpha, 0.5))
            m.text = f'{int(track.track_id)} {TrackState(track.state).name.lower()}'
            out.markers.append(m)

        root = np.asarray(track.position, dtype=np.float64)
        vel = np.asarray(track.velocity, dtype=np.float64)
        if opt.show_velocity and np.all(np.isfinite(root)) and np.all(np.isfinite(vel)):
            m = _base(header, namespaces[3], mid, Marker.ARROW, lifetime)
            m.points = _points(np.stack([root, root + 0.5 * vel]))
            m.scale = Vector3(x=opt.line_width_m, y=2 * opt.line_width_m, z=0.0)
            m.color = color
            out.markers.append(m)
    return out


def _label_anchor(track: Track, xyz: np.ndarray, ok: np.ndarray):
    """Return a finite label position above the head, or None."""
    if ok.any():
        pts = xyz[ok]
        top = float(pts[:, 2].max()) + 0.25
        root = np.asarray(track.position, dtype=np.float64)
        xy = root[:2] if np.all(np.isfinite(root)) else pts[:, :2].mean(axis=0)
        return float(xy[0]), float(xy[1]), top
    root = np.asarray(track.position, dtype=np.float64)
    if np.all(np.isfinite(root)):
        return float(root[0]), float(root[1]), float(root[2]) + 1.0
    return None
