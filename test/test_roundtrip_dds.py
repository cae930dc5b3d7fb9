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

"""Real DDS round trip of the custom messages between two processes (console scripts)."""

import json
import os
import subprocess

from mv3dpose_ros.nodes.roundtrip_probe import sample_message
from mv3dpose_ros.ros.messages import message_to_dict
import pytest

COUNT = 6


def _run_pair(kind, tmp_path):
    out = tmp_path / f'{kind}.json'
    env = dict(os.environ)
    echo = subprocess.Popen(['roundtrip_probe', 'echo', '--type', kind, '--count', str(COUNT),
                             '--output', str(out), '--timeout', '40'], env=env)
    pub = subprocess.Popen(['roundtrip_probe', 'publish', '--type', kind, '--count',
                            str(COUNT), '--timeout', '40'], env=env)
    try:
        assert echo.wait(timeout=60) == 0, 'echo process failed'
        assert pub.wait(timeout=60) == 0, 'publish process failed'
    finally:
        for proc in (echo, pub):
            if proc.poll() is None:
                proc.kill()
    with open(out, encoding='utf-8') as f:
        return json.load(f)


@pytest.mark.ros
@pytest.mark.parametrize('kind', ['person2d', 'tracks'])
def test_dds_round_trip_between_processes(kind, tmp_path):
    received = _run_pair(kind, tmp_path)
    expected = [message_to_dict(sample_message(kind, i)) for i in range(COUNT)]
    assert received == expected


def test_samples_differ_from_defaults():
    """A dropped field would go unnoticed if the samples held default values: they do not."""
    for kind in ('person2d', 'tracks'):
        msg = sample_message(kind, 1)
        default = type(msg)()
        for name in msg.get_fields_and_field_types():
            value, unset = getattr(msg, name), getattr(default, name)
            assert message_to_dict(value) != message_to_dict(unset), \
                f'{kind}.{name} equals its default value'
