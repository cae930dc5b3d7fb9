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
``inference_rate_hz`` auto: the input size and grid rate a camera's node chooses (no ROS).

``AutoInferenceRate`` makes one node's choice from the measured camera rate, processing time
and images lost, with hysteresis (every image while the node keeps up; else a smaller input of
``scheduling.size_ladder``, then a grid rate); ``RigRate`` keeps the rates the rig's cameras
announce on ``rig_rate_topic``, and ``GridRate`` is the rate a node uses: fixed, every image,
or auto's choice held back to the rig's slowest. ``pose2d_node`` feeds them and applies the
choice.
"""

from collections import deque
import math
import statistics
import threading
from typing import Any, Deque, Dict, List, Optional, Sequence, Tuple

from mv3dpose_ros.core.types import NS_PER_S
from mv3dpose_ros.pose2d.models import size_tag
from mv3dpose_ros.pose2d.scheduling import (AUTO_RATES_HZ, frame_period_ns, grid_selects,
                                            RIG_AUTO_RATES_HZ)

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
#: Auto mode across a rig: a rate announced on ``rig_rate_topic`` holds the rig back for this
#: long after it was heard [s] (announced every RIG_RATE_PERIOD_S and at each change).
RIG_RATE_TTL_S, RIG_RATE_PERIOD_S = 3.0, 1.0


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


class GridRate:
    """
    The ``inference_rate_hz`` grid one camera's node uses: fixed, every image (0) or auto.

    In auto mode, ``auto``'s own choice held back to the slowest rate the rig's cameras announce
    (``rig``, when ``shared``: a ``rig_rate_topic`` is set), snapped to this node's grid rates
    so every camera computes the same period. ``hz`` is the rate in use (0: every image). The
    node's threads share it: ``lock`` guards it (the mailbox takes it after its own).
    """

    def __init__(self, shared: bool) -> None:
        self.lock = threading.RLock()
        self.rates = RIG_AUTO_RATES_HZ if shared else AUTO_RATES_HZ
        self.hz = 0.0
        self.auto: Optional[AutoInferenceRate] = None
        self.rig = RigRate()

    def use(self, value: float, sizes: Sequence[Tuple[int, int]] = ()) -> None:
        """Apply a parsed ``inference_rate_hz``: auto (< 0, on ``sizes``), 0 or fixed."""
        with self.lock:
            self.auto = AutoInferenceRate(sizes, self.rates) if value < 0 else None
            self.hz = max(0.0, value)

    def set_sizes(self, sizes: Sequence[Tuple[int, int]]) -> None:
        """Give auto mode a new size ladder (largest first, the one in use)."""
        with self.lock:
            if self.auto is not None:
                self.auto.set_sizes(sizes)

    @property
    def mode(self) -> str:
        """Return 'auto', 'fixed' or 'every image' (for /diagnostics)."""
        return 'auto' if self.auto is not None else 'fixed' if self.hz else 'every image'

    @property
    def size(self) -> Optional[Tuple[int, int]]:
        """Return the input size auto mode chose (None: not auto, or no ladder)."""
        auto = self.auto
        return auto.size if auto is not None else None

    def hear(self, rate_hz: float, now_s: float) -> bool:
        """Record a rate the rig announced (``RigRate.hear``; False: malformed, ignored)."""
        with self.lock:
            return self.rig.hear(rate_hz, now_s)

    def share(self, now_s: float, topic: str = '') -> str:
        """Auto mode: use the slowest of its own rate and the rig's; say why when it changed."""
        with self.lock:
            auto, old = self.auto, self.hz
            if auto is None:
                return ''
            common = self.rig.common(auto.rate_hz, now_s)
            self.hz = auto.fastest(common) if common > 0 else 0.0
            if self.hz == old:
                return ''
            what = f'{self.hz:g} Hz' if self.hz else 'every image'
            own = f'{auto.rate_hz:g} Hz' if auto.rate_hz else 'every image'
            why = ('its own choice' if self.hz == auto.rate_hz else
                   f'the slowest camera of the rig on {topic} (its own choice: {own})')
            return f'inference rate {what}: {why}'

    def adapt(self, seconds: float, now_s: float) -> Optional[Tuple[bool, List[str]]]:
        """
        Auto mode: record one image's processing time and let ``auto`` choose again.

        Return None when nothing changed, else whether its own rate changed (to announce)
        and what changed, to log.
        """
        with self.lock:
            auto = self.auto
            if auto is None:
                return None
            auto.add_processing(seconds, now_s)
            old_rate, old_size = auto.rate_hz, auto.size
            if not auto.update(now_s):
                return None
        notes = []
        if auto.size != old_size:
            steps = ', '.join(size_tag(s) for s in auto.sizes)
            notes.append(f'model.input_size auto: {size_tag(auto.size)} (was '
                         f'{size_tag(old_size)}; steps {steps}): {auto.reason}')
        if auto.rate_hz != old_rate:
            what = f'{auto.rate_hz:g} Hz' if auto.rate_hz else 'every image'
            was = f'{old_rate:g} Hz' if old_rate else 'every image'
            notes.append(f'inference_rate_hz auto: {what} (was {was}): {auto.reason}')
        return auto.rate_hz != old_rate, notes

    def values(self, frame_ns: Optional[float], now_s: float) -> Dict[str, Any]:
        """Return the /diagnostics values of the rate: mode, in use, own and rig choices."""
        with self.lock:
            if grid_selects(self.hz, frame_ns):
                label: Any = self.hz
            else:
                label = f'{self.hz:g}: every image (camera not faster)' if self.hz else \
                    'every image'
            return {'Inference rate mode': self.mode, 'Inference rate (Hz)': label,
                    'Inference rate, own choice (auto)': (
                        'n/a' if self.auto is None else self.auto.rate_hz or 'every image'),
                    'Inference rate, rig slowest (auto)': (
                        self.rig.slowest(now_s) or 'none announced')}
