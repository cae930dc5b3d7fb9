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
``bench/sparse_views.py`` runs end to end on the real data (a short smoke run, no figures).

The bench prints figures, not verdicts: this only checks that both replays (random drops, and
delays through the real synchroniser) go through and print their tables.
"""

import contextlib
import io
import os
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, 'bench'))
import sparse_views  # noqa: E402, I100 - bench/ is no package


@pytest.mark.parametrize('delays', [False, True])
def test_sparse_views_quick(shared_data, delays):
    out = io.StringIO()
    argv = ['--data', 'pose2sim,campus,panoptic', '--drops', '0,0.4', '--seeds', '1',
            '--noise', '1', '--quick'] + (['--delays'] if delays else [])
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(io.StringIO()):
        assert sparse_views.main(argv) == 0
    text = out.getvalue()
    for title in ('Pose2Sim multiperson', 'Campus', 'Panoptic band1'):
        assert title in text
    assert 'set-based' in text and 'per-camera' in text
    rows = [line for line in text.splitlines() if ' | ' in line and line.split()[0] in
            ('real', 'noise', '5c')]
    assert len(rows) == 3 * 2, text         # a row per data set variant and drop rate
    if delays:
        assert 'sets' in text and 'late' in text
