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
Each camera's stamp offset against the rest of the rig, from when its messages arrive.

Sets are matched on capture stamps, and in a multi-host rig every host stamps with its own
clock: a camera host whose clock is off by a fraction of a frame period puts views of different
instants into one set, and nothing else would tell. What the fusion host can see is the delay
of each message, arrival (its own clock) minus stamp (the camera host's): the capture, transport
and inference pipeline plus the clock offset. Pipelines of one rig differ little in their
fastest messages, so a camera's low delay quantile standing apart from the other cameras' is
its clock offset (positive: its stamps are later than the rig's, i.e. its clock runs ahead).

Delays alone cannot tell a clock offset from a pipeline that much faster or slower (a
loaded camera host reads as stamped early), so a camera is named only when the phase of its
stamps within the synchronised sets says the same: a clock that is off moves both by the same
amount, a slow pipeline only the delays. Triggered cameras (one capture instant per set) show
such a phase; free-running cameras have phases of their own and an offset there goes unnamed
(it is one more phase for the sets' slop). With two cameras the offset is relative to the
other one: either may be the one that is off.
"""

from collections import deque
from typing import Callable, Deque, Dict, List, Mapping, Optional, Sequence, Tuple

from mv3dpose_ros.core.live.sync_stats import CameraSyncStats
from mv3dpose_ros.core.types import NS_PER_S
import numpy as np

#: Least stamp offset [s] worth a warning, whatever the frame period (arrival jitter).
CLOCK_WARN_FLOOR_S = 0.005


class StampOffsets:
    """Per-camera stamp offsets from arrival delays over a sliding window."""

    def __init__(self, window_s: float = 10.0, min_samples: int = 20,
                 quantile: float = 0.1) -> None:
        self.window_ns = int(window_s * NS_PER_S)
        self.min_samples = int(min_samples)
        self.quantile = float(quantile)
        self._delays: Dict[str, Deque[Tuple[int, int]]] = {}     # camera -> (arrival, delay)
        self._latest_ns = 0                                       # newest arrival of any

    def observe(self, camera: str, stamp_ns: int, arrival_ns: int) -> None:
        """Record one message: ``arrival_ns`` on the fusion host's clock, as the stamps'."""
        q = self._delays.setdefault(camera, deque())
        q.append((arrival_ns, arrival_ns - stamp_ns))
        self._latest_ns = max(self._latest_ns, arrival_ns)
        while q and q[0][0] < arrival_ns - self.window_ns:
            q.popleft()

    def reset(self) -> None:
        """Forget every delay (a clock jump: the old delays say nothing of the new clock)."""
        self._delays.clear()
        self._latest_ns = 0

    def _low_delay_s(self, camera: str) -> Optional[float]:
        q = self._delays.get(camera)
        if not q or len(q) < self.min_samples or q[-1][0] < self._latest_ns - self.window_ns:
            return None                 # too few, or a camera gone quiet: nothing current
        return float(np.quantile([d for _, d in q], self.quantile)) / NS_PER_S

    def offsets_s(self) -> Dict[str, float]:
        """Return each camera's offset [s] against the median of the other cameras'."""
        low = {c: d for c in self._delays if (d := self._low_delay_s(c)) is not None}
        return {c: -v for c, v in relative(low).items()}

    def suspects(self, period_s: float, fraction: float, floor_s: float,
                 phases_s: Optional[Dict[str, float]] = None) -> List[Tuple[str, float]]:
        """
        Return ``(camera, offset_s)`` beyond ``max(fraction x period, floor)``, worst first.

        ``phases_s``: each camera's mean stamp offset within its sets (the synchroniser's);
        when given, a camera is named only where its phase against the other cameras' agrees
        with its delay offset (same sign, the smaller at least 40 % of the larger). The offset
        returned is the delays' (the phase confirms it: it is biased towards 0 by the sets a
        camera shares with cameras that inferred another instant).
        """
        offsets = self.offsets_s()
        limit = max(fraction * period_s, floor_s)
        if phases_s is not None:
            rel = relative(phases_s)
            offsets = {c: o for c, o in offsets.items()
                       if c in rel and o * rel[c] > 0
                       and min(abs(o), abs(rel[c])) >= 0.4 * max(abs(o), abs(rel[c]))}
        found = [(c, o) for c, o in offsets.items() if abs(o) > limit]
        if found and len(offsets) > 2:
            # with three or more cameras the odd one out is the one that is off; a camera the
            # others all agree with is not named because of it
            found = [(c, o) for c, o in found if abs(o) >= 0.5 * max(abs(x) for _, x in found)]
        return sorted(found, key=lambda co: -abs(co[1]))


class ClockCheck:
    """The live loop's watch on the camera host clocks: each second, who stands apart, warned."""

    def __init__(self, camera_ids: Sequence[str], stats: Mapping[str, CameraSyncStats],
                 fraction: float, warn: Callable[[str, str], None]) -> None:
        self.camera_ids = tuple(camera_ids)
        self.stats = stats                # the synchroniser's: usual rates, phases in the sets
        self.fraction = fraction          # sync.offset_warn_fraction (0: off)
        self.warn = warn                  # (throttle key, text)
        #: Each camera's stamp offset against the rest of the rig (a host clock that is off).
        self.offsets = StampOffsets()
        self.suspects: Dict[str, float] = {}     # camera -> offset [s], beyond the limit
        self._checked_ns = 0

    def observe(self, camera: str, stamp_ns: int, clock_ns: int) -> None:
        """Note the message's arrival delay; each second, warn of cameras whose stamps are off."""
        if self.fraction <= 0.0:
            return
        self.offsets.observe(camera, stamp_ns, clock_ns)
        if clock_ns - self._checked_ns < NS_PER_S:
            return
        self._checked_ns = clock_ns
        stats = self.stats
        rates = [r for r in (stats[c].usual_rate_hz for c in self.camera_ids) if r > 0]
        if not rates:
            return
        period_s = 1.0 / float(np.median(rates))
        phases = {c: stats[c].offset_mean_s for c in self.camera_ids}
        self.suspects = dict(
            self.offsets.suspects(period_s, self.fraction, CLOCK_WARN_FLOOR_S, phases))
        for cam, offset_s in self.suspects.items():
            self.warn(f'{cam}:clock_offset', describe_offset(cam, offset_s, period_s))

    def reset(self) -> None:
        """Forget the delays and the named cameras (a clock jump, a reset of the stream)."""
        self.offsets.reset()
        self.suspects = {}


def relative(values: Dict[str, float]) -> Dict[str, float]:
    """Return each finite value minus the median of the other cameras' finite values."""
    finite = {c: v for c, v in values.items() if np.isfinite(v)}
    return {c: v - float(np.median([o for k, o in finite.items() if k != c]))
            for c, v in finite.items() if len(finite) > 1}


def describe_offset(camera: str, offset_s: float, period_s: float,
                    publisher: str = '') -> str:
    """Say what an offset means and what to fix, naming the camera and its publisher."""
    where = f' (published by {publisher})' if publisher else ''
    direction = 'later' if offset_s > 0 else 'earlier'
    return (f'camera {camera}{where}: stamps {abs(offset_s) * 1e3:.1f} ms {direction} than the '
            f'rest of the rig ({abs(offset_s) / period_s:.0%} of its {period_s * 1e3:.0f} ms '
            'frame period; arrival delays and the phase in the sets agree): views of '
            'different instants are fused as one set. Check that host clock (chrony: '
            '`chronyc tracking`; PTP: linuxptp) or the stamping of the camera driver.')
