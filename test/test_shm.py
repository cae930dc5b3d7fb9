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

"""Fast DDS shared memory of processes that are gone: found by its free locks, removed."""

import fcntl
import os
import signal
import subprocess
import sys
import time

from mv3dpose_ros.ros.system.shm import clean_stale_files, is_locked, SHM_DIR, stale_files
from mv3dpose_ros.ros.system.shm import uses_fast_dds
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PROFILE = os.path.join(ROOT, 'config', 'fastdds_shm.xml')


def _touch(path, size=0, age_s=60.0):
    with open(path, 'wb') as f:
        f.truncate(size)
    old = time.time() - age_s
    os.utime(path, (old, old))
    return str(path)


def test_only_files_whose_lock_nobody_holds_are_stale(tmp_path):
    dead = 'fastrtps_0123456789abcdef'
    alive = 'fastrtps_fedcba9876543210'
    young = 'fastrtps_00000000000000aa'
    for name in (dead, alive, young):
        _touch(tmp_path / name, 1000)
    _touch(tmp_path / f'{dead}_el')
    _touch(tmp_path / f'{alive}_el')
    _touch(tmp_path / f'{young}_el', age_s=1.0)       # just created: its owner may lock it next
    _touch(tmp_path / 'fastrtps_port7411')
    _touch(tmp_path / 'fastrtps_port7411_sl')
    _touch(tmp_path / 'sem.fastrtps_port7411_mutex', 32)
    _touch(tmp_path / 'fastrtps_port7413')                  # no lock file: cannot tell, kept
    _touch(tmp_path / 'fastrtps_port7415')                  # one of its two locks is held
    _touch(tmp_path / 'fastrtps_port7415_el')
    _touch(tmp_path / 'fastrtps_port7415_sl')
    _touch(tmp_path / 'lttng-ust-wait-8')
    holder = open(tmp_path / f'{alive}_el', 'rb')       # another open file: a live owner
    sharer = open(tmp_path / 'fastrtps_port7415_sl', 'rb')
    try:
        fcntl.flock(holder, fcntl.LOCK_EX | fcntl.LOCK_NB)
        fcntl.flock(sharer, fcntl.LOCK_SH | fcntl.LOCK_NB)
        assert is_locked(str(tmp_path / f'{alive}_el'))
        assert not is_locked(str(tmp_path / f'{dead}_el'))
        assert sorted(os.path.basename(p) for p in stale_files(str(tmp_path))) == sorted([
            dead, f'{dead}_el', 'fastrtps_port7411', 'fastrtps_port7411_sl',
            'sem.fastrtps_port7411_mutex'])
        assert clean_stale_files(str(tmp_path)) == (5, 1032)
        assert sorted(os.listdir(tmp_path)) == sorted([
            alive, f'{alive}_el', young, f'{young}_el', 'fastrtps_port7413',
            'fastrtps_port7415', 'fastrtps_port7415_el', 'fastrtps_port7415_sl',
            'lttng-ust-wait-8'])
        assert is_locked(str(tmp_path / f'{alive}_el'))      # the probe left the lock alone
    finally:
        holder.close()
        sharer.close()
    assert sorted(os.path.basename(p) for p in stale_files(str(tmp_path))) == sorted([
        alive, f'{alive}_el', 'fastrtps_port7415', 'fastrtps_port7415_el',
        'fastrtps_port7415_sl', 'sem.fastrtps_port7415_mutex'])
    assert clean_stale_files(str(tmp_path / 'missing')) == (0, 0)
    assert not is_locked(str(tmp_path / 'missing_el'))
    _touch(tmp_path / 'plain')
    assert is_locked(str(tmp_path / 'plain' / 'x_el'))     # cannot be opened: kept


def test_fast_dds_is_the_rmw_unless_another_is_chosen():
    assert uses_fast_dds({})
    assert uses_fast_dds({'RMW_IMPLEMENTATION': 'rmw_fastrtps_cpp'})
    assert not uses_fast_dds({'RMW_IMPLEMENTATION': 'rmw_cyclonedds_cpp'})


@pytest.mark.skipif(not os.path.isdir(SHM_DIR), reason='no /dev/shm')
def test_a_killed_ros_process_leaves_a_segment_that_is_found_stale():
    """A real rclpy process: its segment is locked while it lives and stale once SIGKILLed."""
    def locks():
        return {n for n in os.listdir(SHM_DIR) if n.startswith('fastrtps_') and
                n.endswith('_el') and not n.startswith('fastrtps_port')}

    before = locks()
    env = dict(os.environ, FASTRTPS_DEFAULT_PROFILES_FILE=PROFILE, RMW_IMPLEMENTATION='')
    code = ('import rclpy, sys, time; from std_msgs.msg import String; rclpy.init(); '
            'n = rclpy.create_node("shm_probe"); p = n.create_publisher(String, "shm_probe", 1); '
            'print("up", flush=True); time.sleep(60)')
    proc = subprocess.Popen([sys.executable, '-c', code], env=env, stdout=subprocess.PIPE,
                            text=True)
    try:
        assert proc.stdout.readline().strip() == 'up'
        deadline = time.monotonic() + 10.0
        while not (locks() - before) and time.monotonic() < deadline:
            time.sleep(0.1)
        mine = locks() - before
        assert mine, 'the process created no shared-memory segment'
        assert all(is_locked(os.path.join(SHM_DIR, n)) for n in mine)
        stale = set(stale_files(min_age_s=0.0))
        assert not {os.path.join(SHM_DIR, n) for n in mine} & stale
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)
        gone = [n for n in mine if not is_locked(os.path.join(SHM_DIR, n))]
        assert gone, 'a killed process still holds its segment lock'
        stale = set(stale_files(min_age_s=0.0))
        for name in gone:
            assert os.path.join(SHM_DIR, name) in stale
            assert os.path.join(SHM_DIR, name[:-3]) in stale
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.wait(timeout=10)
        for name in locks() - before:
            if not is_locked(os.path.join(SHM_DIR, name)):
                for path in (os.path.join(SHM_DIR, name), os.path.join(SHM_DIR, name[:-3])):
                    try:
                        os.remove(path)
                    except OSError:
                        pass
