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
What ``bag play`` waits for, and which interrupted recordings ``bag record`` warns about.

``play --wait-for-subscribers`` waits for the played topics of the message types the pipeline
subscribes to (``ros.subscribers``), says what it waits for, and names at a timeout the topics
never subscribed; ``record`` and ``recover`` count a partial folder as left by a dead writer
only when its writer's lock is free (never the recorder's own, never a live process's).
"""

import os
import shutil
import subprocess
import sys
import time

from mv3dpose_ros.commands.bag import recover
from mv3dpose_ros.io.bag import BagError, BagWriter, get_typestore, make_qos, partial_dirs
from mv3dpose_ros.io.bag import writer_alive
from mv3dpose_ros.ros.subscribers import awaited, SETTLE_S
from mv3dpose_ros.testing.spin import spin_until
import pytest

MV3DPOSE = [sys.executable, '-m', 'mv3dpose_ros.cli']

# A writer that checkpoints one message, prints its PID, then dies by SIGKILL ('die') or waits
# for its stdin to close ('live').
_WRITER = """
import os, signal, sys
from mv3dpose_ros.io.bag import BagWriter, get_typestore, make_qos
w = BagWriter(sys.argv[1])
w.add_topic('/chatter', 'std_msgs/msg/String', [make_qos()])
w.write_msg('/chatter', 1, get_typestore().types['std_msgs/msg/String'](data='m'),
            'std_msgs/msg/String')
w.checkpoint()
print(os.getpid(), flush=True)
if sys.argv[2] == 'die':
    os.kill(os.getpid(), signal.SIGKILL)
