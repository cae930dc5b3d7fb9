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
The README's calibration recipe, run as typed on the real Pose2Sim detections.

``INTRINSICS``, ``POSES`` and ``LAYOUT`` are what the text tells a user to set: the Qualisys
file (its extrinsics are ignored), the OpenPose JSON of the 4 cameras and ``body25b``. The
block runs in a scratch folder holding a link to ``env.sh``; the rig it writes must place all
four cameras, and ``mv3dpose track`` must read it.
"""

import os
import subprocess
import sys

from mv3dpose_ros.core.geometry.calibration import load_calibration
import numpy as np
from test_live_rig import readme_block

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def test_readme_calibrate_recipe_as_typed_places_every_camera(shared_data, tmp_path):
    data = os.path.join(shared_data, 'pose2sim_multiperson')
    os.symlink(os.path.join(ROOT, 'env.sh'), tmp_path / 'env.sh')
    env = dict(os.environ, INTRINSICS=os.path.join(data, 'Calib_qualisys.toml'),
               POSES=os.path.join(data, 'pose'), LAYOUT='body25b')
    run = subprocess.run(['bash', '-c', readme_block('calibrate-recipe')], cwd=tmp_path,
                         env=env, capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
    rig = load_calibration(str(tmp_path / 'rig.yaml'))
    qualisys = load_calibration(env['INTRINSICS'])
    assert sorted(rig) == sorted(qualisys)
    for name, cam in rig.items():
        assert np.allclose(cam.K, qualisys[name].K)          # intrinsics kept as given
    assert (tmp_path / 'rig.report.txt').is_file() and (tmp_path / 'rig.png').is_file()
    track = subprocess.run([sys.executable, '-m', 'mv3dpose_ros.cli', 'track', '--calibration',
                            str(tmp_path / 'rig.yaml'), '--poses', env['POSES'], '--layout',
                            'body25b', '-o', str(tmp_path / 'tracks.jsonl')],
                           cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert track.returncode == 0, track.stderr[-3000:]
