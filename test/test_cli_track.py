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


"""``mv3dpose track`` on real Pose2Sim detections and on synthetic scenes."""

import json
import os
import subprocess
import sys

from mv3dpose_ros import cli
from mv3dpose_ros.core.fusion.pipeline import Fusion, FusionConfig
from mv3dpose_ros.core.geometry.calibration import load_calibration
from mv3dpose_ros.core.live.output import LiveOutput, TrackPublisher
from mv3dpose_ros.core.types import JointState
from mv3dpose_ros.io.openpose import match_camera_folders, OpenPoseSequence
from mv3dpose_ros.io.tracks_jsonl import frame_to_line, read_tracks
from mv3dpose_ros.sim import DetectorNoise, make_scene
from mv3dpose_ros.sim.export import write_scene
import numpy as np
import pytest

FPS = 60.0


@pytest.fixture(scope='module')
def pose2sim(shared_data, tmp_path_factory):
    """Run ``mv3dpose track`` once on the Pose2Sim data; return paths and output."""
    root = os.path.join(shared_data, 'pose2sim_multiperson')
    out = str(tmp_path_factory.mktemp('track') / 'tracks.jsonl')
    args = ['track', '--calibration', os.path.join(root, 'Calib_qualisys.toml'),
            '--poses', os.path.join(root, 'pose'), '--layout', 'body25b',
            '--fps', str(FPS), '--smooth', 'causal', '--output', out, '--no-progress']
    assert cli.main(args) == 0
    return root, out


def confirmed_ids(path):
    return [sorted(t.id for t in f.tracks if t.state.name == 'CONFIRMED')
            for f in read_tracks(path)]


def test_pose2sim_gives_two_persistent_tracks(pose2sim):
    _, out = pose2sim
    lines = open(out).read().splitlines()
    assert len(lines) == 100
    for line in lines:                        # every line is a complete, valid JSON object
        obj = json.loads(line)
        assert set(obj) >= {'frame', 'layout', 'units', 'stamp', 'tracks'}
        assert obj['layout'] == 'body25b' and obj['units'] == 'm'
        for t in obj['tracks']:
            assert len(t['joints']) == 25 and len(t['confidence']) == 25
    ids = confirmed_ids(out)
    assert sorted({i for frame in ids for i in frame}) == sorted(set(ids[-1]))
    assert len(ids[-1]) == 2
    # no id switch: once both are confirmed, the same two ids are there in every frame
    first = next(k for k, f in enumerate(ids) if len(f) == 2)
    assert first <= 5
    assert all(f == ids[-1] for f in ids[first:])


def test_track_output_equals_fusion_step(pose2sim):
    root, out = pose2sim
    cameras = load_calibration(os.path.join(root, 'Calib_qualisys.toml'))
    folders, missing = match_camera_folders(os.path.join(root, 'pose'), list(cameras))
    assert not missing
    seq = OpenPoseSequence(folders, num_joints=25)
    config = FusionConfig(smoothing='causal')                # the defaults of the CLI
    fusion = Fusion(cameras, 'body25b', config)
    publisher = TrackPublisher(publish_coast_s=config.publish_coast_s)   # as fusion_node
    expected, reproj = [], []
    for frame, views in seq:
        tracks = publisher.publish(fusion.step(views, frame / FPS), frame / FPS)
        expected.append(frame_to_line(frame, tracks, 'body25b', frame / FPS))
        for t in tracks:
            if t.state.name == 'CONFIRMED':
                e = t.reprojection_error[t.joint_state == JointState.TRIANGULATED]
                reproj.extend(e[np.isfinite(e)])
    assert open(out).read().splitlines() == expected
    print(f'Pose2Sim median reprojection error of confirmed joints: {np.median(reproj):.1f} px')
    assert np.median(reproj) < 30.0


def test_offline_smoothing_keeps_ids_and_smooths(pose2sim, tmp_path):
    root, raw_out = pose2sim
    outs = {}
    for mode in ('none', 'offline'):
        outs[mode] = str(tmp_path / f'{mode}.jsonl')
        assert cli.main(['track', '--calibration', os.path.join(root, 'Calib_qualisys.toml'),
                         '--poses', os.path.join(root, 'pose'), '--layout', 'body25b',
                         '--fps', str(FPS), '--smooth', mode, '-o', outs[mode],
                         '--no-progress']) == 0
    live, settled = confirmed_ids(outs['none']), confirmed_ids(outs['offline'])
    # Same ids; both people are reported from the first frame (well supported at birth).
    assert {i for f in live for i in f} == {i for f in settled for i in f}
    assert all(set(a) <= set(b) for a, b in zip(live, settled)) and len(live) == len(settled)
    assert all(settled[:2]) and all(live[:2])

    def roughness(path):
        traj = {}
        for f in read_tracks(path):
            for t in f.tracks:
                if t.state.name == 'CONFIRMED':
                    traj.setdefault(t.id, []).append(t.joints)
        acc = [np.nanmean(np.linalg.norm(np.diff(np.array(v), 2, axis=0), axis=-1))
               for v in traj.values()]
        return float(np.mean(acc))

    assert roughness(outs['offline']) < 0.5 * roughness(outs['none'])


