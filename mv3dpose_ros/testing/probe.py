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
An in-process probe node: what a test or benchmark feeds a node under test and records of it.

A ``Probe`` is one rclpy node with its executor (in a context of its own unless given one):
``subscribe`` records messages with their arrival times, ``camera_publishers`` makes one
publisher per camera, ``spin_until`` spins until something came (failing fast when a watched
node process died). ``start_spinning`` spins it in a thread instead, for a probe that must
receive while the caller publishes or sleeps.
"""

import threading
import time
from typing import Callable, Dict, Iterable, Optional, Sequence

from mv3dpose_ros.ros.names import camera_topic
from mv3dpose_ros.ros.qos import reliable_qos
from mv3dpose_ros.ros.subscribers import unsubscribed
from mv3dpose_ros.testing import spin
import rclpy
from rclpy.executors import SingleThreadedExecutor


class Received(list):
    """Messages in arrival order; ``arrivals`` holds each one's receipt time (ns since epoch)."""

    def __init__(self) -> None:
        """Start empty."""
        super().__init__()
        self.arrivals = []

    def __call__(self, msg) -> None:
        """Record ``msg`` (a subscription callback)."""
        self.arrivals.append(time.time_ns())
        self.append(msg)

    def clear(self) -> None:
        """Forget the messages and their arrival times."""
        super().clear()
        self.arrivals.clear()


class Probe:
    """One rclpy node and its executor, with the nodes under test (``nodes``) added to it."""

    def __init__(self, name: str = 'probe', context: Optional[rclpy.Context] = None,
                 nodes: Sequence = ()) -> None:
        """Create the node in ``context`` (a new one, shut down by ``close``, when None)."""
        self.own_context = context is None
        if context is None:
            context = rclpy.Context()
            rclpy.init(context=context)
        self.context = context
        self.node = rclpy.create_node(name, context=context)
        self.executor = SingleThreadedExecutor(context=context)
        for n in (self.node, *nodes):
            self.executor.add_node(n)
        self.lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: Optional[threading.Thread] = None

    def subscribe(self, msg_type, topic: str, qos=None, raw: bool = False,
                  callback: Optional[Callable] = None) -> Received:
        """Record every message on ``topic`` (``qos``: reliable, depth 100 by default)."""
        received = Received()

        def on_message(msg) -> None:
            with self.lock:
                received(msg)
            if callback is not None:
                callback(msg)

        self.node.create_subscription(msg_type, topic, on_message,
                                      reliable_qos(100) if qos is None else qos, raw=raw)
        return received

    def camera_publishers(self, msg_type, cameras: Iterable[str],
                          pattern: str = '/{camera}/persons_2d', qos=None) -> Dict[str, object]:
        """Return one publisher per camera on ``pattern`` (``{camera}``: its ROS name)."""
        qos = reliable_qos(100) if qos is None else qos
        return {c: self.node.create_publisher(msg_type, camera_topic(pattern, c), qos)
                for c in cameras}

    def spin_until(self, predicate: Callable[[], bool], timeout: float = 10.0,
                   processes: Sequence = (), step: float = 0.02) -> bool:
        """Spin until ``predicate()`` holds (see ``testing.spin.spin_until``)."""
        return spin.spin_until(self.executor, predicate, timeout, processes, step)

    def spin_for(self, seconds: float) -> None:
        """Spin for ``seconds``."""
        spin.spin_for(self.executor, seconds)

    def start_spinning(self) -> None:
        """Spin the executor in a daemon thread until ``close`` (callbacks under ``lock``)."""
        def run() -> None:
            while not self._stop.is_set() and self.context.ok():
                self.executor.spin_once(timeout_sec=0.05)

        self._thread = threading.Thread(target=run, name=f'{self.node.get_name()}_spin',
                                        daemon=True)
        self._thread.start()

    def close(self) -> None:
        """Stop spinning, destroy the node, and shut down the context if it is the probe's."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        self.executor.shutdown()
        self.node.destroy_node()
        if self.own_context:
            self.context.try_shutdown()


def all_matched(publishers: Iterable) -> bool:
    """Return whether every publisher has a subscriber (the node under test listens)."""
    return not unsubscribed(publishers)


def latest_status(arrays: Iterable) -> Dict[str, object]:
    """Return the latest ``DiagnosticStatus`` of each name in ``DiagnosticArray`` messages."""
    last = {}
    for arr in arrays:
        for st in arr.status:
            last[st.name] = st
    return last


def diagnostics_text(arrays: Iterable) -> str:
    """Return one line per status name, its latest message and values (failure messages)."""
    return '\n'.join(f'{name}: {st.message} ' + ', '.join(f'{kv.key}={kv.value}'
                                                          for kv in st.values)
                     for name, st in sorted(latest_status(arrays).items()))
