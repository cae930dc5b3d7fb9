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

"""Unit tests of the N-stream synchroniser (stamps in message time, waits on an arrival clock)."""

from collections import Counter
import copy
import random

from mv3dpose_ros.core.live.sync import StreamSynchronizer, SyncConfig
import pytest

MS = 1_000_000
S = 1_000_000_000
PERIOD = 33 * MS            # ~30 Hz
T0 = 1_000_000 * MS         # 1000 s: any positive epoch
CAMS = ['cam0', 'cam1', 'cam2']
LATENCY = 5 * MS            # default arrival = stamp - T0 + LATENCY (arrival clock from 0)


def make(cams=CAMS, **kw):
    cfg = {'slop_s': 0.016, 'max_wait_s': 0.1, 'min_views': 2}
    cfg.update(kw)
    return StreamSynchronizer(cams, SyncConfig(**cfg))


def feed(sync, events):
    """Add (cam, stamp_ns[, arrival_ns]) events in order; return all emitted sets."""
    out = []
    for ev in events:
        cam, stamp = ev[0], ev[1]
        now = ev[2] if len(ev) > 2 else stamp - T0 + LATENCY
        out += sync.add(cam, stamp, (cam, stamp), now).sets
    return out


def frames(n, cams=CAMS, jitter_ns=0, seed=0, period=PERIOD):
    """Per-frame, per-camera stamps with uniform capture jitter."""
    rng = random.Random(seed)
    return [[(c, T0 + f * period + rng.randint(-jitter_ns, jitter_ns)) for c in cams]
            for f in range(n)]


def flat(frs):
    return [e for fr in frs for e in fr]


def test_complete_sets_emitted_immediately():
    sync = make()
    out = []
    for f, frame in enumerate(frames(5)):
        got = feed(sync, frame)
        assert len(got) == 1, f'frame {f} not emitted as soon as the last camera arrived'
        out += got
    assert [s.stamp_ns for s in out] == [T0 + f * PERIOD for f in range(5)]
    for s in out:
        assert s.complete and s.missing == ()
        assert set(s.messages) == set(CAMS)
        assert all(msg == (cam, s.stamps_ns[cam]) for cam, msg in s.messages.items())
    assert sync.pending() == 0
    assert all(st.used == 5 and st.dropped == 0 and st.missing == 0
               for st in sync.stats.values())
    assert sync.counts.sets_emitted == 5 and sync.counts.partial_sets == 0


def test_no_set_before_last_camera_or_max_wait():
    sync = make()
    assert feed(sync, [('cam0', T0, 0), ('cam1', T0 + MS, 0)]) == []
    assert sync.pending() == 2
    assert sync.poll(99 * MS) == []              # the wait runs on the arrival clock
    out = sync.poll(100 * MS)
    assert len(out) == 1 and out[0].missing == ('cam2',)


def test_jittered_stamps_group_by_frame_and_stamp_is_mean():
    sync = make(slop_s=0.012)
    evs = frames(50, jitter_ns=5 * MS, seed=3)
    out = feed(sync, flat(evs))
    assert len(out) == 50
    for f, s in enumerate(out):
        stamps = dict(evs[f])
        assert s.stamps_ns == stamps
        assert s.stamp_ns == sum(stamps.values()) // 3
    st = sync.stats['cam1']
    assert abs(st.offset_mean_s) < 0.003
    assert 0.0005 < st.offset_jitter_s < 0.006


def test_reordered_arrivals_give_same_sets():
    evs = flat(frames(40, jitter_ns=4 * MS, seed=1))
    ref = feed(make(), evs)
    rng = random.Random(7)
    # Cameras' messages cross each other (random delivery delay up to 20 ms, below a frame
    # period, so each camera's own stream stays in order as DDS keeps it).
    arrivals = sorted(((c, s, s - T0 + rng.randint(0, 20 * MS)) for c, s in evs),
                      key=lambda e: e[2])
    assert [e[:2] for e in arrivals] != evs
    sync = make()
    out = feed(sync, arrivals) + sync.flush()
    assert [s.stamps_ns for s in out] == [s.stamps_ns for s in ref]
    assert sum(st.late for st in sync.stats.values()) == 0


