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

"""Stamp offsets from arrival delays: the odd camera is named, jitter and phases are not."""

from mv3dpose_ros.core.live.clock_offsets import describe_offset, StampOffsets
import numpy as np

NS = 1_000_000_000
PERIOD = 0.1


def feed(offsets_ms, seconds=10.0, jitter_ms=15.0, phases=True, seed=0, last_arrivals=None):
    """
    Free-running 10 Hz cameras, inference 40 ms + exponential jitter, given stamp offsets.

    ``last_arrivals``: a dict that receives each camera's last arrival [ns].
    """
    rng = np.random.default_rng(seed)
    mon = StampOffsets()
    last = {} if last_arrivals is None else last_arrivals
    for cam, off in offsets_ms.items():
        phase = rng.uniform(0, PERIOD) if phases else 0.0
        for k in range(int(seconds / PERIOD)):
            capture = 100.0 + phase + k * PERIOD
            arrival = capture + 0.040 + rng.exponential(jitter_ms / 1e3)
            last[cam] = int(arrival * NS)
            mon.observe(cam, int((capture + off / 1e3) * NS), last[cam])
    return mon


def test_a_camera_stamped_20_ms_late_is_named_with_its_offset():
    mon = feed({'a': 0, 'b': 0, 'c': 20, 'd': 0})
    (cam, off), = mon.suspects(PERIOD, 0.15, 0.005)
    assert cam == 'c' and abs(off - 0.020) < 0.004
    text = describe_offset(cam, off, PERIOD, '/host2/cam_c/pose2d_node')
    assert 'camera c' in text and f'{off * 1e3:.1f} ms later' in text and 'chrony' in text
    assert '/host2/cam_c/pose2d_node' in text


def test_agreeing_clocks_free_running_phases_and_jitter_raise_nothing():
    for seed in range(5):
        assert feed({'a': 0, 'b': 0, 'c': 0, 'd': 0}, seed=seed).suspects(
            PERIOD, 0.15, 0.005) == []


def test_three_cameras_name_only_the_odd_one_and_early_stamps_read_negative():
    (cam, off), = feed({'a': 0, 'b': -25, 'c': 0}).suspects(PERIOD, 0.15, 0.005)
    assert cam == 'b' and off < -0.018


def test_too_few_messages_say_nothing_and_a_reset_forgets():
    mon = feed({'a': 0, 'b': 30}, seconds=1.0)
    assert mon.offsets_s() == {}
    mon = feed({'a': 0, 'b': 30})
    assert len(mon.suspects(PERIOD, 0.15, 0.005)) == 2     # two cameras: either may be off
    mon.reset()
    assert mon.offsets_s() == {}


def test_a_slower_pipeline_is_not_a_clock_when_the_set_phases_say_otherwise():
    """Delays 25 ms longer but stamps in phase with the rig: a loaded host, not its clock."""
    mon = feed({'a': 0, 'b': 0, 'c': -25, 'd': 0}, phases=False)
    assert [c for c, _ in mon.suspects(PERIOD, 0.15, 0.005)] == ['c']      # delays alone
    in_phase = {'a': 0.0, 'b': 0.0, 'c': 0.0, 'd': 0.0}
    assert mon.suspects(PERIOD, 0.15, 0.005, in_phase) == []
    shifted = {'a': -0.005, 'b': -0.005, 'c': -0.030, 'd': -0.005}            # set means
    (cam, off), = mon.suspects(PERIOD, 0.15, 0.005, shifted)
    assert cam == 'c' and abs(off + 0.025) < 0.004


def test_a_camera_gone_quiet_is_not_judged_on_old_delays():
    last = {}
    mon = feed({'a': 0, 'b': 0, 'c': 30}, last_arrivals=last)
    t = max(last.values())
    for k in range(150):                       # 15 s more of a and b only
        for cam in ('a', 'b'):
            arrival = t + (k + 1) * int(PERIOD * NS)
            mon.observe(cam, arrival - 45_000_000, arrival)
    assert set(mon.offsets_s()) == {'a', 'b'}


def test_a_set_phase_of_the_same_sign_and_size_confirms_the_delay_offset():
    """Delays say 12 ms, the set phase 20 ms: they agree, and the delays' 12 ms is named."""
    mon = feed({'a': 0, 'b': 0, 'c': 12, 'd': 0}, phases=False)
    phases = {'a': -0.005, 'b': -0.005, 'c': 0.015, 'd': -0.005}
    (cam, off), = mon.suspects(PERIOD, 0.1, 0.005, phases)
    assert cam == 'c' and abs(off - 0.012) < 0.003
    assert mon.suspects(PERIOD, 0.1, 0.005, {'a': 0.0, 'b': 0.0, 'c': 0.002, 'd': 0.0}) == []
