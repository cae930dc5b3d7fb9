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
When a camera's images are inferred: the policy of ``inference_rate_hz`` (no ROS here).

A camera that outpaces its model cannot have every image inferred. The policy here decides
which: every image while the node keeps up; else a smaller input (``size_ladder``), then a grid
of stamp windows (``grid_period_ns``, ``on_new_window``) whose rates nest, so cameras on
different rates still infer common instants; ``AutoInferenceRate`` makes that choice from the
measured camera rate, processing time and images lost, with hysteresis, and ``RigRate`` makes
a rig's cameras share the slowest rate announced. ``pose2d_node`` feeds them and applies the
choice.
"""

from collections import deque
import math
import statistics
from typing import Any, Deque, List, Optional, Sequence, Tuple

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
#: Auto mode: a rate is kept while one image takes at most AUTO_DOWN of its period, a rate is
#: chosen at AUTO_MARGIN of what the node can infer, the next faster one (or every image) is
#: taken only below AUTO_UP: the band in between is the hysteresis.
AUTO_DOWN, AUTO_MARGIN, AUTO_UP = 0.9, 0.7, 0.6
#: Auto mode, from a grid back to every image: below AUTO_UP_EVERY of the camera's frame period.
#: Looser than AUTO_UP because every image is left only once more than AUTO_LOSS of the images
#: go uninferred (about 1.33 frame periods per image), and because an image on a rig's grid
#: takes about as long as at every image: the rig's cameras infer the same instants at once,
#: so each meets the others' inference as often as when they run unsynchronised (4 x 1080p at
#: 10 Hz here: 55-69 ms per image on a 6.7 Hz grid, 60-67 ms at every image, 5-8 % replaced;
#: below AUTO_UP such a rig stayed on the grid for up to a minute).
AUTO_UP_EVERY = 0.8
#: Auto mode: a larger input is taken only below AUTO_UP_SIZE of the frame period (estimated
#: from the pixel ratio). Stricter than AUTO_UP: a larger input also slows the other cameras
#: sharing the cores, which a node's own measurement does not show.
AUTO_UP_SIZE = 0.45
#: Auto mode, at the smallest input: every image is left for a grid rate only when more than
#: AUTO_LOSS of the camera's images of the last AUTO_WINDOW_S were not inferred (replaced by a
#: newer one while the model was busy). A grid gives the rig common instants but infers only
#: its rate's share of the images (2/3 on the grid below 10 Hz); a node that infers 3 images
#: in 4 of a 10 Hz camera, on a busy moment of a machine at its edge, gives the rig more sets.
AUTO_LOSS = 0.25
#: Auto mode: a grid rate needing up to AUTO_GENTLE of its period steps down one rate only (a
#: mild overload, often one noisy measurement); above it, straight to AUTO_MARGIN.
AUTO_GENTLE = 1.2
#: Auto mode: processing times kept (median), needed since the last change, and the least time
#: a rate is kept [s]. The median is over the last AUTO_WINDOW times or, when more, those of
#: the last AUTO_WINDOW_S: at 10 images/s a second of slow images (another process's burst)
#: is then not yet an overload.
AUTO_WINDOW, AUTO_MIN_SAMPLES, AUTO_DWELL_S, AUTO_WINDOW_S = 9, 3, 3.0, 3.0
#: Auto mode: the least time a choice is kept before a step *up* (faster rate, every image, a
#: larger input) [s]. Longer than AUTO_DWELL_S: the cameras of one machine share its cores, so
#: just after they all stepped down each one measures a quiet machine and would step back up
#: at once, overloading it again. A step up undone within AUTO_UP_HELD_S doubles the wait
#: before the next one (up to AUTO_UP_DWELL_MAX_S); one that holds resets it.
AUTO_UP_DWELL_S, AUTO_UP_HELD_S, AUTO_UP_DWELL_MAX_S = 10.0, 30.0, 160.0
#: A grid no faster than the camera selects nothing: with the camera's frame period at least
#: GRID_IDLE_RATIO of the grid period, every image is inferred. On a grid of the camera's own
#: rate, stamp jitter at the window boundaries would put two images in one window and none in
#: the next, and the fusion node would wait for the missing camera.
GRID_IDLE_RATIO = 0.9
#: Auto mode across a rig: a rate announced on ``rig_rate_topic`` holds the rig back for this
#: long after it was heard [s] (announced every RIG_RATE_PERIOD_S and at each change).
RIG_RATE_TTL_S, RIG_RATE_PERIOD_S = 3.0, 1.0


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


class AutoInferenceRate:
    """
    ``inference_rate_hz`` auto: the input size and grid rate one camera's node can sustain.

    Fed with the header stamps of arriving images (the camera rate), the images replaced in
    the mailbox before inference and the time the node spends on each image it processes,
    ``update`` returns True when the node should change what it does now:

    - while the node keeps up (also when it is slow but nothing is replaced: a player that
      waits for the output), every image at the largest input size;
    - once the camera outpaces it (images replaced), first a smaller input size of ``sizes``
      (the ladder of ``size_ladder``, down to ``model.min_input_side``; the largest one whose
      time, estimated from the pixel ratio, fits ``AUTO_MARGIN``), then, once more than
      ``AUTO_LOSS`` of the images go uninferred, the fastest of ``rates`` (``AUTO_RATES_HZ``;
      ``RIG_AUTO_RATES_HZ`` in a rig sharing one rate) at ``AUTO_MARGIN`` of what it can
      infer;
    - back up one step (a faster rate, every image, then a larger size, whose time is
      estimated from the pixel ratio) only when that stays below ``AUTO_UP`` (every image
      below ``AUTO_UP_EVERY``, a larger size below ``AUTO_UP_SIZE``); down as soon as the
      current step needs more than ``AUTO_DOWN`` of the frame period (one grid rate slower
      while it needs at most ``AUTO_GENTLE``, else at ``AUTO_MARGIN`` at once).

    A choice is kept for ``AUTO_DWELL_S`` and ``AUTO_MIN_SAMPLES`` images at least, and for
    ``AUTO_UP_DWELL_S`` before a step up, so it follows the load but does not flap.
    ``rate_hz`` (0: every image) and ``size`` are the current choice, ``reason`` says why it
    was made.
    """

    def __init__(self, sizes: Sequence[Tuple[int, int]] = (),
                 rates: Sequence[float] = AUTO_RATES_HZ) -> None:
        self.rate_hz = 0.0                    # current grid rate; 0: every image
        self.rates = tuple(sorted(rates, reverse=True))
        self.sizes: List[Tuple[int, int]] = [tuple(s) for s in sizes]   # largest first
        self.size_index = 0
        # (done at [s], seconds): AUTO_WINDOW_S at up to 40 images/s
        self._proc_s: Deque[Tuple[Optional[float], float]] = deque(maxlen=120)
        # (at [s], header stamp ns, camera images since the last): the camera's frame period
        self._taken: Deque[Tuple[Optional[float], int, int]] = deque(maxlen=17)
        self._replaced = 0                    # images replaced before inference since a change
        # (at [s], camera images, of them replaced) since a change: AUTO_WINDOW_S at 80 Hz
        self._images: Deque[Tuple[Optional[float], int, int]] = deque(maxlen=512)
        self._changed_s: Optional[float] = None
        self._up_s: Optional[float] = None    # when the last step up was taken
        self.up_dwell_s = AUTO_UP_DWELL_S     # wait before a step up (backs off, see update)
        self.reason = 'every image (no measurement yet)'

    @property
    def size(self) -> Optional[Tuple[int, int]]:
        """Input size chosen now (None when the node's size is fixed)."""
        return self.sizes[self.size_index] if self.sizes else None

    def set_sizes(self, sizes: Sequence[Tuple[int, int]]) -> None:
        """Set the size ladder (largest first; the first is the size in use now)."""
        self.sizes = [tuple(s) for s in sizes]
        self.size_index = 0

    def add_stamp(self, stamp_ns: int, frames: int = 1, now_s: Optional[float] = None) -> None:
        """Record the header stamp of a taken image, ``frames`` camera images after the last."""
        self._taken.append((now_s, stamp_ns, frames))
        if frames >= 1:
            self._images.append((now_s, frames, 0))

    def add_replaced(self, count: int = 1, now_s: Optional[float] = None) -> None:
        """Record images replaced by a newer one before inference."""
        self._replaced += count
        if count >= 1:
            self._images.append((now_s, 0, count))

    @property
    def loss(self) -> float:
        """
        Share of the camera's images not inferred (replaced) since the last change.

        Over the last ``AUTO_WINDOW_S`` when the records are timed; 0 while none is known.
        """
        newest = self._images[-1][0] if self._images else None
        recent = [(n, r) for t, n, r in self._images
                  if newest is None or (t is not None and newest - t <= AUTO_WINDOW_S)]
        images = sum(n for n, _ in recent)
        return min(1.0, sum(r for _, r in recent) / images) if images else 0.0

    def add_processing(self, seconds: float, now_s: Optional[float] = None) -> None:
        """Record the time the node spent on one processed image (done at ``now_s``)."""
        if math.isfinite(seconds) and seconds > 0:
            self._proc_s.append((now_s, seconds))

    @property
    def input_hz(self) -> float:
        """Camera rate from the median stamp step (NaN until 4 steps are known)."""
        period = frame_period_ns(self._taken, min_steps=4)
        return NS_PER_S / period if period else math.nan

    @property
    def processing_s(self) -> float:
        """Median time per processed image since the last change (NaN when unknown)."""
        if not self._proc_s:
            return math.nan
        newest = self._proc_s[-1][0]
        recent = [] if newest is None else [
            p for t, p in self._proc_s if t is not None and newest - t <= AUTO_WINDOW_S]
        last = [p for _, p in list(self._proc_s)[-AUTO_WINDOW:]]
        return statistics.median(recent if len(recent) > len(last) else last)

    def _pixel_ratio(self, index: int) -> float:
        """Return pixels of ``sizes[index]`` over those of the size in use."""
        (h0, w0), (h1, w1) = self.sizes[self.size_index], self.sizes[index]
        return (h1 * w1) / (h0 * w0)

    def update(self, now_s: float) -> bool:
        """Return True when the rate or the size changed now (read ``rate_hz`` and ``size``)."""
        if self._changed_s is None:
            self._changed_s = now_s
        if len(self._proc_s) < AUTO_MIN_SAMPLES or now_s - self._changed_s < AUTO_DWELL_S:
            return False
        fps = self.input_hz
        if not math.isfinite(fps):
            return False
        proc = self.processing_s
        cap = 1.0 / proc
        rate, index = self.rate_hz, self.size_index
        smaller = index + 1 < len(self.sizes)
        if self._up_s is not None and now_s - self._up_s >= AUTO_UP_HELD_S:
            self._up_s, self.up_dwell_s = None, AUTO_UP_DWELL_S     # the last step up held
        up = now_s - self._changed_s >= self.up_dwell_s
        if rate == 0.0:
            if fps * proc > AUTO_DOWN and self._replaced >= AUTO_MIN_SAMPLES:
                if smaller:
                    index = next((j for j in range(index + 1, len(self.sizes))
                                  if fps * proc * self._pixel_ratio(j) <= AUTO_MARGIN),
                                 len(self.sizes) - 1)
                elif self.loss > AUTO_LOSS:
                    rate = self.fastest(AUTO_MARGIN * cap)
            elif up and index > 0 and fps * proc * self._pixel_ratio(index - 1) <= AUTO_UP_SIZE:
                index -= 1
        elif rate * proc > AUTO_DOWN:
            slower = next((r for r in self.rates if r < rate), rate)
            rate = slower if rate * proc <= AUTO_GENTLE else self.fastest(AUTO_MARGIN * cap)
        elif up and fps * proc <= AUTO_UP_EVERY:
            rate = 0.0
        elif up:
            faster = next((r for r in reversed(self.rates) if r > rate), rate)
            if faster * proc <= AUTO_UP and faster < fps:
                rate = faster
        if (rate, index) == (self.rate_hz, self.size_index):
            return False
        stepped_up = index < self.size_index or rate > self.rate_hz > 0 or rate == 0 < self.rate_hz
        if stepped_up:                       # a larger input, a faster rate or every image
            self._up_s = now_s
        elif self._up_s is not None:         # down again soon after a step up: back off
            self._up_s = None
            self.up_dwell_s = min(AUTO_UP_DWELL_MAX_S, 2 * self.up_dwell_s)
        self.rate_hz, self.size_index = rate, index
        self._changed_s = now_s
        self._proc_s.clear()
        self._images.clear()
        self._replaced = 0
        self.reason = (f'images at {fps:.2f} Hz, {proc * 1e3:.0f} ms per image (at most '
                       f'{cap:.2f} Hz)')
        return True

    def fastest(self, limit_hz: float) -> float:
        """Return the fastest of ``rates`` up to ``limit_hz`` (else the slowest)."""
        limit = limit_hz * (1 + 1e-9)          # 0.7 x 3.57 Hz is 2.5 Hz, not 1.67 Hz
        return next((r for r in self.rates if r <= limit), self.rates[-1])


class RigRate:
    """
    The grid rate the auto-mode cameras of a rig share: the slowest any of them announced.

    Each node chooses the rate it can sustain alone (``AutoInferenceRate``); cameras on
    different grids infer different instants, and the fusion node then gets sets with cameras
    missing (waits, then partial triangulations). Every camera following the slowest rate heard
    in the last ``ttl_s`` makes them infer the same instants; a camera that stops announcing
    (stopped, crashed) stops holding the rig back when its announcement expires. 0 (every
    image) holds nobody back.
    """

    def __init__(self, ttl_s: float = RIG_RATE_TTL_S) -> None:
        self.ttl_s = ttl_s
        self._heard: Deque[Tuple[float, float]] = deque()    # (steady time [s], rate [Hz])

    def hear(self, rate_hz: float, now_s: float) -> bool:
        """Record an announced rate; False (ignored) unless it is 0 or a finite rate > 0."""
        if not math.isfinite(rate_hz) or rate_hz < 0:
            return False
        if rate_hz > 0:
            self._heard.append((now_s, rate_hz))
        return True

    def slowest(self, now_s: float) -> float:
        """Return the slowest grid rate announced within the TTL (0: none)."""
        while self._heard and now_s - self._heard[0][0] > self.ttl_s:
            self._heard.popleft()
        return min((rate for _, rate in self._heard), default=0.0)

    def common(self, own_hz: float, now_s: float) -> float:
        """Return the rate to use: the slowest of ``own_hz`` (0: every image) and the rig's."""
        rates = [r for r in (own_hz, self.slowest(now_s)) if r > 0]
        return min(rates) if rates else 0.0


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
