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


"""Whole-run scoring: synthetic scenes through Fusion, ``mv3dpose eval`` on real ground truth."""

import argparse
import json
import os

from mv3dpose_ros import cli
from mv3dpose_ros.commands.eval import parse_frames
from mv3dpose_ros.core.fusion.pipeline import Fusion
from mv3dpose_ros.core.skeleton import convert_poses
from mv3dpose_ros.core.types import TrackState
from mv3dpose_ros.eval.mot import MOTEvaluator
from mv3dpose_ros.eval.sequence import evaluate_run, load_ground_truth, read_hypotheses
from mv3dpose_ros.io.datasets import CAMPUS_TEST_FRAMES
from mv3dpose_ros.io.tracks_jsonl import poses_to_line
from mv3dpose_ros.sim import make_scene
from mv3dpose_ros.sim.export import write_scene
import numpy as np
import pytest


def test_synthetic_scene_with_moderate_noise_gives_high_mota(tmp_path, capsys):
    # default DetectorNoise = moderate: 2 px + 0.5 % of person height, 3 % missed joints,
    # 2 % missed people, 0.05 false positives per view, 1 % swaps, occlusion, truncation
    scene = make_scene(num_cameras=4, num_people=4, num_frames=120, seed=11)
    fusion = Fusion(scene.cameras, scene.layout)
    ev = MOTEvaluator(threshold_m=0.5)
    for t, (stamp, views) in enumerate(scene.frames()):
        tracks = [x for x in fusion.step(views, stamp) if x.state == TrackState.CONFIRMED]
        ev.update(range(scene.num_people), scene.gt[t], [x.track_id for x in tracks],
                  np.array([x.joints for x in tracks]).reshape(-1, 17, 3))
    res = ev.result()
    print(res.summary())
    assert res.mota >= 0.95 and res.id_switches == 0 and res.mostly_tracked == 4
    # the same through files, mv3dpose track and mv3dpose eval gives the same figures
    paths = write_scene(scene, str(tmp_path / 'scene'))
    out = str(tmp_path / 'tracks.jsonl')
    assert cli.main(['track', '--calibration', paths['calibration'], '--poses', paths['poses'],
                     '--layout', 'coco17', '--fps', str(scene.fps), '--smooth', 'causal',
                     '-o', out,
                     '--no-progress']) == 0
    js = str(tmp_path / 'figures.json')
    capsys.readouterr()
    assert cli.main(['eval', '--tracks', out, '--gt', paths['gt'], '--format', 'tracks',
                     '--json', js]) == 0
    text = capsys.readouterr().out
    assert 'MOTA' in text and 'PCP' in text
    figures = json.load(open(js))
    assert figures['mot']['mota'] == pytest.approx(res.mota, abs=0.01)
    assert figures['mot']['id_switches'] == 0
    assert figures['pcp']['average'] > 0.95
    assert figures['mpjpe_m'] < 0.05


def write_lines(path, frames, layout):
    with open(path, 'w') as f:
        for frame, (ids, poses) in frames.items():
            f.write(poses_to_line(frame, ids, poses, layout) + '\n')