sys.stdin.read()
"""


def _dead_writer(target) -> int:
    """Leave a SIGKILLed writer's partial folder of ``target``; return the writer's PID."""
    proc = subprocess.run([sys.executable, '-c', _WRITER, str(target), 'die'],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == -9, proc.stderr
    return int(proc.stdout.split()[0])


def _two_topic_bag(path, n=5):
    """``/seen`` (String) and ``/ignored`` (Float64), ``n`` messages each, 10 ms apart."""
    ts = get_typestore()
    string, number = ts.types['std_msgs/msg/String'], ts.types['std_msgs/msg/Float64']
    t0 = 1_700_000_000 * 10 ** 9
    with BagWriter(path) as w:
        for topic, msgtype in (('/seen', 'std_msgs/msg/String'),
                               ('/ignored', 'std_msgs/msg/Float64')):
            w.add_topic(topic, msgtype, [make_qos(reliable=True, depth=10)])
        for i in range(n):
            w.write_msg('/seen', t0 + 20_000_000 * i, string(data=f'm{i}'),
                        'std_msgs/msg/String')
            w.write_msg('/ignored', t0 + 20_000_000 * i + 10_000_000, number(data=float(i)),
                        'std_msgs/msg/Float64')


# ------------------------------------------------------------------------------ no DDS

def test_the_wait_rule_goes_by_message_type_or_by_name():
    types = {'/a/image_raw': 'sensor_msgs/msg/Image', '/b/image_raw': 'sensor_msgs/msg/Image',
             '/a/camera_info': 'sensor_msgs/msg/CameraInfo',
             '/b/camera_info': 'sensor_msgs/msg/CameraInfo'}
    assert awaited(types, []) == []
    # one camera's images subscribed: every camera's images are waited for, no camera_info
    assert awaited(types, ['/a/image_raw']) == ['/a/image_raw', '/b/image_raw']
    assert awaited(types, ['/b/camera_info', '/a/image_raw']) == list(types)
    assert awaited(types, ['/a/image_raw'], named=['/b/camera_info']) == ['/b/camera_info']


def test_partial_folders_count_as_dead_only_when_their_writer_is_gone(tmp_path):
    target = tmp_path / 'x.bag'
    own = BagWriter(target)
    live = None
    try:
        assert partial_dirs(target) == [], 'this process is writing its own'
        dead = tmp_path / f'.x.bag.partial-{_dead_writer(target)}'
        # the dead writer's PID now taken by a live process (pytest's parent): dead all the same
        reused = tmp_path / f'.x.bag.partial-{os.getppid()}'
        shutil.copytree(dead, reused)
        live = subprocess.Popen([sys.executable, '-c', _WRITER, str(target), 'live'],
                                stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        running = tmp_path / f'.x.bag.partial-{int(live.stdout.readline())}'
        assert running.is_dir() and writer_alive(running)
        assert set(partial_dirs(target)) == {dead, reused}
        with pytest.raises(BagError, match='still recording'):
            recover(str(running))
    finally:
        if live is not None:
            live.stdin.close()
            live.wait(timeout=30)
        own.abort()


def test_wait_topics_must_be_played(tmp_path):
    _two_topic_bag(tmp_path / 'bag', n=1)
    proc = subprocess.run(MV3DPOSE + ['bag', 'play', str(tmp_path / 'bag'), '--topics', '/seen',
                                      '--wait-topics', '/ignored'],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 1 and '--wait-topics /ignored: not played' in proc.stderr


# ------------------------------------------------------------------------------ DDS

@pytest.mark.ros
@pytest.mark.timeout(180)
def test_record_warns_only_about_recordings_of_dead_writers(tmp_path):
    def record(out):
        proc = subprocess.Popen(MV3DPOSE + ['bag', 'record', '/fusion_node/tracks', '-o',
                                            str(out), '--duration', '2'],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        _, err = proc.communicate(timeout=120)
        assert proc.returncode == 0, err
        assert out.is_dir() and not (out.parent / f'.{out.name}.partial-{proc.pid}').exists()
        return proc.pid, err

    (tmp_path / 'empty').mkdir()
    pid, err = record(tmp_path / 'empty' / 'x.bag')
    assert 'interrupted' not in err and f'partial-{pid}' not in err, err

    dead = _dead_writer(tmp_path / 'run.bag')
    pid, err = record(tmp_path / 'run.bag')
    assert 'interrupted recording' in err and f'.run.bag.partial-{dead}' in err, err
    assert f'partial-{pid}' not in err, err
    assert (tmp_path / f'.run.bag.partial-{dead}').is_dir()   # left for `bag recover`


@pytest.mark.ros
@pytest.mark.timeout(180)
def test_play_starts_soon_after_the_subscriber_and_names_the_topic_nobody_reads(
        ros_context, tmp_path):
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    from std_msgs.msg import String

    _two_topic_bag(tmp_path / 'bag')
    err_path = tmp_path / 'player.err'
    with open(err_path, 'w') as err_file:
        player = subprocess.Popen(MV3DPOSE + ['bag', 'play', str(tmp_path / 'bag'), '--rate',
                                              '0', '--wait-for-subscribers', '120'],
                                  stdout=subprocess.PIPE, stderr=err_file, text=True)
    node = None
    try:
        # the player is in its wait once it says so (about 1.5 s in): then subscribe
        deadline = time.monotonic() + 90
        while time.monotonic() < deadline and 'waiting up to' not in err_path.read_text():
            assert player.poll() is None, err_path.read_text()
            time.sleep(0.1)
        note = err_path.read_text()
        assert 'no subscriber yet on any of the 2 topics' in note and '/ignored' in note, note
        assert '--wait-topics' in note and 'Ctrl-C' in note, note
        node = Node('bag_wait_listener', context=ros_context)
        got = []
        qos = QoSProfile(depth=100, history=HistoryPolicy.KEEP_LAST,
                         reliability=ReliabilityPolicy.RELIABLE)
        subscribed_at = time.monotonic()
        node.create_subscription(String, '/seen', lambda m: got.append(
            (time.monotonic(), m.data)), qos)
        executor = SingleThreadedExecutor(context=ros_context)
        executor.add_node(node)
        assert spin_until(executor, lambda: len(got) >= 5, timeout=60), \
            f'{len(got)} messages; player: {err_path.read_text()}'
        out, _ = player.communicate(timeout=30)
    finally:
        if player.poll() is None:
            player.kill()
            player.wait()
        if node is not None:
            node.destroy_node()
    err = err_path.read_text()
    assert player.returncode == 0, err
    assert [d for _, d in got] == [f'm{i}' for i in range(5)]
    delay = got[0][0] - subscribed_at
    assert delay < SETTLE_S + 4.0, f'first message {delay:.1f} s after subscribing; {err}'
    assert 'not waiting for /ignored (no subscriber on any topic of their type)' in err, err
    assert 'played 10 messages' in out


@pytest.mark.ros
@pytest.mark.timeout(120)
def test_play_names_the_topics_never_subscribed_at_the_timeout(tmp_path):
    _two_topic_bag(tmp_path / 'bag', n=1)
    t0 = time.monotonic()
    proc = subprocess.run(MV3DPOSE + ['bag', 'play', str(tmp_path / 'bag'),
                                      '--wait-for-subscribers', '2'],
                          capture_output=True, text=True, timeout=100)
    assert proc.returncode == 0, proc.stderr
    [line] = [x for x in proc.stderr.splitlines() if 'going on without them' in x]
    assert line in ('bag play: no subscriber on /ignored, /seen after 2 s; going on without them',
                    'bag play: no subscriber on /seen, /ignored after 2 s; going on without them')
    assert 'played 2 messages' in proc.stdout and time.monotonic() - t0 >= 2.0
