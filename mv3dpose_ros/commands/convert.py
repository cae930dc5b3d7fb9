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
``mv3dpose convert``: files to bags and back, so recorded data can be replayed live.

images    per-camera image folders (or one video per camera) + a calibration file ->
          ``/<cam>/image_raw`` (sensor_msgs/Image, bgr8) and ``/<cam>/camera_info``; the i-th
          time point of every camera gets the same stamp ``start + i / fps``, so the fusion
          node's synchroniser sees complete sets.
openpose  per-camera OpenPose JSON folders -> ``/<cam>/persons_2d`` (Person2DArray), stamp
          ``start + frame / fps``, one message per frame and camera (empty when nobody or no
          file) as a live pose2d_node would publish.
tracks    a tracks bag (TrackedSkeletonArray) -> tracks JSON Lines of ``mv3dpose track``, or
          JSON Lines -> bag; the direction follows the input.

Camera names come from the calibration; folder names are matched to them (exactly, else
loosely: Pose2Sim's ``cam01_json`` is ``cam_01``). A folder without a calibrated camera, or a
requested camera without a folder, is an error naming both sides. ``<cam>`` in topic names is
the camera name, or ``cam<name>`` when the name is no valid ROS name token (``00_03``).

Outputs appear only complete (bags via ``BagWriter``, JSON Lines via a temp file renamed on
success). Exit status: 0 done, 1 error naming the file, 3 done but malformed input files or
lines were skipped (each named on stderr).
"""

import argparse
import os
from pathlib import Path
import re
import sys
from typing import Dict, Iterator, List, Optional, Sequence, Tuple

import cv2
from mv3dpose_ros.io.bag import BagError, BagReader, BagWriter, DEFAULT_STORAGE, get_typestore
from mv3dpose_ros.io.bag import make_qos, STORAGES, temp_path_beside
from mv3dpose_ros.io.media import IMAGE_EXTENSIONS, VIDEO_EXTENSIONS
from mv3dpose_ros.ros.names import camera_namespace
import numpy as np

DEFAULT_START_TIME = 1_700_000_000.0   # [s] fixed epoch: bags are reproducible, stamps never 0
TRACKS_TOPIC = '/mv3dpose/tracks'
TRACKS_TYPE = 'mv3dpose_msgs/msg/TrackedSkeletonArray'
PERSONS_TYPE = 'mv3dpose_msgs/msg/Person2DArray'
_DIGITS = re.compile(r'(\d+)')


class ConvertError(ValueError):
    """Input that cannot be converted; the text names the file or folder and the reason."""


def image_topic(camera: str) -> str:
    """Return the image topic of ``camera``."""
    return f'/{camera_namespace(camera)}/image_raw'


def info_topic(camera: str) -> str:
    """Return the CameraInfo topic of ``camera``."""
    return f'/{camera_namespace(camera)}/camera_info'


def persons_topic(camera: str) -> str:
    """Return the Person2DArray topic of ``camera``."""
    return f'/{camera_namespace(camera)}/persons_2d'


def stamp_ns(start_time: float, index: float, fps: float) -> int:
    """Return the stamp [ns] of time point ``index`` (exact integer arithmetic per frame)."""
    return int(round(start_time * 1e9)) + int(round(index * 1e9 / fps))


# ------------------------------------------------------------------------------------ inputs

def load_cameras(calibration: str, names: Optional[Sequence[str]] = None):
    """Load ``{name: Camera}`` from a calibration file, with errors naming the file."""
    from mv3dpose_ros.core.calibration import load_calibration
    if not os.path.exists(calibration):
        raise ConvertError(f'{calibration}: calibration file does not exist')
    try:
        cams = load_calibration(calibration)
    except (ValueError, OSError) as exc:
        raise ConvertError(f'{calibration}: cannot read the calibration: {exc}') from exc
    if names:
        missing = [n for n in names if n not in cams]
        if missing:
            raise ConvertError(f'{calibration}: no camera {", ".join(missing)} in the '
                               f'calibration (it has {", ".join(cams)})')
        cams = {n: cams[n] for n in names}
    return cams


def frame_key(name: str) -> Optional[int]:
    """Return the last number in a file name (the frame number), or None."""
    nums = _DIGITS.findall(Path(name).stem)
    return int(nums[-1]) if nums else None


def list_images(folder: str) -> List[str]:
    """Return the image files of ``folder`` sorted by frame number (then name)."""
    if not os.path.isdir(folder):
        raise ConvertError(f'{folder}: image folder does not exist')
    files = [f for f in os.listdir(folder) if f.lower().endswith(IMAGE_EXTENSIONS)]
    files.sort(key=lambda f: (frame_key(f) is None, frame_key(f) or 0, f))
    return [os.path.join(folder, f) for f in files]


def camera_sources(root: str, cameras: Sequence[str], calibration: str = '',
                   strict: bool = True) -> Tuple[Dict[str, str], List[str]]:
    """
    Map each camera to its (image or JSON) folder or video file under ``root``.

    ``cameras`` are the calibrated names; folders and videos (by their stem) are matched to them
    as ``mv3dpose track`` matches pose folders (``io.openpose.match_camera_names``: ``cam01.mp4``
    is camera ``cam_01``; a camera fitting several, e.g. a folder and a video, is an error
    naming them). Returns ``(camera -> path, calibrated cameras without data)``. With
    ``strict``, every sub-folder or video of ``root`` must match a calibrated camera, else
    ``ConvertError`` names it and the calibration's cameras.
    """
    from mv3dpose_ros.io.openpose import match_camera_names
    if not os.path.isdir(root):
        raise ConvertError(f'{root}: input folder does not exist')
    entries = sorted(os.listdir(root))
    videos = {e: Path(e).stem for e in entries if e.lower().endswith(VIDEO_EXTENSIONS)
              and os.path.isfile(os.path.join(root, e))}
    folders = [e for e in entries if os.path.isdir(os.path.join(root, e))
               and not e.startswith('.')]
    if not folders and not videos:
        raise ConvertError(f'{root}: no per-camera image folders or video files inside')
    try:
        # The loose rule of `mv3dpose track` (cam01.mp4 or cam01/ is camera cam_01); a camera
        # with both a folder and a video is ambiguous.
        matched, _ = match_camera_names(cameras, {**{f: f for f in folders}, **videos}, root,
                                        'folders or videos')
    except ValueError as exc:
        raise ConvertError(f'{root}: {exc}') from exc
    found = {cam: os.path.join(root, entry) for cam, entry in matched.items()}
    used = {os.path.basename(p) for p in found.values()}
    orphans = [f for f in folders if f not in used]
    orphans += [v for v in videos if v not in used]
    source = f' in {calibration}' if calibration else ''
    if orphans and strict:
        raise ConvertError(f'{root}: {", ".join(orphans)} match no calibrated camera{source} '
                           f'(cameras: {", ".join(cameras)}); rename them or fix the '
                           'calibration')
    if not found:
        raise ConvertError(f'{root}: no folder or video matches a calibrated camera{source} '
                           f'(cameras: {", ".join(cameras)})')
    ignored = [c for c in cameras if c not in found]
    return {c: found[c] for c in cameras if c in found}, ignored


def _read_video(path: str) -> Iterator[np.ndarray]:
    cap = cv2.VideoCapture(path)
    if not cap.isOpened():
        raise ConvertError(f'{path}: cannot open the video')
    try:
        while True:
            ok, frame = cap.read()
            if not ok:
                break
            yield frame
    finally:
        cap.release()


def _video_fps(path: str) -> float:
    cap = cv2.VideoCapture(path)
    fps = cap.get(cv2.CAP_PROP_FPS) if cap.isOpened() else 0.0
    cap.release()
    return float(fps) if fps and np.isfinite(fps) and fps > 0 else 0.0


def _time_points(sources: Dict[str, str]) -> Tuple[List[Optional[int]], Dict[str, list]]:
    """
    Align the images of all cameras into time points.

    When every file name carries a frame number, images with the same number form one time
    point (a camera without that number is absent there); otherwise the i-th images do.
    """
    per_cam = {c: list_images(p) for c, p in sources.items() if os.path.isdir(p)}
    for cam, files in per_cam.items():
        if not files:
            raise ConvertError(f'{sources[cam]}: no images ({", ".join(IMAGE_EXTENSIONS)}) '
                               f'for camera {cam}')
    numbered = all(frame_key(f) is not None for files in per_cam.values() for f in files)
    if numbered and per_cam:
        keys = sorted({frame_key(f) for files in per_cam.values() for f in files})
        table = {c: [next((f for f in files if frame_key(f) == k), None) for k in keys]
                 for c, files in per_cam.items()}
        return list(keys), table
    n = max((len(f) for f in per_cam.values()), default=0)
    return [None] * n, {c: files + [None] * (n - len(files)) for c, files in per_cam.items()}


# ------------------------------------------------------------------------------------ messages

def _stamp(store, ns: int):
    sec, nsec = divmod(int(ns), 10 ** 9)
    return store.types['builtin_interfaces/msg/Time'](sec=sec, nanosec=nsec)


def image_message(image: np.ndarray, stamp: int, frame_id: str):
    """Build a rosbags ``sensor_msgs/Image`` (bgr8 or mono8) from an OpenCV image."""
    store = get_typestore()
    t = store.types
    if image.ndim == 2:
        encoding, channels = 'mono8', 1
    else:
        encoding, channels = 'bgr8', image.shape[2]
        if channels == 4:
            image = cv2.cvtColor(image, cv2.COLOR_BGRA2BGR)
            channels = 3
    image = np.ascontiguousarray(image, dtype=np.uint8)
    h, w = image.shape[:2]
    return t['sensor_msgs/msg/Image'](
        header=t['std_msgs/msg/Header'](stamp=_stamp(store, stamp), frame_id=frame_id),
        height=h, width=w, encoding=encoding, is_bigendian=0, step=w * channels,
        data=image.reshape(-1))


def image_from_message(msg) -> np.ndarray:
    """Return a BGR (or grey) uint8 array from a rosbags ``sensor_msgs/Image``."""
    data = np.frombuffer(bytes(msg.data) if not isinstance(msg.data, np.ndarray)
                         else msg.data.tobytes(), dtype=np.uint8)
    enc = msg.encoding.lower()
    channels = {'mono8': 1, '8uc1': 1, 'bgr8': 3, 'rgb8': 3, '8uc3': 3, 'bgra8': 4,
                'rgba8': 4}.get(enc)
    if channels is None:
        raise ConvertError(f'unsupported image encoding {msg.encoding!r} (8-bit mono, bgr, '
                           'rgb, bgra, rgba are supported)')
    rows = data.reshape(msg.height, msg.step)[:, :msg.width * channels]
    img = rows.reshape(msg.height, msg.width, channels) if channels > 1 else rows.copy()
    if enc == 'rgb8':
        img = cv2.cvtColor(img, cv2.COLOR_RGB2BGR)
    elif enc in ('bgra8', 'rgba8'):
        img = cv2.cvtColor(img, cv2.COLOR_BGRA2BGR if enc == 'bgra8' else cv2.COLOR_RGBA2BGR)
    return np.ascontiguousarray(img)


def camera_info_message(cam, stamp: int, frame_id: str):
    """Build a rosbags ``sensor_msgs/CameraInfo`` (plumb_bob) for a core ``Camera``."""
    store = get_typestore()
    t = store.types
    K = np.asarray(cam.K, dtype=np.float64)
    P = np.zeros((3, 4))
    P[:, :3] = K
    return t['sensor_msgs/msg/CameraInfo'](
        header=t['std_msgs/msg/Header'](stamp=_stamp(store, stamp), frame_id=frame_id),
        height=int(cam.height), width=int(cam.width), distortion_model='plumb_bob',
        d=np.asarray(cam.dist, dtype=np.float64), k=K.reshape(-1), r=np.eye(3).reshape(-1),
        p=P.reshape(-1), binning_x=0, binning_y=0,
        roi=t['sensor_msgs/msg/RegionOfInterest'](
            x_offset=0, y_offset=0, height=0, width=0, do_rectify=False))


# ------------------------------------------------------------------------------------ images

def images_to_bag(root: str, calibration: str, output: str, fps: float = 0.0,
                  start_time: float = DEFAULT_START_TIME, cameras: Optional[Sequence[str]] = None,
                  storage: str = DEFAULT_STORAGE, quiet: bool = False) -> dict:
    """
    Write per-camera images or videos under ``root`` as an image bag.

    Returns a summary: cameras, time points, messages, stamps [ns].
    """
    from tqdm import tqdm
    cams = load_cameras(calibration, cameras)
    sources, ignored = camera_sources(root, list(cams), calibration, strict=not cameras)
    videos = {c: p for c, p in sources.items() if not os.path.isdir(p)}
    if fps <= 0:
        fps = max((_video_fps(p) for p in videos.values()), default=0.0) or 10.0
    keys, table = _time_points({c: p for c, p in sources.items() if c not in videos})
    frames_per_video = {}
    sensor_qos = [make_qos(reliable=True, depth=5)]  # replay reliably: no frame lost to UDP
    latched = [make_qos(reliable=True, depth=1)]
    stamps: List[int] = []
    count = 0
    with BagWriter(output, storage=storage) as writer:
        for cam in sources:
            writer.add_topic(image_topic(cam), 'sensor_msgs/msg/Image', sensor_qos)
            writer.add_topic(info_topic(cam), 'sensor_msgs/msg/CameraInfo', latched)
        iters = {c: _read_video(p) for c, p in videos.items()}
        n_points = len(keys) if keys else 0
        index = 0
        bar = tqdm(total=n_points or None, desc=f'writing {output}', unit='set',
                   disable=True if quiet else None, leave=False, file=sys.stderr)
        while True:
            items = []
            if index < n_points:
                for cam, files in table.items():
                    if files[index] is not None:
                        items.append((cam, files[index], None))
            for cam, it in iters.items():
                frame = next(it, None)
                if frame is not None:
                    items.append((cam, None, frame))
                    frames_per_video[cam] = frames_per_video.get(cam, 0) + 1
            if not items and index >= n_points:
                break
            stamp = stamp_ns(start_time, index, fps)
            for cam, path, frame in items:
                if frame is None:
                    frame = cv2.imread(path, cv2.IMREAD_UNCHANGED)
                    if frame is None:
                        raise ConvertError(f'{path}: not a readable image')
                if frame.dtype != np.uint8:
                    raise ConvertError(f'{path or videos[cam]}: only 8-bit images are supported')
                c = cams[cam]
                h, w = frame.shape[:2]
                if (w, h) != (c.width, c.height):
                    raise ConvertError(
                        f'{path or videos[cam]}: image is {w}x{h} but camera {cam} in '
                        f'{calibration} is calibrated for {c.width}x{c.height}')
                writer.write_msg(image_topic(cam), stamp, image_message(frame, stamp, cam),
                                 'sensor_msgs/msg/Image')
                writer.write_msg(info_topic(cam), stamp, camera_info_message(c, stamp, cam),
                                 'sensor_msgs/msg/CameraInfo')
                count += 2
            stamps.append(stamp)
            index += 1
            bar.update(1)
        bar.close()
    return {'output': output, 'cameras': list(sources), 'ignored_cameras': ignored,
            'time_points': len(stamps), 'frame_numbers': [k for k in keys if k is not None],
            'messages': count, 'stamps': stamps, 'fps': fps}


# ------------------------------------------------------------------------------------ openpose

def openpose_to_bag(root: str, calibration: str, output: str, layout: str, fps: float = 30.0,
                    start_time: float = DEFAULT_START_TIME,
                    cameras: Optional[Sequence[str]] = None,
                    storage: str = DEFAULT_STORAGE, quiet: bool = False) -> dict:
    """
    Write per-camera OpenPose JSON folders as ``Person2DArray`` streams.

    Every frame number found in any folder gives one message per camera (empty for a missing
    or malformed file, which is reported). Returns a summary.
    """
    from mv3dpose_ros.core.skeleton import get_layout
    from mv3dpose_ros.io.openpose import OpenPoseSequence
    from mv3dpose_ros.ros.messages import ns_to_stamp, numpy_to_person2d_array
    from rclpy.serialization import serialize_message
    from std_msgs.msg import Header
    from tqdm import tqdm

    lay = get_layout(layout)
    cams = load_cameras(calibration, cameras)
    folders, ignored = camera_sources(root, list(cams), calibration, strict=not cameras)
    bad = [p for p in folders.values() if not os.path.isdir(p)]
    if bad:
        raise ConvertError(f'{", ".join(bad)}: expected OpenPose JSON folders, not files')
    try:
        seq = OpenPoseSequence(folders, num_joints=lay.num_joints)
    except (OSError, ValueError) as exc:
        raise ConvertError(str(exc)) from exc
    if not len(seq):
        raise ConvertError(f'{root}: no OpenPose JSON files with a frame number in '
                           f'{", ".join(folders.values())}')
    qos = [make_qos(reliable=True, depth=10)]
    count = 0
    with BagWriter(output, storage=storage) as writer:
        for cam in folders:
            writer.add_topic(persons_topic(cam), PERSONS_TYPE, qos)
        for frame, views in tqdm(seq, desc=f'writing {output}', unit='frame', leave=False,
                                 disable=True if quiet else None, file=sys.stderr):
            stamp = stamp_ns(start_time, frame, fps)
            for cam in folders:
                poses = views.get(cam)
                if poses is None or poses.size == 0:
                    poses = np.zeros((0, lay.num_joints, 3))
                c = cams[cam]
                header = Header(stamp=ns_to_stamp(stamp), frame_id=cam)
                msg = numpy_to_person2d_array(poses, header, cam, c.width, c.height, lay.name)
                writer.write(persons_topic(cam), stamp, serialize_message(msg))
                count += 1
    return {'output': output, 'cameras': list(folders), 'ignored_cameras': ignored,
            'frames': len(seq), 'first_frame': seq.frames[0], 'last_frame': seq.frames[-1],
            'messages': count, 'issues': [str(i) for i in seq.issues], 'fps': fps}


# ------------------------------------------------------------------------------------ tracks

def tracks_from_bag(path: str, topic: Optional[str] = None
                    ) -> Iterator[Tuple[int, str, list]]:
    """Yield ``(stamp_ns, layout, [Track])`` for every TrackedSkeletonArray of a bag."""
    from mv3dpose_msgs.msg import TrackedSkeletonArray
    from mv3dpose_ros.ros.messages import msg_to_tracks, stamp_to_ns
    from rclpy.serialization import deserialize_message

    with BagReader(path) as reader:
        topics = {t: s for t, s in reader.topics().items() if s.msgtype == TRACKS_TYPE}
        if topic is None:
            if not topics:
                raise BagError(f'{path}: no {TRACKS_TYPE} topic in the bag '
                               f'(topics: {", ".join(reader.topics()) or "none"})')
            if len(topics) > 1:
                raise BagError(f'{path}: several track topics ({", ".join(topics)}); '
                               'choose one with --topic')
            topic = next(iter(topics))
        elif topic not in topics:
            raise BagError(f'{path}: no {TRACKS_TYPE} topic {topic} '
                           f'(track topics: {", ".join(topics) or "none"})')
        for m in reader.messages([topic]):
            try:
                msg = deserialize_message(m.data, TrackedSkeletonArray)
                tracks = msg_to_tracks(msg)
            except Exception as exc:  # noqa: B902 - rclpy raises RMWError and friends
                raise BagError(f'{path}: undecodable {TRACKS_TYPE} on {topic} at '
                               f'{m.timestamp} ns: {str(exc).splitlines()[0][:200]}') from None
            yield stamp_to_ns(msg.header.stamp), msg.layout, tracks


def record_to_track(rec, stamp: float):
    """Turn a tracks-file ``TrackRecord`` back into a core ``Track`` (unknown fields: NaN/0)."""
    from mv3dpose_ros.core.types import JointState, PositionSource, Track
    joints = np.asarray(rec.joints, dtype=np.float64)
    valid = np.isfinite(joints).all(axis=1)
    states = (np.asarray(rec.joint_state, dtype=np.uint8) if rec.joint_state is not None
              else np.where(valid, JointState.TRIANGULATED, JointState.MISSING).astype(np.uint8))
    extra = rec.extra or {}

    def vec(key):
        v = extra.get(key)
        return np.asarray(v, dtype=np.float64) if v is not None else np.full(3, np.nan)

    views = extra.get('num_views')
    return Track(
        track_id=int(rec.id), state=rec.state, joints=joints,
        confidence=np.asarray(rec.confidence, dtype=np.float64), joint_state=states,
        num_views=(np.asarray(views, dtype=np.uint8) if views is not None
                   else np.zeros(len(joints), np.uint8)),
        reprojection_error=np.full(len(joints), np.nan), position=vec('position'),
        velocity=vec('velocity'), first_seen=stamp, last_observed=stamp,
        score=float(extra.get('score', 0.0) or 0.0),
        position_source=getattr(rec, 'position_source', PositionSource.HIPS))


def bag_to_jsonl(path: str, output: str, topic: Optional[str] = None, fps: float = 0.0,
                 start_time: Optional[float] = None) -> dict:
    """
    Write the tracks of a bag as JSON Lines; return a summary.

    The ``frame`` of each line is the message index, or with ``fps`` (and ``start_time``,
    default the first stamp) ``round((stamp - start) * fps)``: the frame numbers of
    ``mv3dpose convert openpose`` come back.
    """
    from mv3dpose_ros.io.tracks_jsonl import TracksWriter
    out = Path(output)
    tmp = temp_path_beside(output)
    frames = 0
    ids = set()
    try:
        writer = None
        start_ns = None if start_time is None else int(round(start_time * 1e9))
        for i, (stamp, layout, tracks) in enumerate(tracks_from_bag(path, topic)):
            if writer is None:
                writer = TracksWriter(tmp, layout)
            if start_ns is None:
                start_ns = stamp
            frame = int(round((stamp - start_ns) * 1e-9 * fps)) if fps > 0 else i
            writer.write(frame, tracks, stamp * 1e-9)
            ids.update(t.track_id for t in tracks)
            frames += 1
        if writer is None:
            open(tmp, 'w').close()
        else:
            writer.close()
        os.replace(tmp, out)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return {'output': output, 'frames': frames, 'tracks': len(ids)}


def jsonl_to_bag(path: str, output: str, topic: str = TRACKS_TOPIC, frame_id: str = 'world',
                 fps: float = 30.0, start_time: float = DEFAULT_START_TIME,
                 storage: str = DEFAULT_STORAGE) -> dict:
    """Write a tracks JSON Lines file as a bag of TrackedSkeletonArray; return a summary."""
    from mv3dpose_ros.io.tracks_jsonl import read_tracks
    from mv3dpose_ros.ros.messages import ns_to_stamp, tracks_to_msg
    from rclpy.serialization import serialize_message
    from std_msgs.msg import Header
    if not os.path.isfile(path):
        raise ConvertError(f'{path}: tracks file does not exist')
    issues: List[str] = []
    frames = 0
    ids = set()
    with BagWriter(output, storage=storage) as writer:
        writer.add_topic(topic, TRACKS_TYPE, [make_qos(reliable=True, depth=10)])
        for fr in read_tracks(path, issues):
            stamp = (int(round(fr.stamp * 1e9)) if fr.stamp is not None
                     else stamp_ns(start_time, fr.frame, fps))
            tracks = [record_to_track(r, stamp * 1e-9) for r in fr.tracks]
            msg = tracks_to_msg(tracks, Header(stamp=ns_to_stamp(stamp), frame_id=frame_id),
                                fr.layout or '')
            writer.write(topic, stamp, serialize_message(msg))
            ids.update(t.track_id for t in tracks)
            frames += 1
        if not frames:
            raise ConvertError(f'{path}: no valid line of tracks' +
                               (f' ({issues[0]})' if issues else ''))
    return {'output': output, 'frames': frames, 'tracks': len(ids), 'issues': issues}


# ------------------------------------------------------------------------------------ CLI

def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the ``images``, ``openpose`` and ``tracks`` conversions."""
    sub = parser.add_subparsers(dest='convert_command', metavar='{images,openpose,tracks}')
    sub.required = True
    img = sub.add_parser('images', help='image folders / videos + calibration -> image bag')
    img.add_argument('root', help='folder with one image folder (or video file) per camera')
    img.add_argument('-c', '--calibration', required=True,
                     help='calibration file (rig YAML, Panoptic JSON, VoxelPose JSON, '
                          'Pose2Sim TOML)')
    img.add_argument('-o', '--output', required=True, help='output bag (must not exist)')
    img.add_argument('--fps', type=float, default=0.0,
                     help='time points per second (default: the rate of the videos, else 10)')
    img.add_argument('--cameras', nargs='+', help='use only these calibrated cameras')

    op = sub.add_parser('openpose', help='OpenPose JSON folders -> Person2DArray bag')
    op.add_argument('root', help='folder with one OpenPose JSON folder per camera')
    op.add_argument('-c', '--calibration', required=True,
                    help='calibration file (camera names and image sizes)')
    op.add_argument('-o', '--output', required=True, help='output bag (must not exist)')
    op.add_argument('--layout', default='body25',
                    help='keypoint layout of the JSON files (body25, body25b, coco17, ...)')
    op.add_argument('--fps', type=float, default=30.0, help='frames per second')
    op.add_argument('--cameras', nargs='+', help='use only these calibrated cameras')

    tr = sub.add_parser('tracks', help='tracks bag <-> tracks JSON Lines (by the input)')
    tr.add_argument('input', help='a bag (directory, .mcap, .db3) or a .jsonl file')
    tr.add_argument('-o', '--output', required=True)
    tr.add_argument('--topic', help=f'track topic (bag input: auto; JSONL input: '
                                    f'{TRACKS_TOPIC})')
    tr.add_argument('--frame-id', default='world', help='world frame id (JSONL input)')
    tr.add_argument('--fps', type=float, default=0.0,
                    help='JSONL input: stamps of lines without one; bag input: turn stamps '
                         'into frame numbers')
    for p in (img, op, tr):
        p.add_argument('--start-time', type=float, default=None,
                       help=f'stamp of frame 0 [s] (default {DEFAULT_START_TIME:.0f}; '
                            'bag -> JSONL: the first stamp)')
    for p in (img, op, tr):
        p.add_argument('--storage', choices=STORAGES, default=DEFAULT_STORAGE)
        p.add_argument('-q', '--quiet', action='store_true')


def run(args: argparse.Namespace) -> int:
    """Run ``mv3dpose convert <images|openpose|tracks>``."""
    from mv3dpose_ros.io.bag import bag_path_type
    start = DEFAULT_START_TIME if args.start_time is None else args.start_time
    try:
        if args.convert_command == 'images':
            s = images_to_bag(args.root, args.calibration, args.output, fps=args.fps,
                              start_time=start, cameras=args.cameras, storage=args.storage,
                              quiet=args.quiet)
            print(f'wrote {s["output"]}: {len(s["cameras"])} cameras '
                  f'({", ".join(s["cameras"])}), {s["time_points"]} time points at '
                  f'{s["fps"]:g} fps, {s["messages"]} messages')
        elif args.convert_command == 'openpose':
            s = openpose_to_bag(args.root, args.calibration, args.output, args.layout,
                                fps=args.fps, start_time=start, cameras=args.cameras,
                                storage=args.storage, quiet=args.quiet)
            print(f'wrote {s["output"]}: {len(s["cameras"])} cameras, {s["frames"]} frames '
                  f'({s["first_frame"]}..{s["last_frame"]}), {s["messages"]} messages')
            for issue in s['issues']:
                print(f'skipped {issue}', file=sys.stderr)
            if s['issues']:
                return 3          # written, but malformed input files were left out
        else:
            if bag_path_type(args.input) == 'bag' or not os.path.exists(args.input):
                if not os.path.exists(args.input):
                    raise ConvertError(f'{args.input}: input does not exist')
                s = bag_to_jsonl(args.input, args.output, topic=args.topic, fps=args.fps,
                                 start_time=args.start_time)
            else:
                s = jsonl_to_bag(args.input, args.output, topic=args.topic or TRACKS_TOPIC,
                                 frame_id=args.frame_id, fps=args.fps or 30.0,
                                 start_time=start, storage=args.storage)
                for issue in s['issues']:
                    print(f'skipped {issue}', file=sys.stderr)
            print(f'wrote {s["output"]}: {s["frames"]} frames, {s["tracks"]} track ids')
            if s.get('issues'):
                return 3          # written, but malformed lines were left out
    except (ConvertError, BagError, OSError, ValueError) as exc:
        print(f'error: {exc}', file=sys.stderr)
        return 1
    return 0
