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
``mv3dpose render``: pictures of 3D tracks that a person can check at a glance.

A picture shows one time point: the skeletons seen from above (with each track's path so far
and the cameras of the rig) and from the side, in stable per-track colours with their ids;
with images and a calibration, the skeletons are also reprojected onto every camera image.
``--gif`` / ``--video`` animate the whole sequence. Only OpenCV and numpy are used.
Pictures are written to a temp file and renamed into place. Exit status: 0 done, 1 error
naming the file, 3 done but malformed lines of the tracks file were left out.
"""

import argparse
import math
import os
from pathlib import Path
import sys
from typing import Dict, List, Mapping, Optional, Sequence, Tuple

import cv2
from mv3dpose_ros.core.skeleton import get_layout
from mv3dpose_ros.core.types import JointState, TrackState
from mv3dpose_ros.io.bag import bag_path_type, BagError, BagReader, deserialize
from mv3dpose_ros.io.cameras import camera_sources, load_cameras, time_points
from mv3dpose_ros.io.media import SourceError
from mv3dpose_ros.io.tracks_jsonl import frame_to_line, parse_line, read_tracks
from mv3dpose_ros.ros.bag_convert import tracks_from_bag
from mv3dpose_ros.ros.names import image_topic
from mv3dpose_ros.viz.palette import track_colour
from mv3dpose_ros.viz.panels import AXIS_TEXT, draw_label, draw_skeleton, FONT, valid_joints
from mv3dpose_ros.viz.panels import View
from mv3dpose_ros.viz.pictures import RenderError, write_animation, write_png
import numpy as np
from tqdm import tqdm

PANEL = 600           # [px] size of the top and side views


# ------------------------------------------------------------------------------------ input

def load_frames(path: str, topic: Optional[str] = None,
                issues: Optional[List[str]] = None) -> list:
    """
    Read a tracks JSON Lines file or a tracks bag into a list of ``TracksFrame``.

    Bag frames are numbered by message order and carry the header stamp in seconds. Bad
    lines of a JSON Lines file are skipped and appended to ``issues``.
    """
    if not os.path.exists(path):
        raise RenderError(f'{path}: tracks file or bag does not exist')
    if bag_path_type(path) == 'bag':
        # one schema for both inputs: bag tracks go through the JSON Lines record type
        return [parse_line(frame_to_line(i, tracks, layout, stamp * 1e-9))
                for i, (stamp, layout, tracks) in enumerate(tracks_from_bag(path, topic))]
    issues = [] if issues is None else issues
    frames = list(read_tracks(path, issues))
    if not frames:
        reason = f': {issues[0]}' if issues else ''
        raise RenderError(f'{path}: no frames of tracks{reason}')
    return frames


def _live(frame) -> list:
    return [t for t in frame.tracks if t.state != TrackState.DELETED]


def _layout_of(frames, layout: Optional[str]):
    name = layout or next((f.layout for f in frames if f.layout), None)
    if not name:
        raise RenderError('the tracks do not name their skeleton layout; pass --layout')
    return get_layout(name)


def _root(track, layout) -> np.ndarray:
    """Return the hip midpoint, else the track's root position, else the joint mean."""
    ok = valid_joints(track)
    a, b = layout.root_joints
    if ok[a] and ok[b]:
        return 0.5 * (track.joints[a] + track.joints[b])
    pos = track.extra.get('position') if track.extra else None
    if pos is not None and np.all(np.isfinite(pos)) and np.any(np.asarray(pos) != 0):
        return np.asarray(pos, dtype=float)
    return track.joints[ok].mean(axis=0) if ok.any() else np.full(3, np.nan)


