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
Stamps far from the stream's time: held aside, then dropped, or taken as a sustained jump.

The stream time is the arrival clock less the shortest recent capture -> arrival delay (at
least the newest accepted stamp advanced by the arrival time since). A stamp more than
``jump_s`` from it is an *outlier*; the synchroniser (``core.live.sync``) holds it here. When
the camera's next message is normal again the held ones were glitches and are dropped; when
``jump_confirm`` consecutive outliers on each of at least two cameras agree with each other,
the rig's stamps jumped and the held messages continue the stream.
"""

from collections import deque
from typing import Any, Deque, Dict, List, Optional, Sequence, Tuple

from mv3dpose_ros.core.types import NS_PER_S

#: Accepted messages whose capture -> arrival delay sets the stream time (the shortest).
OFFSET_WINDOW = 64

Held = Tuple[Any, ...]               # a synchroniser entry: (stamp_ns, ...)


class StampOutliers:
    """The stream time of the accepted stamps, and the outliers held aside per camera."""

    def __init__(self, camera_ids: Sequence[str], jump_s: float, jump_confirm: int,
                 max_held: int, ahead_check: bool = True) -> None:
        self.camera_ids = tuple(camera_ids)
        self.jump_ns = int(round(jump_s * NS_PER_S))
        self.jump_confirm = jump_confirm
        self.max_held = max_held                     # per camera; beyond, the oldest goes
        self.ahead_check = ahead_check               # judge stamps ahead on the arrival clock
        self._held: Dict[str, List[Held]] = {c: [] for c in self.camera_ids}
        self._ref: Optional[Tuple[int, int]] = None  # newest accepted stamp, its arrival
        self._delays: Deque[int] = deque(maxlen=OFFSET_WINDOW)   # arrival - stamp, recent

    @property
    def cameras_needed(self) -> int:
        """Return on how many cameras a jump must be seen to be taken."""
        return min(2, len(self.camera_ids))

    @property
    def held(self) -> int:
        """Return the number of outlier messages held aside now."""
        return sum(len(h) for h in self._held.values())

    def offset(self, stamp_ns: int, now: int, own_ns: Optional[int]) -> Optional[int]:
        """
        Return how far ``stamp_ns`` is from the stream time if beyond ``jump_s``, else None.

        Ahead: beyond the stream time, the later of the newest accepted stamp advanced by the
        arrival time since and the arrival clock less the shortest recent delay. Behind:
        before it and also before the camera's own newest stamp ``own_ns``, by ``jump_s``
        each; a camera that merely lags (its own stamps still advance, e.g. its input queue is
        behind on an overloaded host, or it has sent nothing yet) is no outlier: its messages
        are late, not a new timeline.
        """
        if self._ref is None:
            return None
        ref_stamp, ref_arrival = self._ref
        # Stream time: the arrival clock less the shortest recent capture -> arrival delay
        # (at least the newest stamp advanced by the time since it arrived), so detections
        # whose delay varies by seconds (bursts of inference on a loaded host) are not ahead.
        lead = min(self._delays) if self._delays else ref_arrival - ref_stamp
        ahead = stamp_ns - max(ref_stamp + max(0, now - ref_arrival), now - lead)
        if ahead > self.jump_ns and self.ahead_check:
            return ahead
        # A camera with no accepted stamp yet has no timeline to jump from: one whose first
        # detections come seconds after the others' (a slower inference) merely lags.
        if stamp_ns < ref_stamp - self.jump_ns and own_ns is not None and \
                stamp_ns < own_ns - self.jump_ns:
            return stamp_ns - ref_stamp
        return None

    def accepted(self, stamp_ns: int, arrival_ns: int) -> None:
        """Advance the stream time with an accepted message."""
        if self._ref is None or stamp_ns > self._ref[0]:
            self._ref = (stamp_ns, arrival_ns)
        self._delays.append(arrival_ns - stamp_ns)

    def forget_time(self) -> None:
        """Forget the stream time (the next accepted stamp starts it again)."""
        self._ref = None
        self._delays.clear()

    def hold(self, cam: str, entry: Held) -> int:
        """Hold an outlier of ``cam``; return how many held ones it pushed out (0 or 1)."""
        held = self._held[cam]
        held.append(entry)
        if len(held) > self.max_held:
            held.pop(0)
            return 1
        return 0

    def drop(self, cam: str) -> int:
        """Drop the outliers held for ``cam`` (isolated glitches); return how many."""
        n = len(self._held[cam])
        self._held[cam].clear()
        return n

    def take(self) -> Dict[str, List[Held]]:
        """Return every camera's held outliers, oldest first, and hold none."""
        held = {c: list(self._held[c]) for c in self.camera_ids}
        for c in self.camera_ids:
            self._held[c].clear()
        return held

    def sustained_jump(self) -> List[str]:
        """Return the cameras whose held outliers agree on a new timeline (empty: none)."""
        cams = [c for c in self.camera_ids if len(self._held[c]) >= self.jump_confirm]
        need = self.cameras_needed
        if len(cams) < need:
            return []
        newest = {c: max(e[0] for e in self._held[c]) for c in cams}
        for c in cams:
            group = [d for d in cams if abs(newest[d] - newest[c]) <= self.jump_ns]
            if len(group) >= need:
                return group
        return []
