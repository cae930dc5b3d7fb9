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
Write a synthetic scene to the files the offline tools read.

``write_scene(scene, folder)`` creates ``folder/rig.yaml`` (the project's rig YAML),
``folder/poses/<camera>/<camera>_<frame:012d>_keypoints.json`` (OpenPose JSON, as
``mv3dpose track --poses`` reads) and ``folder/gt.jsonl`` (ground truth in the tracks JSON
Lines schema, ids = person index, as ``mv3dpose eval --format tracks`` reads).
"""

import os
from typing import Dict

from mv3dpose_ros.core.geometry.calibration import save_rig_yaml
from mv3dpose_ros.io.openpose import openpose_filename, write_openpose_file
from mv3dpose_ros.io.tracks_jsonl import poses_to_line
from mv3dpose_ros.sim.scene import Scene
import numpy as np


def write_openpose(scene: Scene, root: str) -> Dict[str, str]:
    """Write the detections as OpenPose JSON, one folder per camera; return the folders."""
    folders = {}
    for name in scene.cameras:
        folder = os.path.join(root, name)
        os.makedirs(folder, exist_ok=True)
        folders[name] = folder
        for t, views in enumerate(scene.views):
            write_openpose_file(os.path.join(folder, openpose_filename(name, t)),
                                views.get(name, np.zeros((0, 0, 3))))
    return folders


def write_gt(scene: Scene, path: str) -> None:
    """Write the ground truth as tracks JSON Lines (ids = person indices)."""
    ids = list(range(scene.num_people))
    with open(path, 'w', encoding='utf-8') as f:
        for t in range(scene.num_frames):
            f.write(poses_to_line(t, ids, scene.gt[t], scene.layout, scene.stamps[t]) + '\n')


def write_scene(scene: Scene, folder: str) -> Dict[str, str]:
    """Write rig, detections and ground truth under ``folder``; return their paths."""
    os.makedirs(folder, exist_ok=True)
    paths = {'calibration': os.path.join(folder, 'rig.yaml'),
             'poses': os.path.join(folder, 'poses'),
             'gt': os.path.join(folder, 'gt.jsonl')}
    save_rig_yaml(scene.cameras, paths['calibration'])
    write_openpose(scene, paths['poses'])
    write_gt(scene, paths['gt'])
    return paths
