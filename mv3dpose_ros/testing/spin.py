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

"""Spinning a test's executor until something happened, failing fast when a node process died."""

import subprocess
import time
from typing import Callable, Sequence, Union

from mv3dpose_ros.testing.processes import check_alive, NodeProcess
from rclpy.executors import Executor


def spin_until(executor: Executor, predicate: Callable[[], bool], timeout: float = 10.0,
               processes: Sequence[Union[NodeProcess, subprocess.Popen]] = (),
               step: float = 0.02) -> bool:
    """
    Spin ``executor`` until ``predicate()`` holds or ``timeout`` seconds pass; return it.

    A process of ``processes`` that exits meanwhile raises ``ProcessDied`` with its log at
    once, instead of a timeout that says only that nothing came.
    """
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        executor.spin_once(timeout_sec=step)
        check_alive(processes)
    return bool(predicate())


def spin_for(executor: Executor, seconds: float, step: float = 0.01) -> None:
    """Spin ``executor`` for ``seconds`` (callbacks run as they come)."""
    deadline = time.monotonic() + seconds
    while True:
        left = deadline - time.monotonic()
        if left <= 0:
            return
        executor.spin_once(timeout_sec=min(left, step))
