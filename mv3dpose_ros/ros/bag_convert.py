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
Files to bags and back (the library of ``mv3dpose convert``), so recorded data replays live.

- ``images_to_bag``: per-camera image folders or videos + a calibration -> ``/<cam>/image_raw``
  (bgr8) and ``/<cam>/camera_info``; the i-th time point of every camera gets the stamp
  ``start + i / fps``, so the fusion node's synchroniser sees complete sets.
- ``openpose_to_bag``: per-camera OpenPose JSON folders -> ``/<cam>/persons_2d``, one message
  per frame and camera (empty when nobody or no file), as a live pose2d_node publishes.
- ``bag_to_jsonl`` / ``jsonl_to_bag`` (``tracks_from_bag``, ``record_to_track``): a tracks bag
  (TrackedSkeletonArray) <-> the tracks JSON Lines of ``mv3dpose track``.

Topic names are ``ros.names``'. Images are written as rosbags messages (no rclpy: the image
conversion runs without a sourced ROS); the Person2DArray and track conversions serialise
rclpy messages, imported where they are used. Outputs appear only complete (bags via
``BagWriter``, JSON Lines via a temp file renamed on success).
"""

import os
from pathlib import Path
import sys
from typing import Iterator, List, Optional, Sequence, Tuple

import cv2
from mv3dpose_ros.core.skeleton import get_layout
from mv3dpose_ros.core.types import JointState, PositionSource, Track
from mv3dpose_ros.io.bag import BagError, BagReader, BagWriter, DEFAULT_STORAGE, get_typestore
from mv3dpose_ros.io.bag import make_qos, temp_path_beside
from mv3dpose_ros.io.cameras import camera_sources, load_cameras, time_points
from mv3dpose_ros.io.media import read_video, SourceError, video_fps
from mv3dpose_ros.io.openpose import OpenPoseSequence
from mv3dpose_ros.io.tracks_jsonl import read_tracks, TracksWriter
from mv3dpose_ros.ros.names import image_topic, info_topic, persons_topic
import numpy as np
from tqdm import tqdm

DEFAULT_START_TIME = 1_700_000_000.0   # [s] fixed epoch: bags are reproducible, stamps never 0
TRACKS_TOPIC = '/mv3dpose/tracks'
TRACKS_TYPE = 'mv3dpose_msgs/msg/TrackedSkeletonArray'
PERSONS_TYPE = 'mv3dpose_msgs/msg/Person2DArray'


class ConvertError(ValueError):
    """Input that cannot be converted; the text names the file or folder and the reason."""


def stamp_ns(start_time: float, index: float, fps: float) -> int:
    """Return the stamp [ns] of time point ``index`` (exact integer arithmetic per frame)."""
    return int(round(start_time * 1e9)) + int(round(index * 1e9 / fps))


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
    cams = load_cameras(calibration, cameras)
    sources, ignored = camera_sources(root, list(cams), calibration, strict=not cameras)
    videos = {c: p for c, p in sources.items() if not os.path.isdir(p)}
    if fps <= 0:
        fps = max((video_fps(p) for p in videos.values()), default=0.0) or 10.0
    keys, table = time_points({c: p for c, p in sources.items() if c not in videos})
    frames_per_video = {}
    sensor_qos = [make_qos(reliable=True, depth=5)]  # replay reliably: no frame lost to UDP
    latched = [make_qos(reliable=True, depth=1)]
    stamps: List[int] = []
    count = 0
    with BagWriter(output, storage=storage) as writer:
        for cam in sources:
            writer.add_topic(image_topic(cam), 'sensor_msgs/msg/Image', sensor_qos)
            writer.add_topic(info_topic(cam), 'sensor_msgs/msg/CameraInfo', latched)
        iters = {c: read_video(p) for c, p in videos.items()}
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
                        raise SourceError(f'{path}: not a readable image')
                if frame.dtype != np.uint8:
                    raise SourceError(f'{path or videos[cam]}: only 8-bit images are supported')
                c = cams[cam]
                h, w = frame.shape[:2]
                if (w, h) != (c.width, c.height):
                    raise SourceError(
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
    from mv3dpose_ros.ros.messages import ns_to_stamp, numpy_to_person2d_array
    from rclpy.serialization import serialize_message
    from std_msgs.msg import Header

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
