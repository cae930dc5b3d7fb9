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
A probe on another host: a process that writes what it receives as JSON lines, and its reader.

A test's own rclpy participant lives in the test's network namespace; a probe of a namespaced
host (``testing.netns``) must run in that host's namespace, so it is a process of its own:
``python -m mv3dpose_ros.testing.remote_probe OUT.jsonl [--tracks] [--diagnostics]
[--sizes TOPIC ...]`` writes one line per message as it arrives (flushed), and ``Recording``
reads the file while it grows. Lines (``t``: arrival, ns since the epoch; ``stamp``: header
stamp, ns; ``bytes``: serialized size):

- ``{"k": "tracks", "t", "stamp", "bytes", "skeletons": [[id, state, x, y, z, [cameras]]]}``
- ``{"k": "diag", "t", "name", "level", "message", "values": {key: value}}`` per status
- ``{"k": "size", "t", "topic", "bytes"}`` for each message of a ``--sizes`` topic
"""

import argparse
import importlib
import json
import os
import sys
import time
from typing import Callable, Dict, List, Optional

NS_PER_S = 1_000_000_000


def cameras_of(messages: List[dict]) -> set:
    """Return the cameras behind the skeletons of recorded tracks messages."""
    return {c for m in messages for s in m['skeletons'] for c in s[5]}


class Recording:
    """The lines a remote probe wrote so far (``poll`` reads the new ones)."""

    def __init__(self, path: str) -> None:
        """Read ``path`` (it may not exist yet)."""
        self.path = path
        self.tracks: List[dict] = []
        self.diag: List[dict] = []
        self.sizes: List[dict] = []
        self._offset = 0

    def poll(self) -> 'Recording':
        """Read the complete lines written since the last call."""
        if not os.path.exists(self.path):
            return self
        with open(self.path, encoding='utf-8') as f:
            f.seek(self._offset)
            chunk = f.read()
        end = chunk.rfind('\n') + 1
        self._offset += len(chunk[:end].encode('utf-8'))
        for line in chunk[:end].splitlines():
            rec = json.loads(line)
            {'tracks': self.tracks, 'diag': self.diag, 'size': self.sizes}[rec['k']].append(rec)
        return self

    def wait(self, predicate: Callable[[], bool], timeout: float, procs=()) -> bool:
        """Poll until ``predicate()`` or ``timeout`` s; a watched process that died raises."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            self.poll()
            if predicate():
                return True
            for p in procs:
                p.check()
            time.sleep(0.2)
        return False

    def status(self, suffix: str, since_ns: int = 0, until_ns: Optional[int] = None
               ) -> List[dict]:
        """Return the statuses whose name ends with ``suffix`` that arrived in the window."""
        return [d for d in self.diag if d['name'].endswith(suffix) and since_ns <= d['t']
                and (until_ns is None or d['t'] <= until_ns)]

    def tracks_between(self, since_ns: int, until_ns: Optional[int] = None) -> List[dict]:
        """Return the tracks messages that arrived in the window."""
        return [m for m in self.tracks
                if since_ns <= m['t'] and (until_ns is None or m['t'] <= until_ns)]


def main(argv: Optional[List[str]] = None) -> int:
    """Record until SIGINT / SIGTERM."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('out')
    parser.add_argument('--tracks', action='store_true', help='record /fusion_node/tracks')
    parser.add_argument('--diagnostics', action='store_true', help='record /diagnostics')
    parser.add_argument('--sizes', nargs='*', default=[], metavar='TOPIC',
                        help='record the serialized size of every message of these topics')
    parser.add_argument('--type', action='append', default=[], metavar='TOPIC=PKG/msg/TYPE',
                        help='message type of a --sizes topic (default: Person2DArray)')
    args = parser.parse_args(argv)

    import signal

    from diagnostic_msgs.msg import DiagnosticArray
    from mv3dpose_msgs.msg import Person2DArray, TrackedSkeletonArray
    from mv3dpose_ros.ros.qos import reliable_qos
    import rclpy
    from rclpy.qos import qos_profile_sensor_data
    from rclpy.serialization import deserialize_message

    rclpy.init()
    node = rclpy.create_node('remote_probe')
    out = open(args.out, 'w', buffering=1, encoding='utf-8')

    def write(rec: Dict) -> None:
        out.write(json.dumps(rec, separators=(',', ':')) + '\n')

    def stamp(h) -> int:
        return h.stamp.sec * NS_PER_S + h.stamp.nanosec

    def on_tracks(data: bytes) -> None:
        t = time.time_ns()
        msg = deserialize_message(data, TrackedSkeletonArray)
        write({'k': 'tracks', 't': t, 'stamp': stamp(msg.header), 'bytes': len(data),
               'skeletons': [[int(s.track_id), int(s.state), round(s.position.x, 3),
                              round(s.position.y, 3), round(s.position.z, 3),
                              list(s.source_cameras)] for s in msg.skeletons]})

    def on_diag(msg) -> None:
        t = time.time_ns()
        for st in msg.status:
            write({'k': 'diag', 't': t, 'name': st.name, 'level': int.from_bytes(st.level, 'big')
                   if isinstance(st.level, bytes) else int(st.level), 'message': st.message,
                   'values': {kv.key: kv.value for kv in st.values}})

    if args.tracks:
        node.create_subscription(TrackedSkeletonArray, '/fusion_node/tracks', on_tracks,
                                 reliable_qos(50), raw=True)
    if args.diagnostics:
        node.create_subscription(DiagnosticArray, '/diagnostics', on_diag, reliable_qos(50))
    types = dict(t.split('=', 1) for t in args.type)
    for topic in args.sizes:
        msg_type = Person2DArray
        if topic in types:                              # pkg/msg/Type
            pkg, _, name = types[topic].split('/')
            msg_type = getattr(importlib.import_module(f'{pkg}.msg'), name)
        node.create_subscription(
            msg_type, topic, lambda data, tp=topic: write(
                {'k': 'size', 't': time.time_ns(), 'topic': tp, 'bytes': len(data)}),
            qos_profile_sensor_data, raw=True)

    stop = []
    signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
    try:
        while not stop and rclpy.ok():
            rclpy.spin_once(node, timeout_sec=0.1)
    except KeyboardInterrupt:
        pass
    finally:
        out.close()
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
