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
bringup: the plan it derives from one rig, and a real run stopped with SIGINT.

The process list (``nodes.processes``) is what bringup and the launch file both start: the
launch file is run here with stand-ins for ``launch``/``launch_ros`` (not in the PyPI wheels),
and against the real ones where they are installed.

The real run uses a crafted constant-output ONNX model (``pose2d_models``), so no
model download is needed: images in, ``persons_2d`` per camera, ``tracks`` from fusion.
"""

import os
import re
import signal
import subprocess
import sys
import threading
import time
import types

from mv3dpose_msgs.msg import Person2DArray, TrackedSkeletonArray
from mv3dpose_ros.core.geometry.calibration import save_rig_yaml
from mv3dpose_ros.core.geometry.camera import Camera
from mv3dpose_ros.nodes.bringup import build_parser, Plan
from mv3dpose_ros.nodes.processes import PlanError, rig_processes, split_threads
from mv3dpose_ros.ros.images import numpy_to_image
from mv3dpose_ros.ros.messages import ns_to_stamp
from mv3dpose_ros.ros.qos import reliable_qos
from mv3dpose_ros.testing.probe import Probe
from mv3dpose_ros.testing.processes import NodeProcess
import numpy as np
import pytest
from sensor_msgs.msg import Image
from std_msgs.msg import Header
import yaml

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
LAUNCH_FILE = os.path.join(ROOT, 'launch', 'mv3dpose.launch.py')
W, H = 320, 240
CAMS = ('cam_a', 'cam_b')


@pytest.fixture
def rig(tmp_path):
    K = np.array([[300.0, 0, W / 2], [0, 300.0, H / 2], [0, 0, 1]])
    cams = {n: Camera.look_at(n, K, eye, (0, 0, 1), W, H)
            for n, eye in zip(CAMS, ((4, 0, 2), (0, 4, 2)))}
    path = str(tmp_path / 'rig.yaml')
    save_rig_yaml(cams, path)
    return path


def bringup(*args, **kw):
    return subprocess.run([sys.executable, '-m', 'mv3dpose_ros.nodes.bringup', *args],
                          capture_output=True, text=True, timeout=60, cwd=ROOT, **kw)


def test_dry_run_plans_one_pose2d_node_per_camera(rig):
    res = bringup('--rig', rig, '--dry-run', '--image-topic', '/{camera}/image_raw',
                  '--pose2d-param', 'model.threads:=1', '--fusion-param', 'sync.slop_s:=0.02',
                  '--use-sim-time')
    assert res.returncode == 0, res.stderr
    lines = res.stdout.splitlines()
    for cam in CAMS:
        (line,) = [ln for ln in lines if ln.startswith(f'pose2d_node[{cam}]:')]
        assert f'__ns:=/{cam}' in line and f'image:=/{cam}/image_raw' in line
        assert line.count('--params-file') == 3
    (fusion,) = [ln for ln in lines if ln.startswith('fusion_node:')]
    assert '__ns' not in fusion
    overrides = yaml.safe_load(res.stdout.split('(passed last):\n', 1)[1])
    f = overrides['/**/fusion_node']['ros__parameters']
    assert f['rig_config'] == rig and f['camera_ids'] == list(CAMS)
    assert f['input_topic'] == '/{camera}/persons_2d' and f['sync'] == {'slop_s': 0.02}
    assert overrides['/cam_b/pose2d_node']['ros__parameters'] == {
        'model': {'threads': 1}, 'camera_id': 'cam_b'}
    assert overrides['/**']['ros__parameters'] == {'use_sim_time': True}


def test_numeric_camera_names_map_to_one_ros_name_everywhere(tmp_path):
    K = np.array([[300.0, 0, W / 2], [0, 300.0, H / 2], [0, 0, 1]])
    cams = {n: Camera.look_at(n, K, eye, (0, 0, 1), W, H)
            for n, eye in zip(('00_03', '00_06'), ((4, 0, 2), (0, 4, 2)))}
    path = str(tmp_path / 'rig.yaml')
    save_rig_yaml(cams, path)
    res = bringup('--rig', path, '--dry-run')
    assert res.returncode == 0, res.stderr
    lines = res.stdout.splitlines()
    for cam in cams:
        (line,) = [ln for ln in lines if ln.startswith(f'pose2d_node[{cam}]:')]
        assert f'__ns:=/cam{cam} ' in line and f'image:=/cam{cam}/image_raw ' in line
    overrides = yaml.safe_load(res.stdout.split('(passed last):\n', 1)[1].split('\n#')[0])
    assert overrides['/cam00_06/pose2d_node']['ros__parameters']['camera_id'] == '00_06'
    f = overrides['/**/fusion_node']['ros__parameters']
    assert f['camera_ids'] == ['00_03', '00_06'] and f['input_topic'] == '/{camera}/persons_2d'
    assert 'Fast DDS profile: ' in res.stdout and 'fastdds_shm.xml' in res.stdout
    res = bringup('--rig', path, '--dry-run', '--dds-profile', 'none')
    assert '# Fast DDS profile: none' in res.stdout


@pytest.mark.parametrize('option, value, why', [
    ('--image-topic', '/images', 'has no {camera}: all 2 cameras would share one name'),
    ('--image-topic', '/{camera}/image-raw', "contains '-'"),
    ('--image-topic', '/{camera}//image', 'empty token'),
    ('--namespace', '/rig/{camera}/', 'ends with /'),
])
def test_invalid_topic_patterns_are_refused_before_starting(rig, option, value, why):
    res = bringup('--rig', rig, option, value, '--dry-run')
    assert res.returncode != 0 and option in res.stderr and why in res.stderr, res.stderr
    assert 'pose2d_node[' not in res.stdout


@pytest.mark.ros
def test_a_dying_node_stops_bringup_with_its_name_and_reason(rig, tmp_path):
    missing = tmp_path / 'no_such_model.onnx'
    res = bringup('--rig', rig, '--pose2d-param', f'model.path:={missing}',
                  '--pose2d-param', 'model.threads:=1', '--stop-timeout', '5')
    assert res.returncode == 1, res.stderr
    last = res.stderr.strip().splitlines()[-1]
    assert re.search(r'exiting with 1 because pose2d_node\[cam_[ab]\] died \(exit code 1\): '
                     r'.*no_such_model\.onnx', last), res.stderr[-3000:]


@pytest.mark.skipif(not os.path.isdir('/dev/shm'), reason='no /dev/shm')
def test_bringup_removes_shared_memory_left_by_killed_processes(rig, tmp_path):
    # a segment of a process that is gone: nobody holds its lock file (names Fast DDS never
    # makes: it uses hex)
    names = ['fastrtps_zzmv3dposetest01', 'fastrtps_zzmv3dposetest01_el']
    paths = [os.path.join('/dev/shm', n) for n in names]
    old = time.time() - 60.0
    for path, size in zip(paths, (4096, 0)):
        with open(path, 'wb') as f:
            f.truncate(size)
        os.utime(path, (old, old))
    try:
        res = bringup('--rig', rig, '--pose2d-param', f'model.path:={tmp_path / "none.onnx"}',
                      '--stop-timeout', '5')
        assert not any(os.path.exists(p) for p in paths)
        said = r'\[bringup\] removed \d+ Fast DDS shared-memory files \(\d+ MB\) in /dev/shm left'
        assert re.search(said, res.stderr), res.stderr[-3000:]
    finally:
        for path in paths:
            if os.path.exists(path):
                os.remove(path)


def test_respawn_restarts_a_dying_node_after_growing_delays(rig, tmp_path):
    """--respawn: a node that cannot start is restarted after 1 s, then 2 s, then 4 s."""
    proc = subprocess.Popen(
        [sys.executable, '-m', 'mv3dpose_ros.nodes.bringup', '--rig', rig, '--cameras',
         'cam_a', '--no-fusion', '--respawn', '--stop-timeout', '5', '--pose2d-param',
         f'model.path:={tmp_path / "none.onnx"}'], stderr=subprocess.PIPE, text=True, cwd=ROOT)
    watchdog = threading.Timer(90.0, proc.send_signal, (signal.SIGINT,))
    watchdog.start()
    lines = []
    try:
        for line in proc.stderr:
            lines.append(line)
            if line.startswith('[bringup] restarting pose2d_node[cam_a] in 4 s'):
                proc.send_signal(signal.SIGINT)        # the third exit: enough seen
                break
        _, rest = proc.communicate(timeout=60)
    finally:
        watchdog.cancel()
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    text = ''.join(lines) + rest
    delays = re.findall(r'\[bringup\] restarting pose2d_node\[cam_a\] in (\S+) s', text)
    assert delays[:3] == ['1', '2', '4'], text[-3000:]
    assert len(re.findall(r'\[bringup\] started pose2d_node\[cam_a\]', text)) == 3
    died = r'pose2d_node\[cam_a\] died \(exit code 1\): .*none\.onnx'
    assert len(re.findall(died, text)) == 3
    assert 'exit codes' in text and proc.returncode == 1


def test_bad_rig_and_cameras_fail_with_clear_messages(rig, tmp_path):
    res = bringup('--rig', str(tmp_path / 'missing.yaml'), '--dry-run')
    assert res.returncode != 0 and 'cannot load rig' in res.stderr
    res = bringup('--rig', rig, '--cameras', 'cam_a', 'cam_z', '--dry-run')
    assert res.returncode != 0 and "cameras ['cam_z'] are not in" in res.stderr


@pytest.mark.ros
def test_bringup_runs_pipeline_and_stops_on_sigint(rig, tmp_path, ros_context):
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    from pose2d_models import crafted_model
    model, _ = crafted_model(tmp_path)
    log_path = tmp_path / 'bringup.log'
    proc = NodeProcess(
        [sys.executable, '-m', 'mv3dpose_ros.nodes.bringup', '--rig', rig,
         '--pose2d-param', f'model.path:={model}', '--pose2d-param', 'model.threads:=1',
         '--pose2d-param', 'image_qos.reliability:=reliable', '--stop-timeout', '10'],
        log_path, cwd=ROOT, new_session=False)
    probe = Probe('bringup_probe', context=ros_context)
    node = probe.node
    persons = {c: probe.subscribe(Person2DArray, f'/{c}/persons_2d', reliable_qos())
               for c in CAMS}
    tracks = probe.subscribe(TrackedSkeletonArray, '/fusion_node/tracks', reliable_qos())
    # the default --image-topic, where mv3dpose_image_publisher --camera publishes
    pubs = probe.camera_publishers(Image, CAMS, '/{camera}/image_raw', reliable_qos(5))

    def spin_until(pred, timeout):
        return probe.spin_until(pred, timeout, processes=[proc], step=0.05)

    try:
        ready = spin_until(lambda: all(p.get_subscription_count() for p in pubs.values()) and
                           node.count_subscribers('/cam_a/persons_2d') >= 2, 60.0)
        assert ready, log_path.read_text()
        rng = np.random.default_rng(0)
        start = time.time_ns() - 2_000_000_000
        # Publish frame pairs until fusion has output: discovery between the child processes
        # may lag the probe's, and VOLATILE messages sent before matching are not delivered.
        for k in range(100):
            header = Header(stamp=ns_to_stamp(start + k * 20_000_000))
            for c in CAMS:
                header.frame_id = f'{c}_optical_frame'
                pubs[c].publish(numpy_to_image(
                    rng.integers(0, 255, (H, W, 3), dtype=np.uint8), header))
            spin_until(lambda: all(len(v) > k for v in persons.values()), 5.0)
            if len(tracks) >= 3:
                break
        assert spin_until(lambda: len(tracks) >= 3, 5.0), (
            log_path.read_text(), {c: len(v) for c, v in persons.items()}, len(tracks))
        assert all(m.camera_id == c for c in CAMS for m in persons[c])
        assert tracks[-1].header.frame_id == 'world'          # the rig YAML's world_frame
    finally:
        code = proc.interrupt(40)
        probe.close()
    text = log_path.read_text()
    assert code == 0, text
    assert 'all nodes stopped cleanly' in text
    pids = [int(p) for p in re.findall(r'started \S+ \(pid (\d+)\)', text)]
    assert len(pids) == 3
    for pid in pids:
        with pytest.raises(ProcessLookupError):
            os.kill(pid, 0)


def test_no_fusion_starts_the_pose2d_nodes_only(rig):
    res = bringup('--rig', rig, '--no-fusion', '--dry-run')
    assert res.returncode == 0, res.stderr
    started = [ln.split(':')[0] for ln in res.stdout.splitlines() if ln.startswith(('pose2d',
                                                                                    'fusion'))]
    assert started == [f'pose2d_node[{c}]' for c in CAMS]
    res = bringup('--rig', rig, '--no-fusion', '--no-pose2d', '--dry-run')
    assert res.returncode == 2 and 'start nothing' in res.stderr


def test_the_process_list_names_each_node_its_script_and_its_module(rig, tmp_path):
    plan = rig_processes(rig=rig, foxglove_port=8765, pose2d_params={'model.threads': 2})
    assert [p.name for p in plan.processes] == ['pose2d_node[cam_a]', 'pose2d_node[cam_b]',
                                                'fusion_node', 'foxglove_view']
    with open(os.path.join(ROOT, 'setup.py')) as f:
        scripts = dict(re.findall(r"'(\w+) = ([\w.]+):main'", f.read()))
    for p in plan.processes:
        assert scripts[p.executable] == p.module       # the console script runs that module
    cam_a = plan.processes[0]
    assert (cam_a.node, cam_a.namespace, cam_a.remaps) == (
        'pose2d_node', '/cam_a', (('image', '/cam_a/image_raw'),))
    assert cam_a.parameters == {'model.threads': 2, 'camera_id': 'cam_a'}
    fusion, view = plan.processes[2:]
    assert fusion.namespace == '' and fusion.params_key == '/**/fusion_node'
    assert fusion.parameters == {'rig_config': rig, 'camera_ids': list(CAMS),
                                 'input_topic': '/{camera}/persons_2d'}
    assert view.parameters['port'] == 8765 and plan.common == {}
    assert [p.name for p in rig_processes(rig=rig, pose2d=False).processes] == ['fusion_node']
    (only,) = rig_processes(rig=rig, cameras=['cam_b'], fusion=False).processes
    assert only.parameters['model.threads'] == split_threads(1)   # shipped threads: 0
    (tmp_path / 'empty.yaml').write_text('{}\n')
    with pytest.raises(PlanError, match='no rig: pass --rig'):
        rig_processes([str(tmp_path / 'empty.yaml')])


def test_bringup_starts_the_process_list(rig):
    args = build_parser().parse_args(['--rig', rig, '--foxglove', '--use-sim-time'])
    plan = Plan(args)
    listed = rig_processes(rig=rig, foxglove_port=8765, use_sim_time=True)
    commands = plan.commands('over.yaml')
    assert list(commands) == [p.name for p in listed.processes]
    for p in listed.processes:
        argv = commands[p.name]
        tail = argv[argv.index('--ros-args'):]
        assert tail == p.ros_args(listed.params_files + ['over.yaml'])
        assert argv[0].endswith(p.executable) or argv[:3] == [sys.executable, '-m', p.module]
        assert plan.overrides[p.params_key]['ros__parameters'] == yaml.safe_load(
            yaml.safe_dump(plan.overrides[p.params_key]['ros__parameters']))
    assert plan.overrides == listed.overrides()
    assert plan.overrides['/**']['ros__parameters'] == {'use_sim_time': True}


def _launch_stand_ins(monkeypatch):
    """Put minimal ``launch``/``launch_ros`` modules in place: actions as the plain values."""
    def module(name, **attrs):
        mod = types.ModuleType(name)
        mod.__dict__.update(attrs)
        monkeypatch.setitem(sys.modules, name, mod)

    class Configuration:
        def __init__(self, name):
            self.name = name

        def perform(self, context):
            return context[self.name]

    module('launch', LaunchDescription=list)
    module('launch.actions', OpaqueFunction=lambda function: function,
           DeclareLaunchArgument=lambda name, default_value, description: (
               name, default_value))
    module('launch.substitutions', LaunchConfiguration=Configuration)
    module('launch_ros')
    module('launch_ros.actions', Node=lambda **kwargs: kwargs)


def _load_launch_file():
    import importlib.util
    spec = importlib.util.spec_from_file_location('mv3dpose_launch', LAUNCH_FILE)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_the_launch_file_starts_the_process_list(rig, monkeypatch, tmp_path):
    _launch_stand_ins(monkeypatch)
    *arguments, nodes = _load_launch_file().generate_launch_description()
    context = dict(arguments)                    # every argument at its default
    context.update(rig=rig, foxglove_port='8765', use_sim_time='true')
    got = nodes(context)
    files = got[0]['parameters'][:2]             # the shipped ones, from the share directory
    assert [f.split(os.sep)[-2:] for f in files] == [['config', 'pose2d.yaml'],
                                                     ['config', 'fusion.yaml']]
    listed = rig_processes(files, rig, foxglove_port=8765, use_sim_time=True)
    assert got == [p.launch_kwargs(listed.params_files, {'use_sim_time': True})
                   for p in listed.processes]
    assert [n['name'] for n in got] == ['pose2d_node', 'pose2d_node', 'fusion_node',
                                        'foxglove_view']
    assert got[0]['namespace'] == '/cam_a' and 'namespace' not in got[2]
    assert got[0]['parameters'][-1] == {'model': {'threads': split_threads(2)},
                                        'camera_id': 'cam_a', 'use_sim_time': True}
    (tmp_path / 'empty.yaml').write_text('{}\n')
    context.update(rig='', fusion_params=str(tmp_path / 'empty.yaml'))
    with pytest.raises(RuntimeError, match='no rig: pass rig:='):
        nodes(context)


def test_the_installed_launch_description_starts_the_process_list(rig):
    pytest.importorskip('launch.actions')              # a full ROS install only
    pytest.importorskip('launch_ros.actions')
    from launch import LaunchContext
    description = _load_launch_file().generate_launch_description()
    context = LaunchContext()
    context.launch_configurations['rig'] = rig
    nodes = []
    for action in description.entities:       # the arguments take their defaults, then the nodes
        nodes += action.execute(context) or []
    listed = rig_processes(rig=rig).processes
    assert [(n.node_package, n.node_executable) for n in nodes] == [
        ('mv3dpose_ros', p.executable) for p in listed]


def test_bringup_shares_the_cores_among_the_cameras(capsys):
    from mv3dpose_ros.nodes import bringup
    assert [split_threads(n, 2) for n in (1, 2, 4)] == [2, 1, 1]
    assert [split_threads(n, 16) for n in (1, 3, 4, 8, 32)] == [16, 5, 4, 2, 1]
    rig = os.path.join(ROOT, 'config', 'rigs', 'panoptic_demo.yaml')
    cams = ['00_03', '00_06', '00_12', '00_13']
    assert bringup.main(['--rig', rig, '--cameras', *cams, '--dry-run']) == 0
    out = capsys.readouterr().out
    assert out.count(f'threads: {split_threads(4)}') == 4       # shipped threads: 0
    assert bringup.main(['--rig', rig, '--cameras', *cams, '--dry-run',
                         '--pose2d-param', 'model.threads:=3']) == 0
    assert capsys.readouterr().out.count('threads: 3') == 4              # explicit value kept
