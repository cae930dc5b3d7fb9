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

"""Unit tests of ros/diagnostics.py statistics, ros/qos.py profiles and ros/params.py."""

from dataclasses import dataclass, field
import math
import time
from typing import List, Tuple

from mv3dpose_ros.core.live.sync import SyncConfig
from mv3dpose_ros.ros import params as P
from mv3dpose_ros.ros.diagnostics import (ERROR, FrequencyStats, level_value, make_status, OK,
                                          RateLimitedLog, TimestampStats, WARN, WindowStats)
from mv3dpose_ros.ros.qos import (describe, latched_qos, parse_reliability, reliable_qos,
                                  sensor_qos, subscription_events)
from mv3dpose_ros.testing.spin import spin_until
import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.qos import QoSDurabilityPolicy, QoSReliabilityPolicy
from std_msgs.msg import String

S = 1_000_000_000


def test_frequency_stats_window_rate_and_levels():
    f = FrequencyStats(min_hz=10.0, max_hz=10.0, tolerance=0.1, window_size=5)
    level, msg, _ = f.sample(0)
    assert level == OK and msg == 'Waiting for data'
    for k in range(1, 6):
        f.tick(10)
        level, msg, values = f.sample(k * S)
    assert values['Actual frequency (Hz)'] == pytest.approx(10.0)
    assert values['Events in window'] == 50 and level == OK
    assert values['Target frequency (Hz)'] == 10.0
    f.tick(2)
    level, msg, values = f.sample(6 * S)
    assert values['Actual frequency (Hz)'] == pytest.approx(42 / 5)
    assert level == WARN and msg == 'Frequency too low.'
    for k in range(7, 13):
        level, msg, _ = f.sample(k * S)
    assert level == ERROR and msg == 'No events recorded.'
    assert f.total == 52


def test_timestamp_stats_zero_future_past_per_cycle():
    ts = TimestampStats(max_past_s=5.0, max_future_s=0.5)
    ts.record(100 * S, 101 * S)
    ts.record(int(100.5 * S), 101 * S)
    level, msg, v = ts.sample()
    assert level == OK and v['Earliest timestamp delay:'] == pytest.approx(0.5)
    assert v['Latest timestamp delay:'] == pytest.approx(1.0)
    ts.record(0, 101 * S)
    assert ts.sample()[:2] == (ERROR, 'Zero timestamp seen.')
    ts.record(200 * S, 101 * S)
    level, msg, v = ts.sample()
    assert level == ERROR and 'past/future' in msg
    level, _, v = ts.sample()           # a new cycle without bad stamps is OK again
    assert level == OK and math.isnan(v['Earliest timestamp delay:'])
    assert v['Zero timestamps seen (total)'] == 1 and v['Timestamps out of range (total)'] == 1


def test_window_stats_nearest_rank_and_bounded():
    w = WindowStats(size=100)
    assert math.isnan(w.percentile(50))
    for v in range(1, 201):
        w.add(float(v))
    w.add(float('nan'))
    assert len(w) == 100
    assert w.percentile(50) == 150.0 and w.percentile(95) == 195.0 and w.percentile(100) == 200


def test_rate_limited_log_counts_suppressed():
    lines = []
    log = RateLimitedLog(lines.append, period_s=1.0)
    assert log('a', 'first', 0)
    assert not log('a', 'again', int(0.5 * S))
    assert log('b', 'other key', int(0.6 * S))
    assert log('a', 'later', int(1.2 * S))
    assert lines == ['first', 'other key', 'later (1 similar messages suppressed)']


def test_rate_limited_log_defaults_to_the_steady_clock():
    """Without a caller clock it throttles on time.monotonic_ns (not a stallable /clock)."""
    lines = []
    log = RateLimitedLog(lines.append, period_s=0.2)
    assert log('k', 'one') and not log('k', 'two')
    time.sleep(0.25)
    assert log('k', 'three')
    assert lines == ['one', 'three (1 similar messages suppressed)']


def test_make_status_formats_values():
    s = make_status('n: t', WARN, 'm', 'hw', {'f': 1.234567, 'nan': float('nan'), 'i': 3})
    assert level_value(s.level) == 1 and s.hardware_id == 'hw'
    assert {kv.key: kv.value for kv in s.values} == {'f': '1.235', 'nan': 'n/a', 'i': '3'}