def test_partial_set_waits_max_wait_of_arrival_time_not_message_time():
    """A burst of newer frames (fast replay, DDS hiccup) does not expire a set early."""
    sync = make(max_wait_s=0.1)
    # cam0 and cam1 deliver 12 frames (400 ms of message time) within 12 ms of arrival time;
    # cam2, whose inference is slower, delivers the same frames 80 ms later.
    evs = [(c, T0 + f * PERIOD, f * MS) for f in range(12) for c in ('cam0', 'cam1')]
    evs += [('cam2', T0 + f * PERIOD, 80 * MS + f * MS) for f in range(12)]
    out = feed(sync, evs)
    assert len(out) == 12 and all(s.complete for s in out)
    assert sum(st.late + st.dropped for st in sync.stats.values()) == 0


def test_inference_skew_up_to_max_wait_loses_no_set():
    """Free-running 60 fps: each camera's results arrive with its own inference delay."""
    period = 16_667_000
    delay = {'cam0': 10 * MS, 'cam1': 45 * MS, 'cam2': 95 * MS}    # skew 85 ms < max_wait
    rng = random.Random(4)
    evs = []
    for f in range(300):
        for c in CAMS:
            stamp = T0 + f * period + rng.randint(-MS, MS)
            evs.append((c, stamp, stamp - T0 + delay[c] + rng.randint(0, 3 * MS)))
    evs.sort(key=lambda e: e[2])
    sync = make(slop_s=0.0)
    out = feed(sync, evs) + sync.poll(10 * S)
    assert len(out) == 300
    assert sum(s.complete for s in out) >= 295     # the first frames run before the period
    assert sum(st.late for st in sync.stats.values()) == 0


def test_slop_wider_than_half_the_frame_period_is_narrowed_and_named():
    """sync.slop_s 17 ms at 60 fps would merge consecutive frames: every other frame lost."""
    period = 16_667_000
    sync = make(slop_s=0.017)
    out = feed(sync, flat(frames(120, period=period, jitter_ns=MS, seed=2)))
    assert len(out) >= 117                  # the first frames, before the period is known
    assert sum(st.dropped for st in sync.stats.values()) <= 6
    assert 'sync.slop_s 0.017 s is wider than half' in sync.slop_note
    assert sync.slop_ns <= period // 2


def test_auto_slop_groups_free_running_cameras_with_phase_offsets():
    """slop_s 0: half the observed period, so cameras 40 ms out of phase at 10 Hz still match."""
    period = 100 * MS
    phase = {'cam0': 0, 'cam1': 40 * MS, 'cam2': 25 * MS}
    evs = sorted(((c, T0 + f * period + phase[c]) for f in range(60) for c in CAMS),
                 key=lambda e: e[1])
    sync = make(slop_s=0.0)
    out = feed(sync, evs) + sync.flush()
    assert sync.slop_ns == period // 2 and sync.slop_note == ''
    # The first frames (period not known yet) use a 8 ms slop; every later one is complete.
    assert all(s.complete for s in out[-50:]) and sync.counts.pivots_dropped <= 15


def test_half_rate_camera_joins_the_sets_it_has_frames_for_without_delaying_others():
    period = 16_667_000
    evs = []
    for f in range(120):
        for c in CAMS:
            if c == 'cam2' and f % 2:
                continue
            evs.append((c, T0 + f * period))
    sync = make(slop_s=0.0)
    out = []
    for ev in evs:
        got = feed(sync, [ev])
        if ev[0] == 'cam1' and ev[1] > T0 + 20 * period and round((ev[1] - T0) / period) % 2:
            assert len(got) == 1, 'a frame without cam2 waited instead of being emitted'
        out += got
    assert len(out) == 120
    late = out[20:]
    assert all(s.complete == (round((s.stamp_ns - T0) / period) % 2 == 0) for s in late)
    assert sync.stats['cam2'].used == 60 and sync.stats['cam2'].lost == 0
    assert sync.stats['cam2'].rate_hz == pytest.approx(30.0, rel=0.01)


