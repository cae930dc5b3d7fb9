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
End to end over DDS: bag player -> nodes (separate processes) -> recorder, on real data.

* the demo on its synthetic rig (what ``make demo`` runs), scored against the ground truth;
* the full image pipeline on ../shared/data/panoptic_demo: image bag -> player ->
  pose2d_node x 5 -> fusion_node -> recorder, 3 people at every time point;
* the Pose2Sim OpenPose detections replayed as a bag through fusion_node give the tracks of
  ``mv3dpose track`` on the JSON files: ``~/tracks`` those of ``--smooth causal`` and
  ``~/tracks_smoothed`` those of ``--smooth fixed-lag --lag-frames 3``, frame for frame.
"""

import json
import os
import subprocess
import sys
import time

import cv2
from mv3dpose_ros.commands.bag import play
from mv3dpose_ros.commands.demo import (Pipeline, PLAUSIBLE_M, recorder_cmd, TRACKS_TOPIC,
                                        wait_for_nodes, write_params)
from mv3dpose_ros.core.types import TrackState
from mv3dpose_ros.io.tracks_jsonl import read_tracks
from mv3dpose_ros.ros.bag_convert import bag_to_jsonl, openpose_to_bag, tracks_from_bag
from mv3dpose_ros.ros.names import persons_topic
import numpy as np
import pytest

CLI = [sys.executable, '-m', 'mv3dpose_ros.cli']
SMOOTHED_TOPIC = '/fusion_node/tracks_smoothed'


def _demo(args, tmp_path, timeout):
    out = tmp_path / 'demo'
    proc = subprocess.run(CLI + ['demo', '-o', str(out), '-q', '--timeout', '90'] + args,
                          capture_output=True, text=True, timeout=timeout)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    summary = json.loads((out / 'summary.json').read_text())
    return out, summary, proc.stdout


@pytest.mark.ros
@pytest.mark.timeout(240)
def test_demo_on_the_synthetic_rig(tmp_path):
    out, s, log = _demo(['--frames', '60', '--rate', '2', '--seed', '4'], tmp_path, 200)
    assert s['mode'] == 'synthetic' and len(s['cameras']) == 4 and s['people'] == 3
    assert s['frames_with_output'] == 60 and s['unknown_stamps'] == 0
    assert s['tracks_found'] == 3 and s['id_switches'] == 0
    assert s['mota'] > 0.9 and s['mpjpe_mm'] < 60
    assert s['latency_ms']['median'] is not None
    for key in ('MOTA', 'MPJPE', 'latency', 'picture'):
        assert key in log
    img = cv2.imread(s['picture'])
    assert img is not None and img.shape[1] >= 1000
    assert len(list(read_tracks(s['tracks_jsonl']))) == 60


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.timeout(600)
def test_panoptic_images_through_pose2d_and_fusion_nodes(shared_data, tmp_path):
    from mv3dpose_ros.pose2d.models import ModelNotFound, resolve_model_path
    try:
        resolve_model_path()
    except ModelNotFound as exc:
        pytest.skip(str(exc))
    images = os.path.join(shared_data, 'panoptic_demo')
    out, s, log = _demo(['--images', images], tmp_path, 560)
    assert s['mode'] == 'images' and len(s['cameras']) == 5 and s['time_points'] == 5
    # every synchronised set of the 5 time points: the 3 people of the scene
    assert s['people_per_time_point'] == [3, 3, 3, 3, 3]
    for bone, length in s['bone_length_m'].items():
        lo, hi = PLAUSIBLE_M[bone]
        assert lo <= length <= hi, f'{bone}: median {length:.3f} m outside [{lo}, {hi}]'
    assert s['reprojection_error_px']['median'] < 20.0     # 1920x1080 images
    img = cv2.imread(s['picture'])
    assert img is not None and img.shape[0] > 900, 'no camera images in the picture'


@pytest.mark.ros
@pytest.mark.timeout(300)
def test_pose2sim_bag_replay_gives_the_tracks_of_mv3dpose_track(
        shared_data, tmp_path, ros_context):
    root = os.path.join(shared_data, 'pose2sim_multiperson')
    calib = os.path.join(root, 'Calib_qualisys.toml')
    fps, start = 60.0, 1000.0
    expected, expected_lag = tmp_path / 'track.jsonl', tmp_path / 'track_lag.jsonl'
    for smooth, path in ((['causal'], expected), (['fixed-lag', '--lag-frames', '3'],
                                                  expected_lag)):
        proc = subprocess.run(CLI + ['track', '--calibration', calib, '--poses',
                                     os.path.join(root, 'pose'), '--layout', 'body25b',
                                     '--fps', str(fps), '--smooth', *smooth, '-o', str(path),
                                     '--no-progress'],
                              capture_output=True, text=True, timeout=200)
        assert proc.returncode == 0, proc.stderr

    bag = tmp_path / 'detections'
    s = openpose_to_bag(os.path.join(root, 'pose'), calib, str(bag), 'body25b', fps=fps,
                        start_time=start, quiet=True)
    cams = s['cameras']
    env = dict(os.environ)
    pipeline = Pipeline(tmp_path, env)
    recorded = tmp_path / 'tracks_bag'
    try:
        # no shipped fusion.yaml: the node runs FusionConfig's defaults, as `track` does
        params = write_params(tmp_path / 'fusion.yaml', {'/**/fusion_node': {
            'use_sim_time': True, 'rig_config': calib, 'camera_ids': cams,
            'layout': 'body25b', 'smoothed_lag_frames': 3,
            # 60 fps: the synchroniser's slop must stay below half a frame period
            'sync': {'slop_s': 0.004}}})
        pipeline.start('fusion_node', ['fusion_node', '--ros-args', '--params-file', params])
        pipeline.start('recorder', recorder_cmd(recorded, [TRACKS_TOPIC, SMOOTHED_TOPIC]))
        wait_for_nodes(ros_context, pipeline, [persons_topic(c) for c in cams], 60.0)
        n = play(str(bag), rate=0.0, context=ros_context, quiet=True, wait_for_subscribers=60,
                 pace_topics=[TRACKS_TOPIC], pace_timeout=5.0)
        assert n == 400
        time.sleep(1.0)
        pipeline.check()
        assert pipeline.stop('recorder') == 0, pipeline.tail('recorder')
    finally:
        pipeline.stop_all()
    live, live_lag = tmp_path / 'live.jsonl', tmp_path / 'live_lag.jsonl'
    bag_to_jsonl(str(recorded), str(live), TRACKS_TOPIC, fps=fps, start_time=start)
    bag_to_jsonl(str(recorded), str(live_lag), SMOOTHED_TOPIC, fps=fps, start_time=start)

    ids = set()
    for want, got, lag in ((expected, live, 0), (expected_lag, live_lag, 3)):
        a = {f.frame: f for f in read_tracks(str(want))}
        b = {f.frame: f for f in read_tracks(str(got))}
        # the node holds the last `lag` sets until more input (or a reset) comes
        assert len(a) == 100 and sorted(b) == sorted(a)[:100 - lag]
        for frame in sorted(b):
            ta, tb = a[frame].tracks, b[frame].tracks
            assert b[frame].stamp == pytest.approx(a[frame].stamp + start, abs=1e-6), frame
            assert [(t.id, t.state) for t in tb] == [(t.id, t.state) for t in ta], frame
            for x, y in zip(ta, tb):
                # float32 keypoints in the messages vs float64 from JSON: sub-millimetre
                np.testing.assert_allclose(y.joints, x.joints, atol=2e-3, equal_nan=True)
                if x.state == TrackState.CONFIRMED:
                    ids.add(x.id)
    assert len(ids) >= 2, 'the two people of the sequence were not tracked'
    # exact stamps end to end: a track observed by a set carries that set's header stamp
    observed = 0
    for stamp_ns, _, tracks in tracks_from_bag(str(recorded), TRACKS_TOPIC):
        for t in tracks:
            if t.state == TrackState.CONFIRMED:
                assert t.last_observed_ns == stamp_ns
                observed += 1
    assert observed > 150
