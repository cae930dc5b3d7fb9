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

"""A node stopped by Ctrl-C ends cleanly even when the shutdown races a message take."""

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
