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
Back the image-sized buffers of image-moving processes with transparent huge pages.

A 1920x1080 bgr8 image is a 6 MB message. glibc serves allocations that large with a fresh
``mmap``, so every image a node receives costs about 1,500 page faults (zeroed 4 KiB pages) in
each buffer DDS, rcl and Python allocate for it: a do-nothing raw subscriber to 10 Hz 1080p
images spent 22 ms of CPU per image. glibc's ``glibc.malloc.hugetlb=1`` tunable makes malloc
``madvise`` those mappings for transparent huge pages, 2 MiB per fault: 9.8 ms per image
(``bench/bench_image_transport.py --buffers``), with freed memory still returned to the kernel.

The tunable is read when a process starts, so it goes into the environment: ``bringup`` puts it
in its children's, and a node started alone (``ros2 run``, a launch file) re-executes itself once
with it (``reexec_with_hugepages``). It only matters where the kernel's THP mode is ``madvise``
(``always`` already does it; ``never`` cannot); elsewhere, and with ``MV3DPOSE_HUGEPAGES=0``,
nothing changes. Keeping the buffers in the heap instead (``M_MMAP_THRESHOLD``) saves slightly
more but made fusion_node stop receiving in one of four bring-ups here, so it is not used.
"""

import os
import platform
import sys
from typing import Dict, Mapping, Optional, Sequence

TUNABLE = 'glibc.malloc.hugetlb'
#: Environment variable that turns this off (``0``); any other value or none leaves it on.
OPT_OUT = 'MV3DPOSE_HUGEPAGES'
#: Set in a re-executed process so that it never re-executes again.
REEXECUTED = 'MV3DPOSE_HUGEPAGES_REEXEC'
THP_MODE_FILE = '/sys/kernel/mm/transparent_hugepage/enabled'


def thp_mode(path: str = THP_MODE_FILE) -> Optional[str]:
    """Return the kernel's transparent huge page mode (always, madvise, never) or None."""
    try:
        with open(path) as f:
            text = f.read()
    except OSError:
        return None
    start, end = text.find('['), text.find(']')
    return text[start + 1:end] if 0 <= start < end else None


def wants_hugepages(env: Mapping[str, str], mode: Optional[str]) -> bool:
    """Tell whether a process with ``env`` on a kernel in THP ``mode`` should get the tunable."""
    if env.get(OPT_OUT, '').strip() == '0' or mode != 'madvise':
        return False
    if not sys.platform.startswith('linux') or platform.libc_ver()[0] != 'glibc':
        return False
    return TUNABLE not in env.get('GLIBC_TUNABLES', '')        # an explicit choice wins


def with_hugepages(env: Mapping[str, str], mode: Optional[str] = None) -> Dict[str, str]:
    """Return a copy of ``env`` with ``glibc.malloc.hugetlb=1`` added where it helps."""
    out = dict(env)
    if wants_hugepages(env, thp_mode() if mode is None else mode):
        tunables = [t for t in out.get('GLIBC_TUNABLES', '').split(':') if t]
        out['GLIBC_TUNABLES'] = ':'.join(tunables + [f'{TUNABLE}=1'])
    return out


def reexec_with_hugepages(argv: Optional[Sequence[str]] = None) -> None:
    """
    Re-execute this Python process once with the tunable when it helps; return otherwise.

    Call it first thing in a node's ``main`` (before rclpy starts threads): the process keeps
    its pid, arguments, open files and signal handling, so ``ros2 run``, launch and bringup see
    no difference. ``argv`` is the interpreter command line (default ``sys.orig_argv``).
    """
    if os.environ.get(REEXECUTED):
        return
    env = with_hugepages(os.environ)
    if env.get('GLIBC_TUNABLES') == os.environ.get('GLIBC_TUNABLES'):
        return
    env[REEXECUTED] = '1'
    args = list(sys.orig_argv if argv is None else argv)
    sys.stdout.flush()
    sys.stderr.flush()
    try:
        os.execve(sys.executable, [sys.executable] + args[1:], env)
    except OSError:
        return                                  # keep running without it
