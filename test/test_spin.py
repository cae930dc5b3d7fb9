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

"""A node stopped by Ctrl-C ends cleanly, also when the shutdown races a take; its exit status."""

import subprocess
import sys

from mv3dpose_ros.ros.spin import spin_until_shutdown
import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor


def test_a_take_failing_after_shutdown_is_the_normal_end():
    """The race of the CI run: SIGINT invalidates the context while a take is under way."""
    context = rclpy.Context()
    rclpy.init(context=context)
    executor = SingleThreadedExecutor(context=context)
    calls = []

    def take_during_shutdown(timeout_sec=None):
        calls.append(timeout_sec)
        context.try_shutdown()              # what rclpy's SIGINT handler does meanwhile
        raise RuntimeError('Unable to convert call argument 0 to Python object')
    executor.spin_once = take_during_shutdown
    spin_until_shutdown(executor)           # returns: the context is shut down
    assert len(calls) == 1


def test_an_error_while_running_still_propagates_and_until_stops():
    context = rclpy.Context()
    rclpy.init(context=context)
    executor = SingleThreadedExecutor(context=context)
    try:
        spins = []
        executor.spin_once = lambda timeout_sec=None: spins.append(timeout_sec)
        spin_until_shutdown(executor, lambda: len(spins) >= 3)
        assert spins == [0.1, 0.1, 0.1]
        spin_until_shutdown(executor, spins=2)
        assert len(spins) == 5

        def broken(timeout_sec=None):
            raise RuntimeError('a real bug')
        executor.spin_once = broken
        with pytest.raises(RuntimeError, match='a real bug'):
            spin_until_shutdown(executor)
    finally:
        context.try_shutdown()


RUN_NODE_CASES = r"""
import sys
import rclpy
from mv3dpose_ros.ros.spin import run_node


class Bad(Exception):
    pass


def make(overrides, fail=None):
    if fail:
        raise fail
    return rclpy.create_node('run_node_case')


def stop(node, executor):
    rclpy.try_shutdown()             # as Ctrl-C does


print('ok', run_node('case', make, ['prog'], spin=stop, hugepages=False))
print('config', run_node('case', lambda o: make(o, Bad('no rig')), ['prog'],
                         config_errors=(Bad,), hugepages=False))
print('usage', run_node('case', lambda o: make(o, ValueError(o)), ['prog', '--rate', 'x'],
                        parse_cli=lambda argv: ' '.join(argv), usage_errors=(ValueError,),
                        hugepages=False))
print('not started', run_node('case', make, ['prog'], not_started=lambda node: 'no model',
                              hugepages=False))
sys.stdout.flush()
run_node('case', make, ['prog'], spin=stop, stuck=lambda node: 'a thread is stuck',
         hugepages=False)
print('not reached')
"""


def test_the_node_main_exit_statuses_and_what_they_say():
    """run_node: 0 on a stop, 2 on a bad configuration or value, 1 when not started."""
    res = subprocess.run([sys.executable, '-c', RUN_NODE_CASES], capture_output=True,
                         text=True, timeout=120)
    assert res.stdout.splitlines() == ['ok 0', 'config 2', 'usage 2', 'not started 1'], (
        res.stdout + res.stderr)
    assert res.returncode == 0                       # os._exit with the status so far
    assert '[FATAL]' in res.stderr and 'cannot start: no rig' in res.stderr
    assert 'case: error: --rate x' in res.stderr
    assert 'not started: no model' in res.stderr
    assert res.stderr.rstrip().endswith('[case] a thread is stuck')
