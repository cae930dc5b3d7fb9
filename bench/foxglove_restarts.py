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
Restart ``foxglove_view`` with clients already waiting, as Foxglove's auto-reconnect does.

Each start: ``--clients`` clients knock on the port before the view starts, connect the moment
it accepts and subscribe to each channel as it is advertised; ``--busy`` processes load the
CPU meanwhile. Printed: per start, the advertisements the first client saw, refused
subscriptions and channels never advertised; then the totals::

    python bench/foxglove_restarts.py --starts 20 --clients 4 --busy 2
"""

import argparse
import asyncio
import os
import signal
import socket
import subprocess
import sys
import tempfile
from typing import List

from mv3dpose_ros.io.foxglove_ws import StartupWatch, watch_startup

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RIG = os.path.join(ROOT, 'config', 'rigs', 'pose2sim_multiperson.yaml')
BUSY = 'import time\nend = time.monotonic() + {s}\nwhile time.monotonic() < end: pass\n'


def free_port() -> int:
    """Return a TCP port free on loopback now."""
    with socket.socket() as s:
        s.bind(('127.0.0.1', 0))
        return s.getsockname()[1]


def start_with_waiting_clients(clients: int, log_path: str, seconds: float = 4.0,
                               rig: str = RIG) -> List[StartupWatch]:
    """Start the view while ``clients`` wait for it; return what each one saw."""
    port = free_port()

    async def run() -> List[StartupWatch]:
        watches = [asyncio.create_task(watch_startup(f'ws://127.0.0.1:{port}', seconds, 90.0))
                   for _ in range(clients)]
        await asyncio.sleep(0.2)              # the clients knock before the view starts
        with open(log_path, 'w') as log:
            proc = subprocess.Popen(['mv3dpose_foxglove_view', '--port', str(port), '--rig',
                                     rig], stdout=log, stderr=subprocess.STDOUT,
                                    start_new_session=True)
            try:
                return await asyncio.gather(*watches)
            finally:
                proc.send_signal(signal.SIGINT)
                try:
                    code = proc.wait(10)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    code = proc.wait()
                if code != 0:
                    raise RuntimeError(f'foxglove_view exited {code}: see {log_path}')
    return asyncio.run(run())


def busy_processes(count: int, seconds: float) -> List[subprocess.Popen]:
    """Start ``count`` processes that spin a core each for ``seconds``."""
    return [subprocess.Popen([sys.executable, '-c', BUSY.format(s=seconds)])
            for _ in range(count)]


def main() -> int:
    """Run the restarts and print what was lost."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--starts', type=int, default=20)
    parser.add_argument('--clients', type=int, default=4)
    parser.add_argument('--busy', type=int, default=2, help='CPU-spinning processes')
    args = parser.parse_args()
    busy = busy_processes(args.busy, 3600)
    lost = refused = split = 0
    try:
        with tempfile.TemporaryDirectory() as tmp:
            for start in range(args.starts):
                watches = start_with_waiting_clients(args.clients,
                                                     os.path.join(tmp, f'view_{start}.log'))
                every = set().union(*(w.subscribed for w in watches))
                lost_now = sum(len(every - set(w.subscribed)) for w in watches)
                refused_now = sum(len(w.errors) for w in watches)
                split_now = sum(len(w.advertisements) > 1 for w in watches)
                cams = min(w.received.get('/mv3dpose/cameras', 0) for w in watches)
                print(f'start {start + 1:2d}: {len(every)} channels, advertisements per client '
                      f'{[len(w.advertisements) for w in watches]}, refused {refused_now}, '
                      f'never subscribed {lost_now}, fewest camera messages {cams}',
                      flush=True)
                lost, refused, split = lost + lost_now, refused + refused_now, split + split_now
    finally:
        for p in busy:
            p.kill()
            p.wait()
    print(f'{args.starts} starts x {args.clients} clients, {args.busy} busy processes: '
          f'refused subscriptions {refused}, channels never subscribed {lost}, clients that '
          f'got the channels in more than one advertisement {split}')
    return 0 if lost == refused == 0 else 1


if __name__ == '__main__':
    sys.exit(main())
