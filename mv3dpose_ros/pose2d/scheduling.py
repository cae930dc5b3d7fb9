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
When a camera's images are inferred: the grid arithmetic of ``inference_rate_hz`` (no ROS).

A camera that outpaces its model cannot have every image inferred. The arithmetic here says
which: a grid of stamp windows (``grid_period_ns``, ``on_new_window``) whose rates nest, so
cameras on different rates still infer common instants; the camera's frame period from the
images taken (``frame_period_ns``), whether a grid selects at all (``grid_selects``), the
windows lost while the model was busy (``missed_windows``), how long the inference thread may
doze until the next window (``doze_s``), and the smaller inputs auto mode may step down to
(``size_ladder``). ``auto_rate`` chooses among them from measurements; ``intake`` applies them
to the images as they come.
"""

import math
import statistics
from typing import Any, List, Optional, Sequence, Tuple

from mv3dpose_ros.core.types import NS_PER_S

#: Grid rates ``inference_rate_hz`` auto chooses from: 40 / 2^k Hz (periods 25 ms x 2^k). Every
#: window boundary of a slower rate is one of each faster rate, so the first image of a slower
#: window is also the first of a faster one: cameras whose nodes settle on different rates still
#: infer common instants (those of the slowest).
AUTO_RATES_HZ = tuple(40.0 / 2 ** k for k in range(10))      # 40 Hz .. 0.078 Hz
#: Grid rates of cameras that share one rate (``rig_rate_topic``): those of AUTO_RATES_HZ and
#: 2/3 of each (40, 26.7, 20, 13.3, 10, 6.7, 5, 3.3, 2.5, ... Hz). Steps of 1.33-1.5x instead of
#: 2x let a rig settle closer to what it sustains; the grids need not nest when every camera
#: uses the same one.
RIG_AUTO_RATES_HZ = tuple(sorted(
    {r for k in range(10) for r in (40.0 / 2 ** k, 80.0 / (3 * 2 ** k))}, reverse=True))
#: A grid no faster than the camera selects nothing: with the camera's frame period at least
#: GRID_IDLE_RATIO of the grid period, every image is inferred. On a grid of the camera's own
#: rate, stamp jitter at the window boundaries would put two images in one window and none in
#: the next, and the fusion node would wait for the missing camera.
GRID_IDLE_RATIO = 0.9


def parse_inference_rate(value: Any) -> float:
    """
    Return the ``inference_rate_hz`` parameter as a number: < 0 auto, 0 every image, > 0 Hz.

    Accepts an int, a float or the string ``auto`` (or a number as a string); raises
    ``ValueError`` naming the parameter otherwise.
    """
    if isinstance(value, str):
        text = value.strip().lower()
        if text == 'auto':
            return -1.0
        try:
            value = float(text)
        except ValueError:
            raise ValueError(f"inference_rate_hz must be 'auto', -1 (auto), 0 (every image) or "
                             f'a rate in Hz, got {value!r}') from None
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f'inference_rate_hz must be a number or auto, got {value!r}')
    rate = float(value)
    if not math.isfinite(rate) or rate > 1000.0:
        raise ValueError(f'inference_rate_hz must be auto (< 0), 0 or a rate up to 1000 Hz, '
                         f'got {value!r}')
    return -1.0 if rate < 0 else rate


def grid_period_ns(rate_hz: float) -> int:
    """Return the stamp window of a grid rate in integer nanoseconds."""
    return int(round(NS_PER_S / rate_hz))


def on_new_window(stamp_ns: int, last_ns: Optional[int], period_ns: int) -> bool:
    """
    Tell whether ``stamp_ns`` opens a new grid window after the image that opened ``last_ns``.

    Windows are ``stamp // period``; an image in the same window as the last one taken, or
    slightly (< 1 s) before it (reordering), does not; a jump back of 1 s or more (a replay
    starting again) does.
    """
    if last_ns is None:
        return True
    window, last = stamp_ns // period_ns, last_ns // period_ns
    return not (window == last or 0 < (last - window) * period_ns < NS_PER_S)


def frame_period_ns(taken: Sequence[Tuple[Any, int, int]],
                    min_steps: int = 1) -> Optional[float]:
    """
    Return the camera's frame period from images taken, None until ``min_steps`` are known.

    ``taken``: ``(arrival, header stamp ns, camera images since the previous take)``, oldest
    first (the arrival is not used); the median over the last 16 stamp steps, each divided by
    its image count. Steps of 10 s or more (a pause, a stalled camera) and backwards are left
    out; a camera slower than 0.1 Hz has no period.
    """
    taken = list(taken)[-17:]
    steps = [(s1 - s0) // f1 for (_, s0, _), (_, s1, f1) in zip(taken, taken[1:])
             if f1 >= 1 and 0 < s1 - s0 < 10 * NS_PER_S]
    return statistics.median(steps) if len(steps) >= max(1, min_steps) else None


def grid_selects(rate_hz: float, frame_ns: Optional[float]) -> bool:
    """Tell whether a grid rate skips images: one is set and the camera (if known) is faster."""
    if rate_hz <= 0:
        return False
    return frame_ns is None or frame_ns < GRID_IDLE_RATIO * grid_period_ns(rate_hz)


def missed_windows(stamp_ns: Optional[int], last_ns: Optional[int], untaken: int,
                   period_ns: int) -> int:
    """
    Return the grid windows none of whose images was taken, of ``untaken`` images.

    Between the image that opened the last window (``last_ns``) and this one: those windows'
    first images were lost (the model was busy for longer than a window), not skipped by the
    grid, so they count as dropped.
    """
    if not untaken or stamp_ns is None or last_ns is None or stamp_ns <= last_ns:
        return 0
    return min(untaken, max(0, stamp_ns // period_ns - last_ns // period_ns - 1))


def doze_s(rate_hz: float, last_ns: Optional[int], taken: Sequence[Tuple[int, int, int]],
           now_ns: int) -> float:
    """
    Return how long to wait before taking the next image, on a grid (0: take one now).

    The camera's images of the window already inferred (opened by ``last_ns``) are not needed:
    wait until half a frame before the next window's first image can arrive (predicted from
    the stamps and the arrival times of the images ``taken``, ``(arrival wall ns, stamp ns,
    frames)`` oldest first, with the shortest transport seen, so replays faster or slower than
    real time work), at most one window. Waking early costs one take of an image still in the
    old window; waking up to a frame late still takes the window's first image (the newest
    then). Each image not taken is one 6 MB copy less.
    """
    frame_ns = frame_period_ns(taken)
    if not grid_selects(rate_hz, frame_ns) or last_ns is None or frame_ns is None:
        return 0.0
    (w0, s0, _), (w1, s1, _) = taken[0], taken[-1]
    period = grid_period_ns(rate_hz)
    start = (last_ns // period + 1) * period           # stamp opening the next window
    if start <= s1:
        return 0.0
    speed = (s1 - s0) / (w1 - w0) if w1 - w0 > NS_PER_S // 2 and s1 > s0 else 1.0
    speed = min(10.0, max(0.1, speed))                 # stamp ns per wall-clock ns
    transport = min(w - s / speed for w, s, _ in taken)   # wall arrival - stamp, shortest
    wake = transport + (start - frame_ns / 2) / speed
    return min(max(0.0, (wake - now_ns) / 1e9), period / speed / 1e9)


def size_ladder(image_hw: Tuple[int, int], chosen: Tuple[int, int],
                fetched: Sequence[Tuple[int, int]], min_side: int) -> List[Tuple[int, int]]:
    """
    Return the input sizes ``inference_rate_hz`` auto may step down to, ``chosen`` first.

    Each next step is, among the ``fetched`` sizes with fewer pixels than the last (less
    inference time) and a long side of at least ``min_side``, the one whose letterbox keeps
    the most image detail (largest scale; among equals the fewest pixels). A 1920x1080 camera
    on 384x640 gets 288x512, then 224x384; a 1088x1920 one on 640x384 gets 512x288, 384x224.
    """
    h, w = image_hw
    scale = {tuple(s): min(s[0] / h, s[1] / w) for s in fetched}
    out = [tuple(chosen)]
    while True:
        last = out[-1][0] * out[-1][1]
        cheaper = [s for s in scale if s[0] * s[1] < last and max(s) >= min_side]
        if not cheaper:
            return out
        out.append(max(cheaper, key=lambda s: (scale[s], -s[0] * s[1])))
