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

"""The inference-rate policy of pose2d_node, without ROS: grids, auto mode, size ladder."""

import math

from mv3dpose_ros.pose2d.auto_rate import (AUTO_LOSS, AUTO_UP, AUTO_UP_DWELL_S, AUTO_UP_EVERY,
                                           AutoInferenceRate, RigRate)
from mv3dpose_ros.pose2d.scheduling import (AUTO_RATES_HZ, frame_period_ns, grid_period_ns,
                                            grid_selects, on_new_window, RIG_AUTO_RATES_HZ,
                                            size_ladder)
import numpy as np
import pytest

NS = 1_000_000_000


def test_frame_period_is_one_estimate_for_the_grid_and_the_auto_mode():
    """A 1 Hz camera has a period (a 1.25 Hz grid infers its every image); pauses do not count."""
    slow = [(None, 1000 * NS + k * NS, 1) for k in range(6)]
    assert frame_period_ns(slow) == NS
    assert not grid_selects(1.25, NS) and grid_selects(0.625, NS)
    paused = slow + [(None, 1030 * NS, 1), (None, 1031 * NS, 1)]    # a 25 s stall, then 1 Hz
    assert frame_period_ns(paused) == NS
    skipped = [(None, 1000 * NS, 1), (None, 1000 * NS + 300_000_000, 3)]  # 2 never taken
    assert frame_period_ns(skipped) == 100_000_000
    assert frame_period_ns(skipped, min_steps=4) is None and frame_period_ns(slow[:1]) is None
    auto = AutoInferenceRate()
    for k in range(4):
        auto.add_stamp(1000 * NS + k * NS)
    assert math.isnan(auto.input_hz)                  # 3 steps: not yet
    auto.add_stamp(1004 * NS)
    assert auto.input_hz == pytest.approx(1.0)


def test_auto_rate_chain_grids_are_nested():
    """Every slower auto rate infers a subset of the instants of every faster one."""
    assert all(a == 2 * b for a, b in zip(AUTO_RATES_HZ, AUTO_RATES_HZ[1:]))
    rng = np.random.default_rng(0)
    # 25 Hz free-running camera with capture jitter and missing frames, 60 s
    stamps = sorted(int(1000 * NS + k * 40_000_000 + rng.integers(-3_000_000, 3_000_000))
                    for k in range(1500) if rng.random() > 0.1)
    taken = {}
    for rate in AUTO_RATES_HZ:
        last, sel = None, set()
        for s in stamps:
            if on_new_window(s, last, grid_period_ns(rate)):
                sel.add(s)
                last = s
        taken[rate] = sel
    for fast, slow in zip(AUTO_RATES_HZ, AUTO_RATES_HZ[1:]):
        assert taken[slow] <= taken[fast] and len(taken[slow]) < len(taken[fast])
    assert abs(len(taken[0.625]) - 60 * 0.625) <= 1


def test_rig_rates_step_finer_and_keep_the_nested_ones():
    assert set(AUTO_RATES_HZ) < set(RIG_AUTO_RATES_HZ)
    steps = [a / b for a, b in zip(RIG_AUTO_RATES_HZ, RIG_AUTO_RATES_HZ[1:])]
    assert all(1.3 < s <= 1.5 + 1e-9 for s in steps)
    auto = AutoInferenceRate(rates=RIG_AUTO_RATES_HZ)
    t = 0.0
    for _ in range(10):                      # 400 ms per image at 10 Hz, free-running
        for _ in range(10):
            auto.add_stamp(int(1000 * NS + t * NS))
            t += 0.1
        if auto.rate_hz == 0.0:
            for _ in range(8):
                auto.add_replaced()
        auto.add_processing(0.4)
        auto.update(t)
    # at most 2.5 Hz, 0.7 of it 1.75 Hz: 5/3 Hz on the rig's grid (1.25 Hz on the nested one)
    assert auto.rate_hz == pytest.approx(5 / 3)
    assert auto.fastest(2.0) == pytest.approx(5 / 3)
    assert auto.fastest(0.01) == RIG_AUTO_RATES_HZ[-1]             # the slowest
    assert 0.7 / 0.28 < 2.5 and auto.fastest(0.7 / 0.28) == 2.5   # not a step lower

    def load(seconds_per_image, n=10):
        nonlocal t
        seen = []
        for _ in range(n):
            for _ in range(10):
                auto.add_stamp(int(1000 * NS + t * NS))
                t += 0.1
            auto.add_processing(seconds_per_image)
            if auto.update(t):
                seen.append(auto.rate_hz)
        return seen
    # a mild overload (5/3 Hz x 0.6 s = 1.0 of the period): one rate slower, not to 0.7 of it
    assert load(0.6) == [1.25]
    # a heavy one (1.25 Hz x 1.5 s = 1.9): straight to 0.7 x 0.67 Hz -> 5/12 Hz
    assert load(1.5) == [pytest.approx(5 / 12)]


