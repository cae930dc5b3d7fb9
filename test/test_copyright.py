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

"""Every Python source carries the Apache-2.0 header (ament_copyright is not in the wheels)."""

import os
import subprocess

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.mark.copyright
@pytest.mark.linter
def test_copyright_headers():
    files = subprocess.run(['git', 'ls-files', '*.py'], cwd=ROOT, capture_output=True,
                           text=True, check=False).stdout.split()
    if not files:
        pytest.skip('not a git checkout')
    missing = []
    for name in files:
        with open(os.path.join(ROOT, name), encoding='utf-8') as f:
            head = f.read(400)
        if 'Licensed under the Apache License, Version 2.0' not in head:
            missing.append(name)
    assert not missing, 'files without the Apache-2.0 header: ' + ', '.join(missing)