def test_fixed_lag_output_is_the_live_output_settled_lag_frames_later(pose2sim, tmp_path):
    root, causal_out = pose2sim
    out = str(tmp_path / 'lag.jsonl')
    assert cli.main(['track', '--calibration', os.path.join(root, 'Calib_qualisys.toml'),
                     '--poses', os.path.join(root, 'pose'), '--layout', 'body25b',
                     '--fps', str(FPS), '--smooth', 'fixed-lag', '--lag-frames', '4',
                     '-o', out, '--no-progress']) == 0
    causal, lagged = list(read_tracks(causal_out)), list(read_tracks(out))
    # every frame, with its own number and stamp; the live tracks with their ids and states
    # (plus what the lag settles: bridged gaps, tracks confirmed within the lag)
    assert [(f.frame, f.stamp) for f in lagged] == [(f.frame, f.stamp) for f in causal]
    moved = []
    for a, b in zip(causal, lagged):
        settled = {t.id: t for t in b.tracks}
        for x in a.tracks:
            y = settled[x.id]
            assert y.state == x.state
            ok = np.isfinite(x.joints[:, 0]) & np.isfinite(y.joints[:, 0])
            moved.extend(np.linalg.norm(x.joints[ok] - y.joints[ok], axis=1))
    assert 0.001 < np.median(moved) < 0.05        # re-estimated, not a different person

    # the output equals the core smoother run on the causal stream, frame for frame
    cameras = load_calibration(os.path.join(root, 'Calib_qualisys.toml'))
    folders, _ = match_camera_folders(os.path.join(root, 'pose'), list(cameras))
    fusion = Fusion(cameras, 'body25b', FusionConfig())
    output = LiveOutput(fusion.config.publish_coast_s, lag=4,
                        root_joints=fusion.layout.root_joints)
    expected = []
    for frame, views in OpenPoseSequence(folders, num_joints=25):
        stamp = frame / FPS
        _, done = output.step(fusion.step(views, stamp), stamp, frame)
        if done is not None:
            expected.append(frame_to_line(done[0], done[2], 'body25b', done[1]))
    expected += [frame_to_line(k, t, 'body25b', s) for k, s, t in output.flush()]
    assert open(out).read().splitlines() == expected


def test_synthetic_scene_files_with_bad_inputs(tmp_path):
    scene = make_scene(num_cameras=4, num_people=2, num_frames=30, seed=5)
    paths = write_scene(scene, str(tmp_path / 'scene'))
    bad = os.path.join(paths['poses'], 'cam_02', 'cam_02_000000000007_keypoints.json')
    with open(bad, 'w') as f:
        f.write('{"people": [{"pose_keypoints_2d": [1, 2]}]}')
    os.remove(os.path.join(paths['poses'], 'cam_03', 'cam_03_000000000008_keypoints.json'))
    out = str(tmp_path / 'tracks.jsonl')
    proc = subprocess.run(
        [sys.executable, '-m', 'mv3dpose_ros.cli', 'track', '--calibration',
         paths['calibration'], '--poses', paths['poses'], '--layout', 'coco17', '--fps', '25',
         '--output', out], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 3, proc.stderr          # done, but files were skipped
    assert 'cam_02_000000000007_keypoints.json' in proc.stderr
    assert 'not a multiple of 3' in proc.stderr
    frames = list(read_tracks(out))
    assert [f.frame for f in frames] == list(range(30))
    assert len({t.id for f in frames for t in f.tracks if t.state.name == 'CONFIRMED'}) == 2


def test_bad_arguments_fail_with_a_message(tmp_path, capsys):
    scene = make_scene(num_cameras=3, num_people=1, num_frames=3, seed=1,
                       noise=DetectorNoise.none())
    paths = write_scene(scene, str(tmp_path / 's'))
    base = ['track', '--calibration', paths['calibration'], '--poses', paths['poses'],
            '-o', str(tmp_path / 'o.jsonl'), '--no-progress']
    assert cli.main(base + ['--layout', 'body25']) == 2
    assert '17 joints per person' in capsys.readouterr().err
    assert cli.main(base + ['--layout', 'nope']) == 2
    assert 'unknown skeleton layout' in capsys.readouterr().err
    assert cli.main(base + ['--layout', 'coco17', '--cameras', 'cam_01', 'cam_09']) == 2
    assert 'cam_09' in capsys.readouterr().err
    params = tmp_path / 'p.yaml'
    params.write_text('fusion_node:\n  ros__parameters:\n    fusion:\n      bogus: 1\n')
    assert cli.main(base + ['--layout', 'coco17', '--params', str(params)]) == 2
    assert 'bogus' in capsys.readouterr().err
    params.write_text('/**/fusion_node:\n  ros__parameters:\n    fusion:\n'
                      '      tracking_gate_m: 0.3\n')
    assert cli.main(base + ['--layout', 'coco17', '--params', str(params)]) == 0
    os.rename(os.path.join(paths['poses'], 'cam_02'), os.path.join(paths['poses'], 'cam02_json'))
    os.rename(os.path.join(paths['poses'], 'cam_03'), os.path.join(paths['poses'], 'elsewhere'))
    assert cli.main(base + ['--layout', 'coco17']) == 0          # cam02_json is cam_02
    assert "camera 'cam_03': no folder" in capsys.readouterr().err
