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
What the synchroniser counts: per camera, and of its decisions over the whole rig.

``StreamSynchronizer.stats`` (camera id -> ``CameraSyncStats``) and ``.counts``
(``SyncCounts``) are what ``/diagnostics`` reports; both count since construction, and a
reset keeps them.
"""

from collections import Counter, deque
from dataclasses import dataclass, field
import math
from typing import Deque, Iterable, Optional, Tuple

from mv3dpose_ros.core.types import NS_PER_S

#: Stamp steps kept per camera for its frame period (lower quartile).
PERIOD_WINDOW = 16
#: Steps needed before a camera's period is trusted.
PERIOD_MIN_STEPS = 4


@dataclass
class CameraSyncStats:
    """Per-camera counters (since construction; ``reset`` keeps them) and recent offsets."""

    received: int = 0                # messages passed to ``add``
    used: int = 0                    # messages emitted in a set
    dropped: int = 0                 # messages discarded unused (all reasons)
    late: int = 0                    # ... arrived after their set was decided
    outliers: int = 0                # ... isolated outlier stamps
    missing: int = 0                 # emitted sets without this camera
    lost: int = 0                    # frames missing from the stamp sequence (upstream loss)
    skipped: int = 0                 # ... of them announced as skipped by the camera (``skip``)
    latest_stamp_ns: Optional[int] = None
    last_seen_ns: Optional[int] = None       # newest stamp seen (accepted or not): rate, gaps
    last_arrival_ns: Optional[int] = None
    period_ns: Optional[int] = None          # lower quartile of the recent stamp steps
    usual_period_ns: Optional[int] = None    # shortest sustained period seen (usual rate)
    offsets_ns: Deque[int] = field(default_factory=deque)  # stamp - set stamp, recent used
    steps_ns: Deque[int] = field(default_factory=lambda: deque(maxlen=PERIOD_WINDOW))
    unmatched: Counter = field(default_factory=Counter)   # decided unused: reason -> count

    @property
    def offset_mean_s(self) -> float:
        """Mean offset of this camera's stamps to the set stamps (NaN before any use)."""
        if not self.offsets_ns:
            return math.nan
        return sum(self.offsets_ns) / len(self.offsets_ns) / NS_PER_S

    @property
    def offset_jitter_s(self) -> float:
        """Return the standard deviation of the offsets (NaN before any use)."""
        n = len(self.offsets_ns)
        if n == 0:
            return math.nan
        mean = sum(self.offsets_ns) / n
        return math.sqrt(sum((o - mean) ** 2 for o in self.offsets_ns) / n) / NS_PER_S

    @property
    def rate_hz(self) -> float:
        """Recent frame rate from the stamps (NaN until known)."""
        return NS_PER_S / self.period_ns if self.period_ns else math.nan

    @property
    def usual_rate_hz(self) -> float:
        """Highest sustained frame rate seen from the stamps (NaN until known)."""
        return NS_PER_S / self.usual_period_ns if self.usual_period_ns else math.nan

    def observe_step(self, stamp_ns: int, gaps: Iterable[Tuple[int, int]] = ()) -> None:
        """
        Update period, usual period and upstream losses with a stamp newer than the last.

        Frames missing inside one of the announced ``gaps`` (after, before) are counted as
        skipped, not lost.
        """
        last, self.last_seen_ns = self.last_seen_ns, max(stamp_ns, self.last_seen_ns or 0)
        if last is None or stamp_ns <= last:
            return
        step = stamp_ns - last
        if self.usual_period_ns and step > 1.5 * self.usual_period_ns:
            missed = int(round(step / self.usual_period_ns)) - 1
            if any(after <= last and stamp_ns <= before for after, before in gaps):
                self.skipped += missed
            else:
                self.lost += missed
        self.steps_ns.append(step)
        if len(self.steps_ns) >= PERIOD_MIN_STEPS:
            # The lower quartile of the steps, not their median: with a third or more of a
            # camera's frames missing (a CPU that cannot infer them all) the median step is
            # two periods, and a slop of half that would merge consecutive instants.
            self.period_ns = int(sorted(self.steps_ns)[len(self.steps_ns) // 4])
            if len(self.steps_ns) == PERIOD_WINDOW and (
                    self.usual_period_ns is None or self.period_ns < self.usual_period_ns):
                self.usual_period_ns = self.period_ns


@dataclass
class SyncCounts:
    """The synchroniser's decisions, over every camera (since construction)."""

    sets_emitted: int = 0
    partial_sets: int = 0            # ... of them with a camera missing
    pivots_dropped: int = 0          # decided pivots with < min_views cameras
    overflow_decisions: int = 0      # pivots decided early: a queue was full
    decisions: Counter = field(default_factory=Counter)    # why incomplete sets were decided
    resets: int = 0
    forward_jumps: int = 0           # sustained forward jumps taken, no reset