def test_campus_ground_truth_against_itself_and_a_broken_arm(shared_data, tmp_path, capsys):
    gt_path = os.path.join(shared_data, 'campus', 'actorsGT.mat')
    gt = load_ground_truth(gt_path, 'campus')
    assert gt.layout == 'shelf14'
    frames = {f: gt.frames[f] for f in CAMPUS_TEST_FRAMES}
    perfect = str(tmp_path / 'perfect.jsonl')
    write_lines(perfect, frames, 'shelf14')
    js = str(tmp_path / 'f.json')
    assert cli.main(['eval', '--tracks', perfect, '--gt', os.path.dirname(gt_path),
                     '--format', 'campus', '--json', js]) == 0
    fig = json.load(open(js))
    assert fig['frames'] == len(CAMPUS_TEST_FRAMES)
    assert fig['pcp']['average'] == 1.0 and fig['mot']['mota'] == 1.0
    assert fig['mpjpe_m'] == pytest.approx(0.0, abs=1e-5)
    # actor 1's right wrist 0.5 m off: its right lower arm fails, nothing else
    broken = {}
    for f, (ids, poses) in frames.items():
        poses = poses.copy()
        poses[ids == 1, 6, 2] += 0.5
        broken[f] = (ids, poses)
    hyp_layout, hyps = read_hypotheses(perfect)
    assert hyp_layout == 'shelf14'
    rep = evaluate_run('shelf14', broken, gt)
    k = rep.pcp.actor_ids.index(1)
    assert rep.pcp.per_actor[k] == pytest.approx(0.9)
    assert rep.pcp8.per_actor[k] == pytest.approx(7 / 8)
    assert rep.pcp.per_group['Lower arms'][k] == pytest.approx(0.5)
    assert rep.pcp.per_actor[[i for i in range(3) if i != k]].min() == 1.0
    # frames without any line count as misses, with a note
    rep = evaluate_run('shelf14', {f: v for f, v in frames.items() if f < 400}, gt)
    assert rep.mot.mota < 0.5 and any('no line' in n for n in rep.notes)


def test_panoptic_ground_truth_through_coco17_tracks(shared_data, tmp_path, capsys):
    folder = os.path.join(shared_data, 'panoptic_160906_band1')
    gt = load_ground_truth(folder, 'panoptic')
    assert gt.layout == 'panoptic19' and len(gt.frames) == 20
    # tracks in coco17 (what the pipeline outputs) made from the GT, ids renumbered
    coco = {f: (ids + 100, convert_poses(p, 'panoptic19', 'coco17', has_confidence=False))
            for f, (ids, p) in gt.frames.items()}
    path = str(tmp_path / 'coco.jsonl')
    write_lines(path, coco, 'coco17')
    js = str(tmp_path / 'f.json')
    assert cli.main(['eval', '--tracks', path, '--gt', folder, '--format', 'panoptic',
                     '--json', js]) == 0
    fig = json.load(open(js))
    assert fig['mpjpe_m'] == pytest.approx(0.0, abs=1e-5)
    assert fig['mot']['mota'] == 1.0 and fig['mot']['num_unique_objects'] == 3
    assert fig['mot']['id_switches'] == 0
    assert fig['pcp']['average'] == 1.0          # head joints derived alike on both sides
    # the frame offset shifts which tracks line scores which GT frame
    assert cli.main(['eval', '--tracks', path, '--gt', folder, '--format', 'panoptic',
                     '--frame-offset', '1', '--json', js]) == 0
    fig = json.load(open(js))
    assert fig['mot']['num_objects'] == 60 and fig['mot']['misses'] == 3   # no line for 188
    assert 0.0 < fig['mpjpe_m'] < 0.1                                 # one frame of motion
    assert 'no line' in capsys.readouterr().out


def test_frame_lists_and_bad_arguments(tmp_path, capsys):
    assert parse_frames('3-5,1,5') == [1, 3, 4, 5]
    with pytest.raises(argparse.ArgumentTypeError):
        parse_frames('5-3')
    with pytest.raises(argparse.ArgumentTypeError):
        parse_frames('a')
    empty = tmp_path / 'e.jsonl'
    empty.write_text('')
    assert cli.main(['eval', '--tracks', str(empty), '--gt', str(empty),
                     '--format', 'tracks']) == 2
    assert 'mv3dpose eval:' in capsys.readouterr().err
    scene = make_scene(num_cameras=2, num_people=1, num_frames=2)
    paths = write_scene(scene, str(tmp_path / 's'))
    assert cli.main(['eval', '--tracks', paths['gt'], '--gt', paths['gt'], '--format',
                     'tracks', '--states', 'lost']) == 2
    assert 'unknown state' in capsys.readouterr().err
    assert cli.main(['eval', '--tracks', paths['gt'], '--gt', paths['gt'], '--format',
                     'tracks', '--frames', '50-60']) == 1
    assert cli.main(['eval', '--tracks', paths['gt'], '--gt', str(tmp_path / 'nope'),
                     '--format', 'panoptic']) == 2
