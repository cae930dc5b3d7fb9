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

"""ament_flake8 over the package (single quotes, 99 columns, google import order)."""

import json
import os
import subprocess
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EXCLUDE = ['.venv', 'build', 'install', 'log', '.cache']


@pytest.mark.flake8
@pytest.mark.linter
def test_flake8():
    # '--' ends the nargs='*' --exclude list; without it ROOT itself would be excluded.
    argv = ['--exclude'] + [os.path.join(ROOT, e) for e in EXCLUDE] + ['--', ROOT]
    # In a fresh interpreter: flake8 forks worker processes, and a fork of this pytest process
    # (earlier tests leave DDS and onnxruntime threads and their objects in it) crashed in the
    # child's garbage collection (segfault when test_pose2d_node.py ran first).
    code = ('import json, sys; from ament_flake8.main import main_with_errors; '
            'rc, errors = main_with_errors(argv=sys.argv[1:]); print(json.dumps([rc, errors]))')
    res = subprocess.run([sys.executable, '-c', code, *argv], capture_output=True, text=True,
                         cwd=ROOT, timeout=600)
    assert res.returncode == 0, res.stdout[-3000:] + res.stderr[-3000:]
    rc, errors = json.loads(res.stdout.strip().splitlines()[-1])
    assert rc == 0, 'Found %d code style errors / warnings:\n' % len(errors) + '\n'.join(errors)
