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
How wide a synchronised set is: in stamp time (the slop) and in arrival time (the wait).

Both adapt to the rig (see ``core.live.sync``): the slop to half the shortest camera frame
period, so consecutive frames of a camera never merge; the wait to the arrival spread of the
recent sets' messages, so cameras whose inference finishes far apart lose no set.
"""

from collections import deque
import math
from typing import Deque, Iterable, Mapping, Optional, Tuple

from mv3dpose_ros.core.live.sync_stats import CameraSyncStats
from mv3dpose_ros.core.types import NS_PER_S

#: Slop used while no camera's period is known yet (half a 60 fps period).
INITIAL_SLOP_S = 0.008
#: Arrival spreads kept for the adaptive wait, and needed before it adapts.
SPREAD_WINDOW, SPREAD_MIN = 128, 4
#: The adaptive wait is this factor times the p95 of the recent arrival spreads.
SPREAD_FACTOR = 1.3
#: Decided sets remembered to measure how late their late messages came.
DECIDED_WINDOW = 64


class AdaptiveSlop:
    """A set's stamp window: ``slop_s``, narrowed to half the shortest camera frame period."""

    def __init__(self, slop_s: float) -> None:
        self.slop_s = slop_s
        self.configured_ns = int(round(slop_s * NS_PER_S))      # 0: follow the frame period
        self.slop_ns = self.configured_ns or int(INITIAL_SLOP_S * NS_PER_S)
        self.frame_period_ns: Optional[int] = None   # shortest camera period seen now
        self.note = ''                               # set once when slop_s had to be narrowed

    def update(self, stats: Mapping[str, CameraSyncStats]) -> None:
        """Follow the shortest camera period in ``stats``."""
        periods = [(s.period_ns, c) for c, s in stats.items() if s.period_ns]
        if not periods:
            return
        period, cam = min(periods)
        self.frame_period_ns = period
        half = period // 2
        if not self.configured_ns:
            self.slop_ns = half
            return
        self.slop_ns = min(self.configured_ns, half)
        if self.configured_ns > half and not self.note:
            self.note = (
                f'sync.slop_s {self.slop_s:g} s is wider than half the observed frame '
                f'period ({period / 1e6:.1f} ms = {NS_PER_S / period:.1f} Hz, camera {cam}): '
                f'using {half / NS_PER_S:.4f} s so consecutive frames of a camera do not merge '
                f'(set sync.slop_s to 0 to follow the frame rate)')


class AdaptiveWait:
    """A set's wait on the arrival clock: ``max(max_wait, 1.3 x p95 spread)``, capped."""

    def __init__(self, max_wait_s: float, cap_s: float) -> None:
        self.floor_ns = int(round(max_wait_s * NS_PER_S))
        self.cap_ns = max(self.floor_ns, int(round(cap_s * NS_PER_S)))
        self.max_wait_ns = self.floor_ns             # the wait in use
        self._spreads: Deque[int] = deque(maxlen=SPREAD_WINDOW)
        self._decided: Deque[Tuple[int, int, int]] = deque(maxlen=DECIDED_WINDOW)

    @property
    def spread_p95_s(self) -> float:
        """Return the p95 arrival spread of the recent sets' messages [s] (NaN before any)."""
        if not self._spreads:
            return math.nan
        ordered = sorted(self._spreads)
        return ordered[min(len(ordered) - 1, int(0.95 * len(ordered)))] / NS_PER_S

    def decided(self, lo_ns: int, hi_ns: int, first_ns: int, arrivals_ns: Iterable[int]) -> None:
        """Record a decided set: its stamp window, first arrival and members' arrivals."""
        self._decided.append((lo_ns, hi_ns, first_ns))
        self._spreads.extend(a - first_ns for a in arrivals_ns)
        self._adapt()

    def late(self, stamp_ns: int, arrival_ns: int) -> None:
        """Record how long after its set's first message a late message arrived."""
        for lo, hi, first in reversed(self._decided):
            if lo <= stamp_ns <= hi:
                self._spreads.append(max(0, arrival_ns - first))
                self._adapt()
                return

    def forget_sets(self) -> None:
        """Forget the decided sets (the stamps start again); the spreads are kept."""
        self._decided.clear()

    def _adapt(self) -> None:
        if len(self._spreads) < SPREAD_MIN:
            return
        want = int(SPREAD_FACTOR * self.spread_p95_s * NS_PER_S)
        self.max_wait_ns = min(max(self.floor_ns, want), self.cap_ns)
