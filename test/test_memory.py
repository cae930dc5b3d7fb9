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

"""Transparent huge pages for image buffers (ros.system.memory): env logic, effect, re-exec."""

import json
import os
import subprocess
import sys
import textwrap

from mv3dpose_ros.ros.system import memory
from mv3dpose_ros.ros.system.memory import OPT_OUT, thp_mode, TUNABLE, with_hugepages
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
ON = f'{TUNABLE}=1'


def test_tunable_added_only_where_it_helps():
    assert with_hugepages({}, 'madvise')['GLIBC_TUNABLES'] == ON
    assert with_hugepages({'GLIBC_TUNABLES': 'glibc.x=2'}, 'madvise')['GLIBC_TUNABLES'] == \
        f'glibc.x=2:{ON}'
    for mode in ('always', 'never', ''):          # already done / impossible / unknown
        assert 'GLIBC_TUNABLES' not in with_hugepages({}, mode)
    assert 'GLIBC_TUNABLES' not in with_hugepages({OPT_OUT: '0'}, 'madvise')
    explicit = {'GLIBC_TUNABLES': f'{TUNABLE}=0'}
    assert with_hugepages(explicit, 'madvise') == explicit          # the user's choice wins
    env = {'A': 'b'}
    with_hugepages(env, 'madvise')
    assert env == {'A': 'b'}                                           # a copy, not in place


def test_thp_mode_parses_the_kernel_file(tmp_path):
    path = tmp_path / 'enabled'
    path.write_text('always [madvise] never\n')
    assert thp_mode(str(path)) == 'madvise'
    path.write_text('garbage\n')
    assert thp_mode(str(path)) is None
    assert thp_mode(str(tmp_path / 'missing')) is None


def _minor_faults_of_big_buffers(env):
    """Page faults of a child allocating and filling five 40 MB buffers (always mmapped)."""
    code = textwrap.dedent("""
        import resource
        before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
        for _ in range(5):
            buf = b'x' * (40 << 20)        # malloc + fill (numpy madvises on its own)
            del buf
        print(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
    """)
    out = subprocess.run([sys.executable, '-c', code], env=env, capture_output=True, text=True,
                         timeout=60, check=True)
    return int(out.stdout.split()[-1])


@pytest.mark.skipif(thp_mode() != 'madvise', reason='the tunable acts only in THP madvise mode')
def test_tunable_cuts_page_faults_of_image_sized_buffers():
    plain = dict(os.environ, **{OPT_OUT: '0'})
    plain.pop('GLIBC_TUNABLES', None)
    huge = with_hugepages(dict(plain, **{OPT_OUT: '1'}))
    assert huge['GLIBC_TUNABLES'].endswith(ON)
    without, with_ = _minor_faults_of_big_buffers(plain), _minor_faults_of_big_buffers(huge)
    # 4 KiB pages: 5 x 10,240 faults; 2 MiB pages: a few dozen (fallbacks to small pages allowed)
    assert without > 40_000
    assert with_ < without / 4, (without, with_)


@pytest.mark.skipif(thp_mode() != 'madvise', reason='the tunable acts only in THP madvise mode')
def test_reexec_keeps_pid_and_arguments_and_happens_once(tmp_path):
    script = tmp_path / 'node.py'
    script.write_text(textwrap.dedent(f"""
        import json, os, sys
        sys.path.insert(0, {ROOT!r})
        from mv3dpose_ros.ros.system.memory import reexec_with_hugepages
        print(json.dumps([os.getpid(), sys.argv[1:], os.environ.get('GLIBC_TUNABLES')]),
              flush=True)
        reexec_with_hugepages()
        reexec_with_hugepages()          # in the re-executed process: returns
        print('main', flush=True)
    """))
    env = dict(os.environ)
    for var in ('GLIBC_TUNABLES', OPT_OUT, memory.REEXECUTED):
        env.pop(var, None)
    out = subprocess.run([sys.executable, str(script), '--ros-args', '-p', 'x:=1'], env=env,
                         capture_output=True, text=True, timeout=60, check=True)
    lines = out.stdout.splitlines()
    first, second = json.loads(lines[0]), json.loads(lines[1])
    assert lines[2:] == ['main']
    assert first[0] == second[0]                            # same process
    assert first[1] == second[1] == ['--ros-args', '-p', 'x:=1']
    assert first[2] is None and second[2] == ON
    # opted out: no re-exec at all
    out = subprocess.run([sys.executable, str(script)], env=dict(env, **{OPT_OUT: '0'}),
                         capture_output=True, text=True, timeout=60, check=True)
    assert len(out.stdout.splitlines()) == 2
