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
A small ``/diagnostics`` publisher with diagnostic_updater's key names.

``diagnostic_updater`` is not in the wheels. This keeps its conventions so that
``rqt_robot_monitor`` and aggregators read our status as usual: status name
``"<node name>: <task>"``, hardware id, levels OK/WARN/ERROR/STALE, the FrequencyStatus and
TimeStampStatus keys. Stamp delays are measured against the node clock, so they stay right
under ``use_sim_time`` (bag replay); the publish timer and the log throttle run on the steady
clock, so a stalled ``/clock`` is still reported. The statistics classes take times in
nanoseconds, so pose2d_node and fusion_node share them.
"""

from collections import deque
import math
import time
from typing import Any, Callable, Deque, Dict, List, Optional, Tuple

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from mv3dpose_ros.core.types import NS_PER_S
from mv3dpose_ros.ros.qos import publisher_events, reliable_qos
from rclpy.clock import Clock, ClockType

OK = DiagnosticStatus.OK
WARN = DiagnosticStatus.WARN
ERROR = DiagnosticStatus.ERROR
STALE = DiagnosticStatus.STALE


def _level(value: Any) -> bytes:
    return value if isinstance(value, bytes) else bytes([int(value)])


def level_value(level: Any) -> int:
    """Return a status level (bytes as in the message, or int) as an int for comparisons."""
    return level[0] if isinstance(level, (bytes, bytearray)) else int(level)


def format_value(value: Any) -> str:
    """Format a diagnostic value: floats with 4 significant digits, NaN as 'n/a'."""
    if isinstance(value, float):
        return 'n/a' if not math.isfinite(value) else f'{value:.4g}'
    return str(value)


def make_status(name: str, level: Any, message: str, hardware_id: str = '',
                values: Optional[Dict[str, Any]] = None) -> DiagnosticStatus:
    """Build one ``DiagnosticStatus``; values are formatted with ``format_value``."""
    return DiagnosticStatus(
        level=_level(level), name=name, message=message, hardware_id=hardware_id,
        values=[KeyValue(key=str(k), value=format_value(v)) for k, v in (values or {}).items()])


class FrequencyStats:
    """
    Event rate over a sliding window (diagnostic_updater FrequencyStatus semantics).

    The window holds the last ``window_size`` publish cycles' event counts; the rate is the
    events in the window over the window's duration. ``tolerance`` widens the acceptable band
    around ``min_hz``/``max_hz``.
    """

    def __init__(self, min_hz: float = 0.0, max_hz: float = math.inf, tolerance: float = 0.1,
                 window_size: int = 5) -> None:
        self.min_hz, self.max_hz, self.tolerance = min_hz, max_hz, tolerance
        self._count = 0
        self._hist: Deque[Tuple[int, int]] = deque(maxlen=window_size + 1)  # (now_ns, count)
        self.total = 0

    def tick(self, n: int = 1) -> None:
        """Count ``n`` events."""
        self._count += n
        self.total += n

    def sample(self, now_ns: int) -> Tuple[Any, str, Dict[str, Any]]:
        """Close one cycle at ``now_ns``; return (level, message, values)."""
        self._hist.append((int(now_ns), self._count))
        t0, c0 = self._hist[0]
        events = self._count - c0
        span = (now_ns - t0) / NS_PER_S
        freq = events / span if span > 0 else math.nan
        values = {'Events in window': events, 'Events since startup': self.total,
                  'Duration of window (s)': span, 'Actual frequency (Hz)': freq}
        if self.min_hz == self.max_hz:
            values['Target frequency (Hz)'] = self.min_hz
        if self.min_hz > 0:
            values['Minimum acceptable frequency (Hz)'] = self.min_hz * (1 - self.tolerance)
        if math.isfinite(self.max_hz):
            values['Maximum acceptable frequency (Hz)'] = self.max_hz * (1 + self.tolerance)
        if not math.isfinite(freq):
            return OK, 'Waiting for data', values
        if events == 0 and self.min_hz > 0:
            return ERROR, 'No events recorded.', values
        if freq < self.min_hz * (1 - self.tolerance):
            return WARN, 'Frequency too low.', values
        if freq > self.max_hz * (1 + self.tolerance):
            return WARN, 'Frequency too high.', values
        return OK, 'Desired frequency met', values


class TimestampStats:
    """
    Header-stamp delays (diagnostic_updater TimeStampStatus semantics), per publish cycle.

    Delay = node-clock now - header stamp at receipt. Stamps that are zero, or beyond
    ``max_future_s`` ahead / ``max_past_s`` behind now, are counted as errors.
    """

    def __init__(self, max_past_s: float = 5.0, max_future_s: float = 0.5) -> None:
        self.max_past_s, self.max_future_s = max_past_s, max_future_s
        self.zero_seen = 0               # this cycle
        self.out_of_range = 0            # this cycle
        self.zero_total = 0
        self.out_of_range_total = 0
        self._delays: List[float] = []
        self.last_stamp_ns: Optional[int] = None

    def record(self, stamp_ns: int, now_ns: int) -> None:
        """Record one header stamp received at ``now_ns`` (node clock)."""
        if stamp_ns <= 0:
            self.zero_seen += 1
            self.zero_total += 1
            return
        delay = (now_ns - stamp_ns) / NS_PER_S
        if delay > self.max_past_s or -delay > self.max_future_s:
            self.out_of_range += 1
            self.out_of_range_total += 1
        self._delays.append(delay)
        self.last_stamp_ns = stamp_ns

    def sample(self) -> Tuple[Any, str, Dict[str, Any]]:
        """Close one cycle; return (level, message, values) of the stamps seen in it."""
        values = {'Earliest timestamp delay:': min(self._delays, default=math.nan),
                  'Latest timestamp delay:': max(self._delays, default=math.nan),
                  'Zero timestamps seen (total)': self.zero_total,
                  'Timestamps out of range (total)': self.out_of_range_total}
        zero, out = self.zero_seen, self.out_of_range
        self._delays, self.zero_seen, self.out_of_range = [], 0, 0
        if zero:
            return ERROR, 'Zero timestamp seen.', values
        if out:
            return ERROR, 'Timestamps too far in past/future seen.', values
        return OK, 'Timestamps are reasonable.', values


class WindowStats:
    """Recent values (bounded) with median / p95 / max, e.g. latency in seconds."""

    def __init__(self, size: int = 300) -> None:
        self._values: Deque[float] = deque(maxlen=size)

    def add(self, value: float) -> None:
        """Record one value (non-finite values are ignored)."""
        if math.isfinite(value):
            self._values.append(float(value))

    def __len__(self) -> int:
        return len(self._values)

    def percentile(self, q: float) -> float:
        """Return the nearest-rank percentile ``q`` (0..100) of the window, NaN when empty."""
        if not self._values:
            return math.nan
        ordered = sorted(self._values)
        k = min(len(ordered) - 1, max(0, math.ceil(q / 100.0 * len(ordered)) - 1))
        return ordered[k]


class RateLimitedLog:
    """
    Log a message per key at most once per ``period_s``, counting the rest.

    Times are on the steady clock (``time.monotonic_ns``) unless the caller passes its own
    ``now_ns``: a stalled sim clock must not silence (or flood) the log.
    """

    def __init__(self, log: Callable[[str], None], period_s: float = 5.0) -> None:
        self._log = log
        self._period_ns = int(period_s * NS_PER_S)
        self._last: Dict[str, int] = {}
        self._suppressed: Dict[str, int] = {}

    def __call__(self, key: str, text: str, now_ns: Optional[int] = None) -> bool:
        """Log ``text`` unless ``key`` was logged within the period; return whether logged."""
        if now_ns is None:
            now_ns = time.monotonic_ns()
        last = self._last.get(key)
        if last is not None and 0 <= now_ns - last < self._period_ns:
            self._suppressed[key] = self._suppressed.get(key, 0) + 1
            return False
        skipped = self._suppressed.pop(key, 0)
        suffix = f' ({skipped} similar messages suppressed)' if skipped else ''
        self._log(text + suffix)
        self._last[key] = now_ns
        return True


class Diagnostics:
    """
    Periodic ``/diagnostics`` publisher for one node.

    Tasks are callables returning a list of statuses (``make_status``); they are called on a
    steady-clock timer every ``period_s`` (so a stalled or paused ``/clock`` under sim time
    cannot stop the reports that would say so), and their statuses are published in one
    ``DiagnosticArray`` stamped with the node clock.
    """

    def __init__(self, node: Any, period_s: float = 1.0, topic: str = '/diagnostics') -> None:
        self.node = node
        self.prefix = node.get_name()
        qos = reliable_qos(10)
        self.publisher = node.create_publisher(
            DiagnosticArray, topic, qos, event_callbacks=publisher_events(node, topic, qos))
        self._tasks: List[Callable[[], List[DiagnosticStatus]]] = []
        self.timer = node.create_timer(period_s, self.publish,
                                       clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.last: Optional[DiagnosticArray] = None

    def name(self, task: str) -> str:
        """Return the status name ``"<node name>: <task>"``."""
        return f'{self.prefix}: {task}'

    def add_task(self, task: Callable[[], List[DiagnosticStatus]]) -> None:
        """Register a callable producing statuses each cycle."""
        self._tasks.append(task)

    def now_ns(self) -> int:
        """Return node-clock now in nanoseconds (sim time aware)."""
        return self.node.get_clock().now().nanoseconds

    def publish(self) -> DiagnosticArray:
        """Collect all tasks' statuses and publish them; a failing task reports ERROR."""
        msg = DiagnosticArray()
        msg.header.stamp = self.node.get_clock().now().to_msg()
        for task in self._tasks:
            try:
                msg.status.extend(task())
            except Exception as exc:  # noqa: B902 - diagnostics must never stop the node
                msg.status.append(make_status(self.name('diagnostics'), ERROR,
                                              f'diagnostic task failed: {exc!r}'))
        self.publisher.publish(msg)
        self.last = msg
        return msg

    def destroy(self) -> None:
        """Stop the timer and the publisher."""
        self.node.destroy_timer(self.timer)
        self.node.destroy_publisher(self.publisher)