def test_auto_rate_choice_follows_load_with_hysteresis():
    auto = AutoInferenceRate()
    t = 0.0

    def run(seconds_per_image, fps, n, step_s=1.0, paced=False):
        nonlocal t
        changes = []
        for _ in range(n):
            for _ in range(int(fps * step_s)):
                auto.add_stamp(int(1000 * NS + t * NS))
                t += 1.0 / fps
            if not paced and auto.rate_hz == 0.0:
                for _ in range(max(0, int(fps * step_s) - int(step_s / seconds_per_image))):
                    auto.add_replaced()              # what the mailbox replaces meanwhile
            auto.add_processing(seconds_per_image)
            if auto.update(t):
                changes.append(auto.rate_hz)
        return changes

    assert run(0.05, 10.0, 10) == []                # 50 ms per 100 ms frame: every image
    assert auto.rate_hz == 0.0
    # 400 ms per image at 10 Hz: at most 2.5 Hz, 0.7 of it -> 1.25 Hz, after the dwell time
    assert run(0.4, 10.0, 10) == [1.25]
    assert run(0.4, 10.0, 30) == []                 # steady: no flapping
    assert run(0.5, 10.0, 10) == []                 # 1.25 Hz x 0.5 s = 0.62 < 0.9: kept
    assert run(0.8, 10.0, 10) == [0.625]            # 1.0 > 0.9: one step slower
    assert run(0.55, 10.0, 10) == []                # 2 x 0.625 x 0.55 > 0.6: not faster yet
    # faster again, one step per AUTO_UP_DWELL_S (10 s here)
    assert run(0.2, 10.0, 10) == [1.25] and run(0.2, 10.0, 10) == [2.5]
    assert run(0.02, 10.0, 5) == []                 # keeps up, but not for 10 s yet
    assert run(0.02, 10.0, 10) == [0.0]             # keeps up: every image
    assert 'images at 10.00 Hz' in auto.reason
    # slow, but a player waits for each output (nothing replaced): every image
    auto = AutoInferenceRate()
    assert run(2.0, 1.0, 10, paced=True) == [] and auto.rate_hz == 0.0
    assert run(2.0, 1.0, 10) == [0.3125]            # the same, free-running: a grid


def test_rig_rate_is_the_slowest_announced_and_forgets_the_silent():
    rig = RigRate(ttl_s=3.0)
    assert rig.common(0.0, 0.0) == 0.0 and rig.common(5.0, 0.0) == 5.0     # nothing heard
    assert rig.hear(2.5, 0.0) and rig.hear(0.0, 0.5) and rig.hear(10.0, 1.0)
    assert rig.slowest(1.0) == 2.5
    assert rig.common(0.0, 1.0) == 2.5 and rig.common(5.0, 1.0) == 2.5      # rig slower
    assert rig.common(1.25, 1.0) == 1.25                                    # own slower
    for bad in (float('nan'), float('inf'), -1.0):
        assert not rig.hear(bad, 1.0)
    assert rig.common(0.0, 3.5) == 10.0          # 2.5 Hz unheard for 3.5 s: gone
    assert rig.common(0.0, 4.5) == 0.0           # all gone: every image again


