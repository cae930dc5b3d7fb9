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

"""Spinning a node's executor until the process is asked to stop; a node's command line."""

import sys
from typing import Any, Callable, List, Optional, Tuple, Type

from mv3dpose_ros.ros.memory import reexec_with_hugepages
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


def run_cli_node(prog: str, make_node: Callable[[List[Any]], Any],
                 parse_cli: Callable[[List[str]], List[Any]], args: Optional[List[str]],
                 spin: Optional[Callable[[Any, Executor], None]] = None,
                 errors: Tuple[Type[BaseException], ...] = (ValueError,)) -> int:
    """
    Run a node whose parameters come from its own command line until Ctrl-C; return the status.

    ``make_node(overrides)`` builds it from ``parse_cli``'s parameter overrides; ``spin(node,
    executor)`` runs it (default: ``spin_until_shutdown``). A bad value (``errors``) prints
    ``prog: error: ...`` and returns 2. Run as a console script (``args`` None), the process
    first re-executes itself with huge-page friendly malloc settings (ros/memory.py).
    """
    if args is None:
        reexec_with_hugepages()         # 6 MB images with 2 MiB page faults (ros/memory.py)
    argv = sys.argv if args is None else args
    rclpy.init(args=argv)
    node = None
    try:
        node = make_node(parse_cli(rclpy.utilities.remove_ros_args(argv)[1:]))
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        if spin is None:
            spin_until_shutdown(executor)
        else:
            spin(node, executor)
    except errors as exc:
        print(f'{prog}: error: {exc}', file=sys.stderr)
        return 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0
