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

import os

from ament_flake8.main import main_with_errors
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EXCLUDE = ['.venv', 'build', 'install', 'log', '.cache']


@pytest.mark.flake8
@pytest.mark.linter
def test_flake8():
    # '--' ends the nargs='*' --exclude list; without it ROOT itself would be excluded.
    argv = ['--exclude'] + [os.path.join(ROOT, e) for e in EXCLUDE] + ['--', ROOT]
    rc, errors = main_with_errors(argv=argv)
    assert rc == 0, 'Found %d code style errors / warnings:\n' % len(errors) + '\n'.join(errors)