def test_auto_mode_shrinks_the_input_before_the_rate_and_grows_it_back():
    ladder = [(384, 640), (288, 512), (224, 384)]
    auto = AutoInferenceRate(ladder)
    t = 0.0
    # Inference time of each size in this made-up node: proportional to its pixels.
    cost = {(384, 640): 0.2, (288, 512): 0.12, (224, 384): 0.07}

    def run(load, n, fps=10.0):
        nonlocal t
        seen = []
        for _ in range(n):
            proc = cost[auto.size] * load
            for _ in range(int(fps)):
                auto.add_stamp(int(1000 * NS + t * NS), 1, t)
                t += 1.0 / fps
            if auto.rate_hz == 0.0:
                auto.add_replaced(max(0, int(fps) - int(1.0 / proc)), t)
            auto.add_processing(proc, t)
            if auto.update(t):
                seen.append((auto.size, auto.rate_hz))
        return seen

    assert run(0.4, 10) == []                         # 80 ms per 100 ms frame: kept
    # 200 ms at 10 Hz: a smaller input, no grid rate; 288x512 would still need 120 ms, so
    # straight to the one estimated to fit (224x384: 70 ms, keeps up)
    assert run(1.0, 20) == [((224, 384), 0.0)]
    assert run(1.0, 20) == []                         # 70 ms per frame: stays, no flapping
    # slower again (133 ms at the smallest size): now a grid rate, 0.7 x 7.5 Hz -> 5 Hz
    assert run(1.9, 10) == [((224, 384), 5.0)]
    # the load goes away: every image first, then the larger inputs back one by one
    assert run(0.2, 30) == [((224, 384), 0.0), ((288, 512), 0.0), ((384, 640), 0.0)]
    assert 'ms per image' in auto.reason


def test_auto_mode_backs_off_a_step_up_that_overloads():
    """Cameras sharing cores: a step up undone at once waits twice as long before the next."""
    auto = AutoInferenceRate([(224, 384), (192, 320)])
    t = 0.0

    def run(proc_of, n, fps=10.0):
        nonlocal t
        seen = []
        for _ in range(n):
            proc = proc_of[auto.size]
            for _ in range(int(fps)):
                auto.add_stamp(int(1000 * NS + t * NS))
                t += 1.0 / fps
            for _ in range(max(0, int(fps) - int(1.0 / proc))):
                auto.add_replaced()
            auto.add_processing(proc)
            if auto.update(t):
                seen.append((t, auto.size))
        return seen

    # 30 ms at 192x320 looks like room for 224x384 (42 ms estimated) but the machine is shared:
    # there it takes 120 ms, so it steps down again, each time after a longer wait
    shared = {(224, 384): 0.12, (192, 320): 0.03}
    seen = run(shared, 200)
    ups = [at for at, size in seen if size == (224, 384)]
    downs = [at for at, size in seen if size == (192, 320)]
    assert len(ups) >= 3 and len(downs) >= 3
    waits = [up - down for down, up in zip(downs, ups)]          # 11, 20, 41, 81 s
    assert waits[0] >= AUTO_UP_DWELL_S and all(b >= 1.7 * a for a, b in zip(waits, waits[1:]))
    assert auto.up_dwell_s > AUTO_UP_DWELL_S
    # where a step up holds (30 s), the wait is back to the base
    run({(224, 384): 0.05, (192, 320): 0.03}, 400)
    assert auto.size == (224, 384) and auto.up_dwell_s == AUTO_UP_DWELL_S


def test_auto_mode_rides_out_a_burst_but_not_an_overload():
    """Every image at 10 Hz: a second of slow images is a burst, three seconds an overload."""
    auto = AutoInferenceRate()
    t = 0.0

    def run(seconds, proc):
        nonlocal t
        changed = False
        for _ in range(int(seconds * 10)):
            t += 0.1
            auto.add_stamp(int(1000 * NS + t * NS), 1, t)
            if proc > 0.1:
                auto.add_replaced(1, t)
            auto.add_processing(proc, t)
            changed |= auto.update(t)
        return changed

    assert not run(10.0, 0.05)
    assert not run(1.2, 0.3) and auto.rate_hz == 0.0      # a burst: 12 of 30 slow
    assert not run(5.0, 0.05)
    assert run(3.0, 0.3) and auto.rate_hz > 0.0           # sustained: a grid rate


