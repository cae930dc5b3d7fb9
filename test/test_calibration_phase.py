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
``mv3dpose_bringup --calibrate`` without ROS: its plan, and the phase's retries on fake commands.

The phase (``nodes.calibration_phase``) runs ``mv3dpose bag record`` and ``mv3dpose calibrate``
as children; here a small script stands in for ``mv3dpose`` (records until SIGINT; calibrates
with the exit status a file says), so what is asserted is bringup's side: progress, one line
per missing-data failure, bounded retries, the failure reason.
"""

import collections
import os
import subprocess
import sys
import textwrap

from mv3dpose_ros.core.geometry.calibration import save_rig_yaml
from mv3dpose_ros.core.geometry.camera import Camera
from mv3dpose_ros.nodes import calibration_phase
from mv3dpose_ros.nodes.calibration_phase import CalibrationPhase, READY_MARK, recorded_topics
import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
FAKE_CLI = textwrap.dedent("""
    import sys, time
    if sys.argv[1] == 'bag':
        print('recording', flush=True)
        try:
            time.sleep(60)
        except KeyboardInterrupt:
            print('wrote bag: 10 messages on 2 topics', flush=True)
        sys.exit(0)
    code = int(open(sys.argv[-1] + '.code').read().split()[0])
    if code == 2:
        print('mv3dpose calibrate: too few frames with people in two cameras (3 < 10)')
    if code == 3:
        print('camera  placed\\n\\nnot placed:\\n  cam_b: shares no person with another camera')
    sys.exit(code)
""")


@pytest.fixture
def rig(tmp_path):
    K = np.array([[300.0, 0, 320], [0, 300.0, 240], [0, 0, 1]])
    cams = {n: Camera.look_at(n, K, eye, (0, 0, 1), 640, 480)
            for n, eye in zip(('cam_a', 'cam_b'), ((4, 0, 2), (0, 4, 2)))}
    path = str(tmp_path / 'intrinsics.yaml')
    save_rig_yaml(cams, path)
    return path


def bringup(*args):
    return subprocess.run([sys.executable, '-m', 'mv3dpose_ros.nodes.bringup', *args],
                          capture_output=True, text=True, timeout=60, cwd=ROOT)


def test_calibrate_needs_save_rig_and_plans_the_pose2d_nodes_first(rig, tmp_path):
    res = bringup('--rig', rig, '--calibrate', '--dry-run')
    assert res.returncode == 2 and '--save-rig' in res.stderr
    res = bringup('--rig', rig, '--calibrate', '--save-rig', str(tmp_path / 'rig.yaml'),
                  '--calibrate-pose2d-param', 'model.input_size:=640x384', '--dry-run')
    assert res.returncode == 0, res.stderr
    names = [ln.split(':')[0] for ln in res.stdout.splitlines() if ': ' in ln and
             not ln.startswith('#') and ln.startswith(('pose2d', 'fusion'))]
    assert names == ['pose2d_node[cam_a]', 'pose2d_node[cam_b]']    # fusion_node after
    assert 'input_size: 640x384' in res.stdout
    assert 'mv3dpose calibrate -o' in res.stdout
    res = bringup('--rig', rig, '--calibrate', '--save-rig', str(tmp_path / 'rig.yaml'),
                  '--dry-run')       # by default the largest input at a lower rate
    assert 'min_input_side: 640' in res.stdout and 'inference_rate_hz: 5.0' in res.stdout


def test_recorded_topics_are_each_cameras_persons_and_camera_info():
    assert recorded_topics(['cam_a'], '/{camera}', '/{camera}/image_raw') == [
        '/cam_a/persons_2d', '/cam_a/camera_info']


class FakeSupervisor:
    """What the phase uses of bringup's Supervisor: its log, its state, the pose2d nodes."""

    def __init__(self) -> None:
        self.lines, self.stopping, self.failed = [], False, False
        self.procs = {'pose2d_node[cam_a]': subprocess.Popen(
            [sys.executable, '-c', 'import time; time.sleep(60)'], start_new_session=True)}
        self.tails = {'pose2d_node[cam_a]': collections.deque([f'-> /cam_a/{READY_MARK}'])}

    def say(self, text: str) -> None:
        self.lines.append(text)

    def close(self) -> None:
        calibration_phase.end(self.procs['pose2d_node[cam_a]'], 5.0)


WHY = {2: 'too few frames with people in two cameras (3 < 10)',
       3: 'not placed: cam_b: shares no person with another camera'}


@pytest.mark.parametrize('codes, ok', [((2, 2), False), ((2, 0), True), ((3, 0), True)])
def test_missing_data_is_said_in_one_line_and_recorded_again(tmp_path, monkeypatch, codes, ok):
    script = tmp_path / 'fake_cli.py'
    script.write_text(FAKE_CLI)
    rig = str(tmp_path / 'rig.yaml')
    (tmp_path / 'rig.yaml.code').write_text(' '.join(map(str, codes)))
    monkeypatch.setattr(calibration_phase, 'PROGRESS_EVERY_S', 0.3)
    sup = FakeSupervisor()
    phase = CalibrationPhase(sup, list(sup.procs), [sys.executable, str(script)],
                             ['/cam_a/persons_2d'], 'intrinsics.yaml', rig, 0.8, 2)
    real = phase.calibrate

    def calibrate(bag):           # the fake's next exit status: the file's next number
        code = real(bag)
        rest = (tmp_path / 'rig.yaml.code').read_text().split()[1:] or ['0']
        (tmp_path / 'rig.yaml.code').write_text(' '.join(rest))
        return code
    phase.calibrate = calibrate
    try:
        assert phase.run() is ok, sup.lines
    finally:
        sup.close()
    log = '\n'.join(sup.lines)
    assert 'calibration: recorded 0 of 0.8 s (attempt 1 of 2)' in log, log
    assert 'bag record: wrote bag: 10 messages' in log, log
    missing = [ln for ln in sup.lines if ln.startswith('calibration: not enough data: ')]
    assert len(missing) == (2 if not ok else 1), log
    assert f'{WHY[codes[0]]}; recording again' in missing[0], log
    if ok:
        assert 'calibration: wrote ' in log and not sup.failed
    else:
        assert 'no attempts left' in missing[-1] and sup.failed
        assert phase.reason == f'calibration failed 2 times: {WHY[2]}', log