def test_silent_camera_gives_partial_sets_and_missing_counts():
    sync = make()
    evs = [e for f, fr in enumerate(frames(30)) for e in fr if not (e[0] == 'cam1' and f >= 10)]
    out = feed(sync, evs) + sync.flush()
    assert len(out) == 30
    assert all(s.complete for s in out[:10])
    assert all(s.missing == ('cam1',) for s in out[10:])
    assert sync.stats['cam1'].missing == 20
    assert sync.stats['cam0'].used == 30


def test_silent_camera_adds_no_latency_once_known_silent():
    sync = make()
    out = feed(sync, flat(frames(10)))
    assert len(out) == 10
    for f in range(10, 25):               # cam2 stopped; the others go on
        got = feed(sync, [(c, T0 + f * PERIOD) for c in ('cam0', 'cam1')])
        # Once cam2 sent nothing for max_wait + its period and its last frame is more than
        # max_wait before the set, sets no longer wait for it (the first ones waited max_wait).
        if f >= 17:
            assert len(got) == 1 and got[0].missing == ('cam2',)


@pytest.mark.parametrize('glitch_s', [1.0, -1.0, 3600.0, -0.6])
def test_isolated_outlier_stamp_dropped_counted_without_reset(glitch_s):
    sync = make()
    out = feed(sync, flat(frames(10)))
    bad = T0 + 10 * PERIOD + int(glitch_s * S)
    res = sync.add('cam1', bad, 'glitch', 10 * PERIOD + LATENCY)
    assert not res.accepted and not res.reset and res.kind == 'outlier'
    assert 'sync.jump_s' in res.reason
    out += feed(sync, flat(frames(20)[10:]))
    assert sync.counts.resets == 0
    assert len(out) == 20 and all(s.complete for s in out)
    assert sync.stats['cam1'].outliers == 1 and sync.stats['cam1'].dropped == 1
    assert sync.stats['cam1'].lost == 0


