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
Keep large message buffers in the heap of processes that move images.

A 1920x1080 bgr8 image is a 6 MB message. glibc serves allocations that large with ``mmap``
and returns them with ``munmap`` when freed, so every image a node receives or publishes costs
about 1,500 fresh page faults (zeroed pages) in each of the buffers DDS, rcl and Python allocate
for it. Measured here: a do-nothing rclpy subscriber to 10 Hz 1080p images used 24 % of a core,
7 % with the buffers kept in the heap (``bench/bench_image_transport.py --malloc``).
``keep_large_buffers`` raises glibc's mmap threshold above the largest image expected and keeps
freed memory for reuse instead of trimming it, for the allocations made after the call.
"""

import ctypes
import ctypes.util
from typing import Optional

# mallopt parameters (glibc malloc.h).
_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3
#: glibc's largest allowed mmap threshold on 64-bit (HEAP_MAX / 2): 32 MiB, a 4K bgr8 image.
MAX_MMAP_THRESHOLD = 32 * 1024 * 1024
#: Freed heap memory kept for reuse before glibc gives it back to the kernel.
TRIM_THRESHOLD = 256 * 1024 * 1024

_applied: Optional[bool] = None


def keep_large_buffers() -> bool:
    """
    Make glibc keep image-sized buffers in the heap; return True when it is in effect.

    Idempotent; a no-op returning False where the C library is not glibc (musl, macOS) or the
    call is refused. Call it once at process start, before the first image arrives.
    """
    global _applied
    if _applied is not None:
        return _applied
    _applied = False
    name = ctypes.util.find_library('c')
    if not name:
        return False
    try:
        libc = ctypes.CDLL(name)
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    mallopt.restype = ctypes.c_int
    _applied = bool(mallopt(_M_MMAP_THRESHOLD, MAX_MMAP_THRESHOLD)) and \
        bool(mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD))
    return _applied
