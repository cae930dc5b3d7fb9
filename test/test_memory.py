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


"""keep_large_buffers: image-sized buffers are reused instead of page-faulted in afresh."""

import subprocess
import sys
import textwrap

import pytest

PROBE = textwrap.dedent("""
    import resource, sys
    from mv3dpose_ros.ros.memory import keep_large_buffers
    if sys.argv[1] == 'keep':
        assert keep_large_buffers() and keep_large_buffers()   # idempotent
    def faults():
        return resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    size = 1920 * 1080 * 3                                      # one 1080p bgr8 image

    def receive(n):
        # What a raw subscription does per image: a serialised buffer, a Python copy of it, a
        # slightly larger buffer for the next message; each zeroed or written in full.
        for _ in range(n):
            cdr = bytearray(size)
            data = bytes(cdr)
            del cdr
            nxt = bytearray(size + 100000)
            del data, nxt
    receive(3)                                                  # warm up
    before = faults()
    receive(20)
    print(faults() - before)
""")


def _faults(mode: str) -> int:
    out = subprocess.run([sys.executable, '-c', PROBE, mode], capture_output=True, text=True,
                         timeout=60, check=True)
    return int(out.stdout.split()[-1])


@pytest.mark.skipif(not sys.platform.startswith('linux'), reason='glibc malloc only')
def test_image_buffers_are_reused_not_faulted_in_again():
    pages = 1920 * 1080 * 3 // 4096
    default = _faults('default')
    kept = _faults('keep')
    # glibc's default: each 6 MB buffer is a fresh mmap, all its pages fault in again.
    assert default >= 10 * pages, default
    # Kept in the heap: the same memory is reused, (almost) no new page faults.
    assert kept < pages, kept
