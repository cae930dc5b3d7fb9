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
The live view survives restarts: clients already waiting get every channel, and keep them.

Foxglove reconnects on its own when ``foxglove_view`` restarts, so its first subscriptions
race the server's start-up. Each start here has four clients waiting for the port, on a
machine loaded by two busy processes; every client must get all channels in its first
advertisement, no refused subscription, and the camera frustums. ``bench/foxglove_restarts.py``
runs the same for 20 starts.
"""

import os
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, 'bench'))
from foxglove_restarts import busy_processes, start_with_waiting_clients  # noqa: E402, I100

pytestmark = [pytest.mark.ros]

TOPICS = {'/mv3dpose/scene', '/mv3dpose/cameras', '/fusion_node/tracks'}


def test_clients_waiting_during_startup_get_every_channel_under_load(tmp_path):
    busy = busy_processes(2, 120)
    try:
        for start in range(2):
            watches = start_with_waiting_clients(4, str(tmp_path / f'view_{start}.log'))
            for i, watch in enumerate(watches):
                where = f'start {start} client {i}'
                first = set(watch.advertisements[0])
                assert TOPICS <= first, (where, watch.advertisements)
                assert first == set(watch.subscribed), (where, watch.advertisements)
                assert not watch.errors, (where, watch.errors)
                assert watch.received['/mv3dpose/cameras'] >= 1, (where, watch.received)
    finally:
        for p in busy:
            p.kill()
            p.wait()