class Renderer:
    """Draws frames of tracks; bounds are fixed over the sequence so animations do not jump."""

    def __init__(self, frames: list, layout=None, cameras: Optional[Mapping] = None,
                 panel: int = PANEL):
        """Prepare views that fit every live joint of ``frames`` (and the camera centres)."""
        self.frames = frames
        self.layout = _layout_of(frames, layout)
        self.cameras = dict(cameras or {})
        pts = [t.joints[valid_joints(t)] for f in frames for t in _live(f)]
        pts = np.concatenate(pts) if pts else np.zeros((0, 3))
        if len(pts) and pts.shape[1] != 3:
            raise RenderError('joints are not 3D')
        body = pts if len(pts) else np.array([[-1.0, -1.0, 0.0], [1.0, 1.0, 1.8]])
        lo, hi = np.percentile(body, 0.5, axis=0), np.percentile(body, 99.5, axis=0)
        top = [lo[:2] - 0.5, hi[:2] + 0.5]
        if self.cameras:
            centres = np.array([c.center for c in self.cameras.values()])
            top = [np.minimum(top[0], centres[:, :2].min(0) - 0.4),
                   np.maximum(top[1], centres[:, :2].max(0) + 0.4)]
        top = _min_extent(top, 2.0)
        self.top = View('top view (looking down)', (0, 1), top[0], top[1], (panel, panel),
                        ('x', 'y'))
        z_lo, z_hi = min(0.0, lo[2]) - 0.1, max(1.9, hi[2]) + 0.25
        half = (panel, panel // 2)
        self.sides = [
            View('side view (looking along +y)', (0, 2), np.array([lo[0] - 0.4, z_lo]),
                 np.array([hi[0] + 0.4, z_hi]), half, ('x', 'z')),
            View('side view (looking along -x)', (1, 2), np.array([lo[1] - 0.4, z_lo]),
                 np.array([hi[1] + 0.4, z_hi]), half, ('y', 'z')),
        ]
        self.sides[1].flip = True   # looking along -x: +y points left
        self.t0 = next((f.stamp for f in frames if f.stamp is not None), None)
        self.roots: Dict[int, List[Tuple[int, np.ndarray]]] = {}
        for i, f in enumerate(frames):
            for t in _live(f):
                r = _root(t, self.layout)
                if np.all(np.isfinite(r)):
                    self.roots.setdefault(t.id, []).append((i, r))

    # -------------------------------------------------------------------- 3D views
    def _views(self, index: int) -> np.ndarray:
        frame = self.frames[index]
        top = self.top.blank()
        sides = [v.blank() for v in self.sides]
        for view, img in zip(self.sides, sides):
            floor = np.round(view.px(np.array([[-1e3, -1e3, 0], [1e3, 1e3, 0]]))).astype(int)
            cv2.line(img, tuple(floor[0]), tuple(floor[1]), (150, 150, 150), 2)  # the ground
        for name, cam in self.cameras.items():
            c = cam.center
            axis = cam.R[2]  # optical axis in world coordinates
            p = self.top.px(c)
            q = self.top.px(c + 0.45 * axis / max(np.linalg.norm(axis[:2]), 1e-6))
            cv2.arrowedLine(top, tuple(map(int, p)), tuple(map(int, q)), (90, 90, 90), 1,
                            cv2.LINE_AA, tipLength=0.3)
            cv2.circle(top, tuple(map(int, p)), 4, (60, 60, 60), -1, cv2.LINE_AA)
            cv2.putText(top, name, (int(p[0]) + 5, int(p[1]) - 5), FONT, 0.38, (60, 60, 60), 1,
                        cv2.LINE_AA)
        for tid, path in self.roots.items():
            pts = [r for i, r in path if i <= index]
            if len(pts) > 1:
                uv = np.round(self.top.px(np.array(pts))).astype(np.int32)
                cv2.polylines(top, [uv.reshape(-1, 1, 2)], False, track_colour(tid), 1,
                              cv2.LINE_AA)
        for t in _live(frame):
            ok = valid_joints(t)
            if not ok.any():
                continue
            colour = track_colour(t.id)
            predicted = (np.asarray(t.joint_state) == JointState.PREDICTED
                         if t.joint_state is not None else None)
            dim = t.state == TrackState.COASTING
            head = t.joints[ok][np.argmax(t.joints[ok][:, 2])]
            for view, img in [(self.top, top)] + list(zip(self.sides, sides)):
                draw_skeleton(img, view.px(t.joints), ok, self.layout.bones, colour, 2, 3,
                              predicted, dim)
                at = (view.px(t.joints[ok].mean(0)) - [0, 16] if view is self.top
                      else view.px(head) - [0, 10])
                draw_label(img, f'#{t.id}', at, colour, 0.5, 1)
        legend = 'hollow joint = predicted, pale skeleton = coasting'
        cv2.putText(sides[1], legend, (self.sides[1].w - 330, 19), FONT, 0.38, AXIS_TEXT, 1,
                    cv2.LINE_AA)
        return np.hstack([top, np.vstack(sides)])

    # -------------------------------------------------------------------- camera images
    def _camera_tiles(self, index: int, images: Mapping[str, np.ndarray], width: int,
                      columns: int) -> Optional[np.ndarray]:
        names = [n for n in self.cameras if n in images]
        if not names:
            return None
        frame = self.frames[index]
        tile_w = width // columns
        tiles = []
        for name in names:
            cam, img = self.cameras[name], images[name]
            img = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR) if img.ndim == 2 else img.copy()
            thick = max(2, int(round(img.shape[1] / 320)))
            for t in _live(frame):
                ok = valid_joints(t)
                if not ok.any():
                    continue
                uv = cam.project(t.joints)
                ok = ok & np.isfinite(uv).all(axis=1)
                if not ok.any():
                    continue
                draw_skeleton(img, uv, ok, self.layout.bones, track_colour(t.id), thick,
                              thick + 1, dim=t.state == TrackState.COASTING)
                top = uv[ok][np.argmin(uv[ok][:, 1])]
                draw_label(img, f'#{t.id}', top - [0, 3 * thick], track_colour(t.id),
                           0.35 * thick, max(1, thick // 2))
            scale = tile_w / img.shape[1]
            tile = cv2.resize(img, (tile_w, int(round(img.shape[0] * scale))),
                              interpolation=cv2.INTER_AREA)
            cv2.rectangle(tile, (0, 0), (tile_w - 1, tile.shape[0] - 1), (200, 200, 200), 1)
            draw_label(tile, name, (40, 18), (30, 30, 30), 0.5, 1)
            tiles.append(tile)
        h = max(t.shape[0] for t in tiles)
        rows = []
        for k in range(0, len(tiles), columns):
            row = [np.pad(t, ((0, h - t.shape[0]), (0, 0), (0, 0)), constant_values=255)
                   for t in tiles[k:k + columns]]
            row += [np.full((h, tile_w, 3), 255, np.uint8)] * (columns - len(row))
            rows.append(np.hstack(row))
        grid = np.vstack(rows)
        return np.pad(grid, ((0, 0), (0, width - grid.shape[1]), (0, 0)), constant_values=255)

    def render(self, index: int, images: Optional[Mapping[str, np.ndarray]] = None,
               title: str = '') -> np.ndarray:
        """Return the BGR picture of frame ``index`` (3D views, then camera images)."""
        frame = self.frames[index]
        views = self._views(index)
        live = sorted(_live(frame), key=lambda t: t.id)
        bar = np.full((40, views.shape[1], 3), 255, np.uint8)
        stamp = ('' if frame.stamp is None or self.t0 is None
                 else f'   t = {frame.stamp - self.t0:.2f} s')
        text = f'{title}   ' if title else ''
        coasting = sum(1 for t in live if t.state == TrackState.COASTING)
        count = f'{len(live) - coasting} tracked' + (f', {coasting} coasting' if coasting else '')
        cv2.putText(bar, f'{text}frame {frame.frame}{stamp}   {count}',
                    (10, 26), FONT, 0.6, (30, 30, 30), 1, cv2.LINE_AA)
        x = views.shape[1] - 10
        for t in reversed(live):
            label = f'#{t.id}'
            (tw, _), _ = cv2.getTextSize(label, FONT, 0.6, 2)
            x -= tw + 14
            cv2.putText(bar, label, (x, 26), FONT, 0.6, track_colour(t.id), 2, cv2.LINE_AA)
        parts = [bar, views]
        if images:
            columns = 3 if len(images) > 4 else max(1, min(2, len(images)))
            tiles = self._camera_tiles(index, images, views.shape[1], columns)
            if tiles is not None:
                parts.append(tiles)
        return np.vstack(parts)

    def default_index(self) -> int:
        """Pick the frame to show: the last one with the most live tracks."""
        counts = [len(_live(f)) for f in self.frames]
        best = max(counts) if counts else 0
        return max(i for i, c in enumerate(counts) if c == best) if counts else 0


def _min_extent(box, extent: float):
    lo, hi = np.asarray(box[0], dtype=float), np.asarray(box[1], dtype=float)
    grow = np.maximum(extent - (hi - lo), 0.0) / 2
    return [lo - grow, hi + grow]


# ------------------------------------------------------------------------------------ images

class ImageSource:
    """Per-camera images for each frame: folders (by time-point order) or an image bag (stamp)."""

    def __init__(self, path: str, cameras: Sequence[str], frames: list):
        """Index ``path`` (per-camera folders or an image bag) for the given frames."""
        self.path = path
        self.frames = frames
        self._bag: Dict[str, Dict[int, bytes]] = {}
        self._table: Dict[str, list] = {}
        if not os.path.exists(path):
            raise RenderError(f'{path}: image folder or bag does not exist')
        if bag_path_type(path) == 'bag':
            self._index_bag(cameras)
        else:
            sources, _ = camera_sources(path, list(cameras), strict=False)
            _, self._table = time_points(
                {c: p for c, p in sources.items() if os.path.isdir(p)})

    def _index_bag(self, cameras: Sequence[str]) -> None:
        wanted = {image_topic(c): c for c in cameras}
        with BagReader(self.path) as reader:
            topics = [t for t in reader.topics() if t in wanted]
            if not topics:
                raise RenderError(f'{self.path}: no image topic of the calibrated cameras '
                                  f'({", ".join(wanted)})')
            stamps = {int(round(f.stamp * 1e9)) for f in self.frames if f.stamp is not None}
            for m in reader.messages(topics):
                header = deserialize(m.data, m.msgtype).header
                ns = header.stamp.sec * 10 ** 9 + header.stamp.nanosec
                if _near(ns, stamps):
                    self._bag.setdefault(wanted[m.topic], {})[_near(ns, stamps)] = m.data

    def images(self, index: int) -> Dict[str, np.ndarray]:
        """Return camera -> BGR image for frame ``index`` (cameras without one are left out)."""
        out = {}
        if self._bag:
            from mv3dpose_ros.ros.images import image_from_message  # ROS: image bags only
            stamp = self.frames[index].stamp
            ns = None if stamp is None else int(round(stamp * 1e9))
            for cam, by_stamp in self._bag.items():
                data = by_stamp.get(ns)
                if data is not None:
                    out[cam] = image_from_message(deserialize(data, 'sensor_msgs/msg/Image'))
            return out
        for cam, files in self._table.items():
            if index < len(files) and files[index] is not None:
                img = cv2.imread(files[index], cv2.IMREAD_COLOR)
                if img is None:
                    raise RenderError(f'{files[index]}: not a readable image')
                out[cam] = img
        return out


def _near(ns: int, stamps, tolerance_ns: int = 1_000_000) -> Optional[int]:
    if ns in stamps:
        return ns
    best = min(stamps, key=lambda s: abs(s - ns), default=None)
    return best if best is not None and abs(best - ns) <= tolerance_ns else None


# ------------------------------------------------------------------------------------ output

def render_tracks(tracks: str, output: Optional[str] = None, gif: Optional[str] = None,
                  video: Optional[str] = None, calibration: Optional[str] = None,
                  images: Optional[str] = None, frame: Optional[int] = None,
                  layout: Optional[str] = None, topic: Optional[str] = None, fps: float = 0.0,
                  max_frames: int = 300, title: str = '', quiet: bool = False) -> dict:
    """Render a tracks file or bag; return what was written and which frame the PNG shows."""
    issues: List[str] = []
    frames = load_frames(tracks, topic, issues)
    if not frames:
        raise RenderError(f'{tracks}: no frames of tracks')
    cameras = None
    if calibration:
        try:
            cameras = load_cameras(calibration)
        except SourceError as exc:
            raise RenderError(str(exc)) from exc
    if images and not cameras:
        raise RenderError('--images needs --calibration to reproject the skeletons')
    renderer = Renderer(frames, layout, cameras)
    source = ImageSource(images, list(cameras), frames) if images else None
    if source is not None and cameras is not None:
        used = set(source._table) | set(source._bag)
        renderer.cameras = {n: c for n, c in cameras.items() if n in used} or cameras
    result = {'frames': len(frames)}
    if frame is not None and not -len(frames) <= frame < len(frames):
        raise RenderError(f'{tracks}: frame index {frame} out of range (0..{len(frames) - 1})')
    if output:
        index = renderer.default_index() if frame is None else frame % len(frames)
        imgs = source.images(index) if source else None
        write_png(renderer.render(index, imgs, title), output)
        result.update(png=output, png_frame=frames[index].frame, png_index=index)
    if gif or video:
        step = max(1, math.ceil(len(frames) / max_frames))
        indices = list(range(0, len(frames), step))
        if fps <= 0:
            stamps = [f.stamp for f in frames if f.stamp is not None]
            period = (np.median(np.diff(stamps)) if len(stamps) > 1 else 0.0) * step
            fps = 1.0 / period if period > 0 else 10.0
            fps = min(max(fps, 1.0), 30.0)
        pictures = [renderer.render(i, source.images(i) if source else None, title)
                    for i in tqdm(indices, desc='rendering', unit='frame', leave=False,
                                  disable=True if quiet else None, file=sys.stderr)]
        for target in (gif, video):
            if target:
                write_animation(pictures, target, fps)
        result.update(gif=gif, video=video, animated_frames=len(indices), fps=fps)
    result['issues'] = issues
    return result


# ------------------------------------------------------------------------------------ CLI

def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the render options."""
    parser.add_argument('tracks', help='tracks JSON Lines file or tracks bag')
    parser.add_argument('-o', '--output', help='PNG of one frame (default: <tracks>.png)')
    parser.add_argument('--gif', help='animated GIF of the sequence')
    parser.add_argument('--video', help='MP4 (or AVI) of the sequence')
    parser.add_argument('-c', '--calibration', help='calibration file: draws the cameras and, '
                        'with --images, reprojects the skeletons')
    parser.add_argument('--images', help='per-camera image folders or an image bag '
                        '(folders: i-th time point = i-th frame of the tracks)')
    parser.add_argument('--frame', type=int,
                        help='frame index for the PNG (default: the last with most tracks)')
    parser.add_argument('--layout', help='skeleton layout if the tracks do not name it')
    parser.add_argument('--topic', help='track topic of a bag (default: the only one)')
    parser.add_argument('--fps', type=float, default=0.0,
                        help='animation speed (default: real time from the stamps)')
    parser.add_argument('--max-frames', type=int, default=300,
                        help='animate at most this many frames (evenly subsampled)')
    parser.add_argument('--title', default='', help='text in the picture header')
    parser.add_argument('-q', '--quiet', action='store_true')


def run(args: argparse.Namespace) -> int:
    """Run ``mv3dpose render``."""
    output = args.output
    if not (output or args.gif or args.video):
        output = str(Path(args.tracks.rstrip('/')).with_suffix('.png'))
    try:
        result = render_tracks(args.tracks, output, args.gif, args.video, args.calibration,
                               args.images, args.frame, args.layout, args.topic, args.fps,
                               args.max_frames, args.title, args.quiet)
    except (RenderError, BagError, OSError, ValueError) as exc:
        print(f'error: {exc}', file=sys.stderr)
        return 1
    if result.get('png'):
        print(f'wrote {result["png"]} (frame {result["png_frame"]} of {result["frames"]})')
    for key in ('gif', 'video'):
        if result.get(key):
            print(f'wrote {result[key]} ({result["animated_frames"]} frames at '
                  f'{result["fps"]:.1f} fps)')
    for issue in result['issues'][:20]:
        print(f'skipped {issue}', file=sys.stderr)
    return 3 if result['issues'] else 0   # done, but malformed lines were left out