def test_auto_mode_at_the_smallest_input_keeps_every_image_while_few_are_lost():
    """
    A machine at its edge: images take about the frame period, a few are replaced.

    A grid would infer 2 images in 3; the node inferring more than 3 in 4 stays on every image
    and takes a grid only once it loses more (the images of the last 3 s count).
    """
    auto = AutoInferenceRate()
    t = 0.0

    def run(seconds, proc, lost_every):
        nonlocal t
        for k in range(int(seconds * 10)):
            t += 0.1
            auto.add_stamp(int(1000 * NS + t * NS), 1, t)
            if k % lost_every == 0:
                auto.add_replaced(1, t)
            auto.add_processing(proc, t)
            if auto.update(t):
                return True
        return False

    assert not run(20.0, 0.095, 10) and auto.rate_hz == 0.0     # 10 % lost: every image
    assert auto.loss == pytest.approx(0.1, abs=0.02)
    assert not run(20.0, 0.095, 5) and auto.rate_hz == 0.0      # 20 %: still
    assert 0.2 < 1 / 3 > AUTO_LOSS
    assert run(4.0, 0.095, 3) and auto.rate_hz == pytest.approx(5.0)   # 1 in 3: a grid
    assert auto.loss == 0.0                                      # counted anew after a change


def test_auto_mode_leaves_a_grid_where_images_take_as_long_as_at_every_image():
    """
    A rig on a shared machine: on the grid its images take 65 ms of a 100 ms frame period.

    The cameras infer the grid's instants together, so that is what every image costs too
    (the loss there, a few %, is far from AUTO_LOSS): the node returns to every image after
    the up dwell, and stays there.
    """
    assert AUTO_UP < 0.65 <= AUTO_UP_EVERY
    auto = AutoInferenceRate()
    t = 0.0

    def run(seconds, proc, lost_every=0):
        nonlocal t
        changes = []
        for k in range(int(seconds * 10)):
            t += 0.1
            auto.add_stamp(int(1000 * NS + t * NS), 1, t)
            if lost_every and k % lost_every == 0:
                auto.add_replaced(1, t)
            if auto.rate_hz == 0.0 or k % 2 == 0:        # a 5 Hz grid infers 1 in 2
                auto.add_processing(proc, t)
            if auto.update(t):
                changes.append((round(t, 1), auto.rate_hz))
        return changes

    assert [r for _, r in run(4.0, 0.095, 3)] == [5.0]      # 1 in 3 lost: a grid
    changes = run(2 * AUTO_UP_DWELL_S, 0.065)
    assert [r for _, r in changes] == [0.0], changes       # back to every image
    assert changes[0][0] - 4.0 <= AUTO_UP_DWELL_S + 1.0
    assert run(30.0, 0.065, 20) == [] and auto.rate_hz == 0.0   # 5 % lost: it holds


def test_size_ladder_keeps_the_most_detail_per_step():
    fetched = [(640, 640), (384, 640), (640, 384), (288, 512), (512, 288), (224, 384),
               (384, 224)]
    assert size_ladder((1080, 1920), (384, 640), fetched, 384) == [
        (384, 640), (288, 512), (224, 384)]
    assert size_ladder((1920, 1088), (640, 384), fetched, 384) == [
        (640, 384), (512, 288), (384, 224)]
    # 4:3: the square input first, then the 16:9 ones (more detail than the portrait ones)
    assert size_ladder((1080, 1440), (640, 640), fetched, 384) == [
        (640, 640), (384, 640), (288, 512), (224, 384)]
    # model.min_input_side: a floor; above the chosen size: no steps
    assert size_ladder((1080, 1920), (384, 640), fetched, 512) == [(384, 640), (288, 512)]
    assert size_ladder((1080, 1920), (384, 640), fetched, 1000) == [(384, 640)]
    assert size_ladder((1080, 1920), (384, 640), [(384, 640)], 384) == [(384, 640)]