def test_one_stale_message_every_few_frames_never_resets():
    sync = make()
    out = []
    for f in range(150):
        out += feed(sync, frames(150)[f])
        if f % 30 == 29:
            cam = CAMS[(f // 30) % 3]
            feed(sync, [(cam, T0 + (f - 60) * PERIOD, f * PERIOD + LATENCY + MS)])
    assert sync.counts.resets == 0 and len(out) == 150
    assert sum(st.outliers for st in sync.stats.values()) == 4


def test_sustained_jump_on_two_cameras_resets_and_keeps_the_new_frames():
    """A bag loop: every camera goes back 10 s; the held messages start the new timeline."""
    sync = make(jump_confirm=3)
    out = feed(sync, flat(frames(10)))
    back = T0 - 10 * S
    resets = []
    arrival = 10 * PERIOD
    for f in range(10):
        for c in CAMS:
            arrival += 11 * MS
            res = sync.add(c, back + f * PERIOD, (c, f), arrival)
            out += res.sets
            resets.append(res.reset)
    assert sync.counts.resets == 1 and sum(resets) == 1
    new = [s for s in out if s.stamp_ns < T0]
    assert [s.stamp_ns for s in new] == [back + f * PERIOD for f in range(10)]
    assert all(s.complete for s in new)


def test_one_camera_with_a_wrong_clock_is_dropped_not_reset():
    sync = make()
    out = []
    for f in range(30):
        out += feed(sync, [('cam0', T0 + f * PERIOD), ('cam1', T0 + f * PERIOD),
                           ('cam2', T0 + f * PERIOD + 2 * S, f * PERIOD + LATENCY)])
    assert sync.counts.resets == 0 and len(out) >= 29
    assert sync.stats['cam2'].used == 0
    assert sync.held_outliers + sync.stats['cam2'].outliers == 30


def test_stamp_gaps_count_upstream_losses():
    sync = make()
    evs = [e for f, fr in enumerate(frames(100)) for e in fr
           if not (e[0] == 'cam0' and f in (40, 41, 42, 70))]
    feed(sync, evs)
    assert sync.stats['cam0'].lost == 4
    assert sync.stats['cam1'].lost == 0
    assert sync.stats['cam0'].usual_rate_hz == pytest.approx(1e9 / PERIOD, rel=0.01)


def test_announced_gaps_count_as_skipped_not_lost():
    """Frames a camera said it skips are its own choice, not a loss upstream."""
    sync = make()
    out = []
    for f, fr in enumerate(frames(100)):
        for cam, stamp in fr:
            if cam == 'cam0' and f in (40, 41, 42, 70):
                continue
            if cam == 'cam0' and f == 43:        # announced before frame 43's result
                out += sync.skip('cam0', T0 + 39 * PERIOD, stamp, stamp - T0 + LATENCY)
            out += feed(sync, [(cam, stamp)])
    assert sync.stats['cam0'].skipped == 3 and sync.stats['cam0'].lost == 1   # frame 70
    assert len(out) == 100 and sum(s.complete for s in out) == 96


def test_too_few_views_pivot_dropped_and_counted():
    sync = make(min_views=2)
    later = [(c, T0 + f * PERIOD) for f in range(1, 6) for c in ('cam1', 'cam2')]
    out = feed(sync, [('cam0', T0)] + later)
    assert all(s.stamp_ns != T0 for s in out)
    assert sync.counts.pivots_dropped >= 1
    assert sync.stats['cam0'].dropped == 1 and sync.stats['cam0'].used == 0
    assert sync.stats['cam0'].unmatched['too_few_views'] == 1


def test_late_message_dropped_and_counted():
    sync = make()
    out = feed(sync, [e for e in flat(frames(6)) if e != ('cam2', T0 + PERIOD)])
    assert any(s.stamp_ns == T0 + PERIOD and s.missing == ('cam2',) for s in out)
    res = sync.add('cam2', T0 + PERIOD, 'late', 6 * PERIOD)
    assert not res.accepted and res.sets == [] and 'after its set' in res.reason
    assert res.kind == 'late' and 'sync.max_wait_s' in res.reason
    st = sync.stats['cam2']
    assert st.late == 1 and st.dropped == 1 and st.received == 6
    assert sync.counts.resets == 0
    # Following good messages still form sets.
    assert len(feed(sync, frames(7)[6])) == 1


def test_drops_of_random_frames_every_set_has_min_views():
    rng = random.Random(11)
    evs = [e for e in flat(frames(200, jitter_ns=3 * MS, seed=5)) if rng.random() > 0.15]
    sync = make()
    out = feed(sync, evs) + sync.flush()
    assert all(len(s.messages) >= 2 for s in out)
    stamps = [s.stamp_ns for s in out]
    assert stamps == sorted(stamps) and len(set(stamps)) == len(stamps)
    for cam in CAMS:
        st = sync.stats[cam]
        assert st.received == sum(1 for c, _ in evs if c == cam)
        assert st.used + st.dropped == st.received       # every message accounted for
        assert st.used + st.missing == len(out)
    assert sync.pending() == 0


def test_small_own_stream_reordering_is_not_a_jump():
    sync = make()
    feed(sync, [('cam0', T0 + 2 * PERIOD), ('cam0', T0 + PERIOD)])
    assert sync.counts.resets == 0 and sync.pending() == 2


def test_memory_bounded_per_camera_by_deciding_early():
    sync = make(max_queue=8, min_views=2, max_wait_s=1000.0)
    # cam2 is slow and still "coming": without the bound every set would wait for it.
    evs = [(c, T0 + f * PERIOD, 0) for f in range(100) for c in ('cam0', 'cam1')]
    sync.add('cam2', T0 - PERIOD, 'x', 0)
    out = feed(sync, evs)
    assert sync.pending() <= 2 * 9
    assert sync.counts.overflow_decisions >= 90 and len(out) >= 90
    assert all(s.missing == ('cam2',) for s in out)


def test_duplicate_in_window_uses_nearest_and_drops_other():
    sync = make(cams=['a', 'b'])
    out = feed(sync, [('a', T0), ('b', T0 + 10 * MS), ('b', T0 + 2 * MS)])
    # 'a' + the first 'b' already complete the set: the nearer 'b' arrives late.
    assert len(out) == 1 and out[0].stamps_ns['b'] == T0 + 10 * MS
    sync = make(cams=['a', 'b', 'c'])
    out = feed(sync, [('a', T0, 0), ('b', T0 + 10 * MS, 0), ('b', T0 + 2 * MS, 0),
                      ('c', T0, 0)])
    assert out[0].stamps_ns['b'] == T0 + 2 * MS
    assert sync.stats['b'].dropped == 1 and sync.stats['b'].used == 1


def test_flush_emits_pending_sets():
    sync = make()
    feed(sync, [('cam0', T0, 0), ('cam1', T0, 0), ('cam0', T0 + PERIOD, 0)])
    out = sync.flush()
    assert [s.stamp_ns for s in out] == [T0]
    assert sync.pending() == 0 and sync.stats['cam0'].dropped == 1


def test_decide_through_makes_older_messages_late():
    sync = make()
    feed(sync, flat(frames(3)))
    sync.decide_through(T0 + 10 * PERIOD)
    res = sync.add('cam0', T0 + 5 * PERIOD, 'x', 5 * PERIOD)
    assert res.kind == 'late'


def test_single_camera_rig():
    sync = make(cams=['only'], min_views=1)
    assert len(feed(sync, [('only', T0), ('only', T0 + PERIOD)])) == 2


@pytest.mark.parametrize('kw', [{'slop_s': -1.0}, {'min_views': 0}, {'max_queue': 0},
                                {'max_wait_s': float('nan')}, {'jump_s': 0.0},
                                {'jump_confirm': 0}])
def test_bad_config_rejected(kw):
    with pytest.raises(ValueError):
        make(**kw)


def test_bad_inputs_raise_clear_errors():
    sync = make()
    with pytest.raises(ValueError, match='unknown camera'):
        sync.add('camX', T0, None)
    with pytest.raises(ValueError, match='stamp must be > 0'):
        sync.add('cam0', 0, None)
    with pytest.raises(ValueError, match='duplicate'):
        StreamSynchronizer(['a', 'a'])


def test_min_views_one_expires_on_the_only_live_camera():
    sync = make(min_views=1)
    feed(sync, [('cam0', T0), ('cam1', T0), ('cam2', T0)])
    out = feed(sync, [('cam0', T0 + f * PERIOD) for f in range(1, 8)])
    assert [s.stamp_ns for s in out][:3] == [T0 + PERIOD, T0 + 2 * PERIOD, T0 + 3 * PERIOD]
    assert all(s.missing == ('cam1', 'cam2') for s in out)


def test_sustained_forward_jump_of_the_rig_continues_without_reset():
    """Input queues that dropped 1 s under load: every camera skips ahead together."""
    sync = make()
    out = feed(sync, flat(frames(20)))
    skip = 30                                   # frames lost upstream (~1 s)
    arrival = 20 * PERIOD
    for f in range(20 + skip, 30 + skip):
        for c in CAMS:
            arrival += MS
            out += sync.add(c, T0 + f * PERIOD, (c, f), arrival).sets
    assert sync.counts.resets == 0 and sync.counts.forward_jumps == 1
    assert len(out) == 30 and all(s.complete for s in out)
    assert sum(st.outliers for st in sync.stats.values()) == 0
    assert all(sync.stats[c].lost == skip for c in CAMS)


def test_cameras_lagging_behind_on_an_overloaded_host_are_late_not_a_reset():
    """Two cameras' queues fall ever further behind (their own stamps still advance)."""
    sync = make()
    out = feed(sync, flat(frames(40)))
    arrival = 40 * PERIOD
    lag_frame = 40
    for f in range(40, 140):
        arrival += PERIOD
        out += sync.add('cam0', T0 + f * PERIOD, ('cam0', f), arrival).sets
        if f % 2:                                  # the others drain at half the pace
            for c in ('cam1', 'cam2'):
                res = sync.add(c, T0 + lag_frame * PERIOD, (c, lag_frame), arrival)
                assert not res.reset
                out += res.sets
            lag_frame += 1
    assert (139 - lag_frame) * PERIOD > 1.5 * S       # more than jump_s behind at the end
    assert sync.counts.resets == 0 and sum(st.outliers for st in sync.stats.values()) == 0
    assert sync.stats['cam1'].late > 0


def _lagging_rig(sync, n_sets, lag_ns, period=S, base=1500 * MS):
    """
    1 Hz sets of 4 cameras whose detections arrive ``base`` after capture, cam3 ``lag`` later.

    Events go in arrival order with a poll at each arrival (what the node's timer does).
    """
    cams = ['cam0', 'cam1', 'cam2', 'cam3']
    events = sorted(((c, T0 + f * period, f * period + base + (lag_ns if c == 'cam3' else 0))
                     for f in range(n_sets) for c in cams), key=lambda e: e[2])
    out = []
    for cam, stamp, now in events:
        out += sync.poll(now)
        out += sync.add(cam, stamp, (cam, stamp), now).sets
    return out + sync.poll(events[-1][2] + 10 * S)


def test_the_default_wait_is_a_latency_budget():
    """By default a set waits at most 0.25 s: a camera later than that is late, not waited for."""
    sync = StreamSynchronizer(['cam0', 'cam1', 'cam2', 'cam3'], SyncConfig(max_wait_s=0.1))
    out = _lagging_rig(sync, 20, 1200 * MS)
    assert sync.max_wait_ns == 250 * MS
    assert all(s.missing == ('cam3',) for s in out) and sync.stats['cam3'].late >= 19


def test_wait_adapts_to_a_camera_whose_detections_come_seconds_later():
    """A steady 1.2 s inference skew: learned from the late messages, then no set loses it."""
    fixed = StreamSynchronizer(['cam0', 'cam1', 'cam2', 'cam3'],
                               SyncConfig(max_wait_s=0.1, max_wait_cap_s=0.0))
    out = _lagging_rig(fixed, 20, 1200 * MS)
    assert fixed.max_wait_ns == 100 * MS
    assert all(s.missing == ('cam3',) for s in out) and fixed.stats['cam3'].late >= 19
    sync = StreamSynchronizer(['cam0', 'cam1', 'cam2', 'cam3'],
                              SyncConfig(max_wait_s=0.1, max_wait_cap_s=2.0))
    out = _lagging_rig(sync, 20, 1200 * MS)
    # The first sets measure the spread (4 samples, the late messages included); from then on
    # every set waits for cam3.
    assert sync.stats['cam3'].late <= 3 and sync.stats['cam3'].used >= 17
    assert all(s.complete for s in out if s.stamp_ns >= T0 + 3 * S)
    assert len([s for s in out if s.stamp_ns >= T0 + 3 * S]) == 17
    assert sync.spread_p95_s == pytest.approx(1.2)
    assert sync.max_wait_ns == pytest.approx(1.3 * 1200 * MS, rel=1e-6)


def test_adaptive_wait_is_capped_and_returns_when_the_skew_goes():
    sync = StreamSynchronizer(['cam0', 'cam1', 'cam2', 'cam3'],
                              SyncConfig(max_wait_s=0.1, max_wait_cap_s=1.0))
    out = _lagging_rig(sync, 10, 1200 * MS)
    assert sync.max_wait_ns == 1000 * MS          # capped: cam3 stays late, others go on
    assert all(not s.complete for s in out) and sync.stats['cam3'].late >= 9
    sync = StreamSynchronizer(['cam0', 'cam1', 'cam2', 'cam3'],
                              SyncConfig(max_wait_s=0.1, max_wait_cap_s=2.0))
    _lagging_rig(sync, 10, 600 * MS)
    assert sync.max_wait_ns == pytest.approx(1.3 * 600 * MS, rel=1e-6)
    # 40 on-time sets later the recent spreads are all small: back to max_wait_s.
    cams = ['cam0', 'cam1', 'cam2', 'cam3']
    for f in range(10, 50):
        for c in cams:
            sync.add(c, T0 + f * S, c, f * S + 1500 * MS)
    assert sync.max_wait_ns == 100 * MS


def test_cameras_lagging_seconds_behind_capture_are_no_outliers():
    """Steady 1-3 s capture -> detection latency: every set is emitted, nothing is an outlier."""
    sync = StreamSynchronizer(['cam0', 'cam1', 'cam2', 'cam3'],
                              SyncConfig(max_wait_s=0.1, max_wait_cap_s=2.0))
    out = _lagging_rig(sync, 30, 1500 * MS, base=1000 * MS)      # 1.0 s and 2.5 s
    assert sync.counts.resets == 0 and sync.counts.forward_jumps == 0
    assert sum(st.outliers for st in sync.stats.values()) == 0
    # Only the sets before the wait learned the 1.5 s skew miss the lagging camera.
    assert len(out) >= 28 and sync.stats['cam3'].used >= 26
    assert all(s.complete for s in out if s.stamp_ns >= T0 + 4 * S)


def test_detection_delay_varying_by_seconds_between_slow_sets_is_no_outlier():
    """Sets every 3.2 s whose capture -> arrival delay varies in 1-3 s: no outlier, no set lost."""
    rng = random.Random(3)
    cams = ['cam0', 'cam1', 'cam2', 'cam3']
    sync = StreamSynchronizer(cams, SyncConfig(max_wait_s=0.1, max_wait_cap_s=2.0))
    events = []
    for f in range(30):
        delay = rng.randint(1000, 3000) * MS
        events += [(c, T0 + f * 3200 * MS, f * 3200 * MS + delay + rng.randint(0, 400) * MS)
                   for c in cams]
    out = []
    for cam, stamp, now in sorted(events, key=lambda e: e[2]):
        out += sync.poll(now)
        res = sync.add(cam, stamp, cam, now)
        assert res.kind != 'outlier', res.reason
        out += res.sets
    out += sync.poll(events[-1][2] + 10 * S)
    assert sync.counts.resets == 0 and sync.counts.forward_jumps == 0
    assert sum(st.outliers for st in sync.stats.values()) == 0
    # Once the cameras' periods are known (4 steps) and the spread measured, every set is
    # complete; the first ones are lost while the 3.2 s period is unknown.
    steady = [s for s in out if s.stamp_ns >= T0 + 7 * 3200 * MS]
    assert len(steady) == 23 and all(s.complete for s in steady)


@pytest.mark.parametrize('seed', range(3))
def test_waking_at_next_decision_is_never_late(seed):
    """
    Sleeping until ``next_decision_ns`` (fusion_node's release timer) loses no time to polling.

    Drops, delays of 2-60 ms and a camera silent for 40 frames: just before each wake and
    each arrival, a copy of the synchroniser polled then decides nothing (so a poll at any
    earlier time would not have either: its rules only ripen with time), and every set goes.
    """
    rng = random.Random(seed)
    events = []                  # (arrival, camera, stamp)
    for f in range(150):
        for c in CAMS:
            if rng.random() < 0.15 or (c == 'cam2' and 50 <= f < 90):
                continue
            events.append((f * PERIOD + rng.randint(2, 60) * MS + rng.randint(0, MS),
                           c, T0 + f * PERIOD))
    events.sort()
    sync = make()
    out, wakes, due = [], 0, None

    def nothing_due_before(t):
        return copy.deepcopy(sync).poll(t - 1) == []

    for arrival, cam, stamp in events + [(events[-1][0] + 10 * S, None, None)]:
        while due is not None and due < arrival:
            assert nothing_due_before(due), 'a set was due before the wake'
            out += sync.poll(due)
            wakes += 1
            due = sync.next_decision_ns(due)
        assert nothing_due_before(arrival), 'a set was due before this arrival'
        if cam is not None:      # as fusion_node: add, poll (a late stamp may decide a set)
            out += sync.add(cam, stamp, cam, arrival).sets + sync.poll(arrival)
            due = sync.next_decision_ns(arrival)
    assert sync.pending() == 0 and due is None
    partial = sum(1 for s in out if not s.complete)
    views = Counter(stamp for _, _, stamp in events)
    assert len(out) >= 0.9 * sum(1 for n in views.values() if n >= 2)   # frames of 2 cameras
    assert partial > 40                        # waits ran out
    assert wakes < 2 * partial                 # a wake per set that waited, not a poll


def test_announced_skip_lets_a_set_go_when_its_last_real_message_arrives():
    """A camera whose image was replaced says so: its set no longer waits max_wait for it."""
    sync = make(max_wait_s=0.1)
    feed(sync, flat(frames(8)))                          # periods known, all complete
    f = 8
    stamp = T0 + f * PERIOD
    arrival = stamp - T0 + LATENCY
    # cam2 skips frame 8 (replaced while its model was busy) and says so when it takes frame 9;
    # cam0 and cam1 deliver frame 8 first.
    assert feed(sync, [('cam0', stamp, arrival), ('cam1', stamp, arrival + MS)]) == []
    sets = sync.skip('cam2', T0 + 7 * PERIOD, T0 + 9 * PERIOD, arrival + 2 * MS)
    assert [s.missing for s in sets] == [('cam2',)] and sets[0].stamp_ns == stamp
    assert sync.counts.decisions['skipped (announced)'] == 1


def test_announced_skip_before_the_other_results_closes_the_set_on_the_last_of_them():
    sync = make(max_wait_s=0.1)
    feed(sync, flat(frames(8)))
    stamp = T0 + 8 * PERIOD
    arrival = stamp - T0 + LATENCY
    assert sync.skip('cam2', T0 + 7 * PERIOD, T0 + 9 * PERIOD, arrival) == []   # nothing pending
    assert feed(sync, [('cam0', stamp, arrival + MS)]) == []                    # cam1 may come
    got = feed(sync, [('cam1', stamp, arrival + 30 * MS)])
    assert len(got) == 1 and got[0].missing == ('cam2',)


def test_skip_does_not_cover_its_own_end_stamps():
    """Only stamps strictly between: the images at both ends have (or will have) results."""
    sync = make(max_wait_s=0.1)
    feed(sync, flat(frames(8)))
    stamp = T0 + 8 * PERIOD
    arrival = stamp - T0 + LATENCY
    feed(sync, [('cam0', stamp, arrival), ('cam1', stamp, arrival)])
    # cam2 announces a gap ending at frame 8 itself: frame 8's result is still coming.
    assert sync.skip('cam2', T0 + 6 * PERIOD, stamp, arrival + MS) == []
    assert sync.skip('cam2', stamp, T0 + 10 * PERIOD, arrival + MS) == []
    got = feed(sync, [('cam2', stamp, arrival + 50 * MS)])
    assert len(got) == 1 and got[0].complete


def test_skip_rejects_unknown_cameras_and_empty_intervals():
    sync = make()
    with pytest.raises(ValueError, match='unknown camera'):
        sync.skip('nope', 0, 1)
    with pytest.raises(ValueError, match='after < before'):
        sync.skip('cam0', 5, 5)
    with pytest.raises(ValueError, match='after < before'):
        sync.skip('cam0', -1, 5)


def test_reset_forgets_announced_skips():
    sync = make(max_wait_s=0.1)
    feed(sync, flat(frames(8)))
    sync.skip('cam2', T0 + 7 * PERIOD, T0 + 9 * PERIOD, 0)
    sync.reset()
    feed(sync, flat(frames(8)))
    stamp = T0 + 8 * PERIOD
    arrival = stamp - T0 + LATENCY
    assert feed(sync, [('cam0', stamp, arrival), ('cam1', stamp, arrival)]) == []