def test_qos_profiles():
    p = sensor_qos()
    assert p.reliability == QoSReliabilityPolicy.BEST_EFFORT and p.depth == 5
    assert sensor_qos('reliable', 3).reliability == QoSReliabilityPolicy.RELIABLE
    assert describe(reliable_qos(10)) == 'RELIABLE VOLATILE KEEP_LAST(10)'
    latched = latched_qos()
    assert latched.durability == QoSDurabilityPolicy.TRANSIENT_LOCAL and latched.depth == 1
    assert parse_reliability(' Best_Effort ') == QoSReliabilityPolicy.BEST_EFFORT
    with pytest.raises(ValueError, match='best_effort, reliable'):
        parse_reliability('sometimes')
    with pytest.raises(ValueError, match='depth'):
        sensor_qos('reliable', 0)


@dataclass
class _Inner:
    gain: float = 2          # an int default of a float field
    names: Tuple[str, ...] = ('a', 'b')  # names of things


@dataclass
class _Outer:
    threshold_m: float = 0.2     # gate in metres
    count: int = 3
    enabled: bool = True         # a comment that goes
    #                              on over two lines
    # a section comment, not a continuation
    mode: str = 'x'
    inner: _Inner = field(default_factory=_Inner)
    skipped: List[dict] = field(default_factory=list)


def test_dataclass_parameters_from_comments():
    rows = {r['name']: r for r in P.dataclass_parameters(_Outer, 'cfg')}
    assert set(rows) == {'cfg.threshold_m', 'cfg.count', 'cfg.enabled', 'cfg.mode',
                         'cfg.inner.gain', 'cfg.inner.names'}
    assert rows['cfg.threshold_m']['description'] == 'gate in metres'
    assert rows['cfg.inner.gain']['default'] == 2.0 and rows['cfg.inner.gain']['type'] is float
    assert rows['cfg.count']['description'] == 'count'
    assert rows['cfg.enabled']['description'] == 'a comment that goes on over two lines'
    sync = {r['name'] for r in P.dataclass_parameters(SyncConfig, 'sync')}
    assert 'sync.slop_s' in sync


def test_declare_and_build_config_with_overrides(ros_context):
    node = rclpy.create_node('params_probe', context=ros_context, parameter_overrides=[
        Parameter('cfg.threshold_m', value=0.5), Parameter('cfg.inner.names', value=['z']),
        Parameter('cfg.inner.gain', value=3.0)])
    try:
        P.declare_config(node, _Outer, 'cfg')
        P.declare(node, 'ids', [], 'camera ids', read_only=True)
        cfg = P.build_config(node, _Outer, 'cfg')
        assert cfg == _Outer(threshold_m=0.5, inner=_Inner(gain=3.0, names=('z',)))
        assert P.value(node, 'ids', []) == []
        desc = node.describe_parameter('cfg.threshold_m')
        assert desc.description == 'gate in metres' and desc.read_only
        docs = {d['name']: d for d in P.all_parameter_docs(node)}
        assert docs['cfg.count']['default'] == 3 and docs['cfg.count']['type'] == 'integer'
    finally:
        node.destroy_node()


@pytest.mark.ros
def test_incompatible_qos_reported_with_topic_and_both_profiles(ros_context):
    node = rclpy.create_node('qos_probe', context=ros_context)
    errors = []
    topic = '/qos_probe_topic'
    try:
        qos = reliable_qos(10)
        node.create_subscription(String, topic, lambda m: None, qos,
                                 event_callbacks=subscription_events(node, topic, qos,
                                                                     errors.append))
        node.create_publisher(String, topic, sensor_qos('best_effort', 5))
        ex = SingleThreadedExecutor(context=ros_context)
        ex.add_node(node)
        assert spin_until(ex, lambda: errors, timeout=10.0)
        text = errors[0]
        assert topic in text and 'RELIABILITY' in text
        assert 'This subscription: [RELIABLE VOLATILE KEEP_LAST(10)]' in text
        assert 'publishers: /qos_probe [BEST_EFFORT VOLATILE]' in text
        ex.shutdown()
    finally:
        node.destroy_node()
