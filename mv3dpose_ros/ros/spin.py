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

"""Spinning a node's executor until the process is asked to stop; the ``main`` of every node."""

import os
import sys
from typing import Any, Callable, List, Optional, Tuple, Type

from mv3dpose_ros.ros.system.memory import reexec_with_hugepages
import rclpy
from rclpy.executors import Executor, ExternalShutdownException, SingleThreadedExecutor


def spin_until_shutdown(executor: Executor, until: Optional[Callable[[], bool]] = None,
                        spins: Optional[int] = None) -> None:
    """
    Spin ``executor`` until Ctrl-C or SIGTERM shuts its context down.

    Or until ``until()`` is true, or ``spins`` times (0.1 s each at most).

    rclpy's signal handler shuts the context down from outside the executor, which may be
    taking a message just then; the take then raises (``RCLError``, or pybind11's
    ``RuntimeError: Unable to convert call argument``) instead of
    ``ExternalShutdownException``, and a node stopped by Ctrl-C exited 1 with a traceback.
    Once the context is shut down any exception is that normal end; before, it propagates.
    """
    done = 0
    try:
        while executor.context.ok() and not (until is not None and until()) and (
                spins is None or done < spins):
            executor.spin_once(timeout_sec=0.1)
            done += 1
    except ExternalShutdownException:
        return
    except Exception:  # noqa: B902 - re-raised unless the context was shut down meanwhile
        if executor.context.ok():
            raise


def run_node(prog: str, make_node: Callable[[Any], Any], args: Optional[List[str]] = None, *,
             parse_cli: Optional[Callable[[List[str]], Any]] = None,
             spin: Optional[Callable[[Any, Executor], None]] = None,
             usage_errors: Tuple[Type[BaseException], ...] = (),
             config_errors: Tuple[Type[BaseException], ...] = (),
             not_started: Optional[Callable[[Any], Optional[str]]] = None,
             stuck: Optional[Callable[[Any], str]] = None, hugepages: bool = True) -> int:
    """
    Run one node until Ctrl-C or SIGTERM (or until ``spin`` returns); return the exit status.

    The ``main`` of every node. ``args`` None is a console script's run: ``sys.argv``, and,
    with ``hugepages``, the process first re-executes itself with huge-page friendly malloc
    settings (ros/system/memory.py). ``make_node`` builds the node from what ``parse_cli`` makes of
    the arguments that are not ROS arguments (no ``parse_cli``: ``[]``); ``spin(node,
    executor)`` runs it (default: ``spin_until_shutdown``). Exit status:

    - 2: ``config_errors`` raised while building the node, logged FATAL as ``cannot start:
      ...`` on the ``prog`` logger; ``usage_errors`` raised while building or running it, printed
      ``prog: error: ...`` on stderr (a bad command-line value);
    - 1: ``not_started(node)`` gives a reason (not None) why the node was built but did not
      start, logged FATAL as ``not started: ...`` on the node's logger;
    - 0 otherwise, Ctrl-C and SIGTERM included.

    After the shutdown ``stuck(node)`` may name a thread still inside native code: the process
    then says so and ends with ``os._exit``, since the C++ destructors of a normal exit could
    hang under that thread until SIGKILL.
    """
    if args is None and hugepages:
        reexec_with_hugepages()         # 6 MB images with 2 MiB page faults (ros/system/memory.py)
    argv = sys.argv if args is None else args
    rclpy.init(args=argv)
    node = executor = None
    code = 0
    try:
        try:
            node = make_node(parse_cli(rclpy.utilities.remove_ros_args(argv)[1:])
                             if parse_cli is not None else [])
        except config_errors as exc:
            rclpy.logging.get_logger(prog).fatal(f'cannot start: {exc}')
            code = 2
        reason = not_started(node) if node is not None and not_started is not None else None
        if reason is not None:
            node.get_logger().fatal(f'not started: {reason}')
            code = 1
        elif node is not None:
            executor = SingleThreadedExecutor()
            executor.add_node(node)
            if spin is None:
                spin_until_shutdown(executor)
            else:
                spin(node, executor)
    except usage_errors as exc:
        print(f'{prog}: error: {exc}', file=sys.stderr)
        code = 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if executor is not None:
            executor.shutdown()
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    why = stuck(node) if node is not None and stuck is not None else ''
    if why:
        print(f'[{prog}] {why}', file=sys.stderr, flush=True)
        sys.stdout.flush()
        os._exit(code)
    return code
