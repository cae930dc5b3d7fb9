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

"""Unit tests of the N-stream synchroniser (message time only, no rclpy)."""

import random

from mv3dpose_ros.core.sync import StreamSynchronizer, SyncConfig
import pytest

MS = 1_000_000
PERIOD = 33 * MS            # ~30 Hz
T0 = 1_000_000 * MS         # 1000 s: any positive epoch
CAMS = ['cam0', 'cam1', 'cam2']


def make(cams=CAMS, **kw):
    cfg = {'slop_s': 0.016, 'max_wait_s': 0.1, 'min_views': 2}
    cfg.update(kw)
    return StreamSynchronizer(cams, SyncConfig(**cfg))


def feed(sync, events):
    """Add (cam, stamp_ns) events in order; return all emitted sets."""
    out = []
    for cam, stamp in events:
        out += sync.add(cam, stamp, (cam, stamp)).sets
    return out


def frames(n, cams=CAMS, jitter_ns=0, seed=0):
    """Per-frame, per-camera stamps with uniform capture jitter."""
    rng = random.Random(seed)
    return [[(c, T0 + f * PERIOD + rng.randint(-jitter_ns, jitter_ns)) for c in cams]
            for f in range(n)]


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
    assert sync.sets_emitted == 5 and sync.partial_sets == 0


def test_no_set_before_last_camera_or_max_wait():
    sync = make()
    assert feed(sync, [('cam0', T0), ('cam1', T0 + MS)]) == []
    assert sync.pending() == 2


def test_jittered_stamps_group_by_frame_and_stamp_is_mean():
    sync = make(slop_s=0.012)
    evs = frames(50, jitter_ns=5 * MS, seed=3)
    out = feed(sync, [e for fr in evs for e in fr])
    assert len(out) == 50
    for f, s in enumerate(out):
        stamps = dict(evs[f])
        assert s.stamps_ns == stamps
        assert s.stamp_ns == sum(stamps.values()) // 3
    st = sync.stats['cam1']
    assert abs(st.offset_mean_s) < 0.003
    assert 0.0005 < st.offset_jitter_s < 0.006


def test_reordered_arrivals_give_same_sets():
    evs = [e for fr in frames(40, jitter_ns=4 * MS, seed=1) for e in fr]
    ref = feed(make(), evs)
    rng = random.Random(7)
    shuffled = list(evs)
    # Local reordering: swap neighbours within a few messages (cross-camera and own stream).
    for i in range(0, len(shuffled) - 3, 2):
        j = i + rng.randint(0, 3)
        shuffled[i], shuffled[j] = shuffled[j], shuffled[i]
    sync = make()
    out = feed(sync, shuffled) + sync.flush()
    assert [s.stamps_ns for s in out] == [s.stamps_ns for s in ref]
    assert sum(st.late for st in sync.stats.values()) == 0


def test_partial_set_after_max_wait_in_message_time():
    sync = make(max_wait_s=0.1)
    evs = []
    for f in range(10):
        evs += [('cam0', T0 + f * PERIOD), ('cam1', T0 + f * PERIOD)]
        if f != 2:
            evs.append(('cam2', T0 + f * PERIOD))
    out = feed(sync, evs)
    # Frame 2 is only emitted once the horizon passes pivot + max_wait (frame 2 + 100 ms).
    stamps = [s.stamp_ns for s in out]
    assert stamps == [T0 + f * PERIOD for f in range(10)]
    partial = [s for s in out if not s.complete]
    assert len(partial) == 1 and partial[0].missing == ('cam2',)
    assert set(partial[0].messages) == {'cam0', 'cam1'}
    assert sync.stats['cam2'].missing == 1 and sync.partial_sets == 1
    assert sync.stats['cam0'].missing == 0


def test_partial_set_waits_for_horizon_not_arrival_order():
    sync = make(max_wait_s=0.1)
    feed(sync, [('cam0', T0), ('cam1', T0)])
    # Newer messages within max_wait do not expire the pivot.
    out = feed(sync, [('cam0', T0 + 90 * MS), ('cam1', T0 + 90 * MS)])
    assert out == []
    out = feed(sync, [('cam0', T0 + 120 * MS), ('cam1', T0 + 120 * MS)])
    assert [s.stamp_ns for s in out] == [T0]   # T0 + 90 ms waits until the horizon > 190 ms


def test_single_future_stamp_does_not_flush_buffers():
    sync = make()
    feed(sync, [('cam0', T0), ('cam1', T0)])
    assert feed(sync, [('cam2', T0 + 3600 * 10**9)]) == []  # one camera an hour ahead
    assert sync.pending() == 3
    out = feed(sync, [('cam2', T0 + 1 * MS)])   # cam2 own stream goes back >0.5 s: reset
    assert out == [] and sync.resets == 1


def test_too_few_views_pivot_dropped_and_counted():
    sync = make(min_views=2)
    later = [(c, T0 + f * PERIOD) for f in range(1, 6) for c in ('cam1', 'cam2')]
    out = feed(sync, [('cam0', T0)] + later)
    assert all(s.stamp_ns != T0 for s in out)
    assert sync.pivots_dropped >= 1
    assert sync.stats['cam0'].dropped == 1 and sync.stats['cam0'].used == 0


def test_silent_camera_gives_partial_sets_and_missing_counts():
    sync = make()
    evs = [e for f, fr in enumerate(frames(30)) for e in fr if not (e[0] == 'cam1' and f >= 10)]
    out = feed(sync, evs) + sync.flush()
    assert len(out) == 30
    assert all(s.complete for s in out[:10])
    assert all(s.missing == ('cam1',) for s in out[10:])
    assert sync.stats['cam1'].missing == 20
    assert sync.stats['cam0'].used == 30


def test_late_message_dropped_and_counted():
    sync = make()
    out = feed(sync, [e for fr in frames(6) for e in fr if e != ('cam2', T0 + PERIOD)])
    assert any(s.stamp_ns == T0 + PERIOD and s.missing == ('cam2',) for s in out)
    res = sync.add('cam2', T0 + PERIOD, 'late')
    assert not res.accepted and res.sets == [] and 'after its set' in res.reason
    st = sync.stats['cam2']
    assert st.late == 1 and st.dropped == 1 and st.received == 6
    assert sync.resets == 0
    # Following good messages still form sets.
    assert len(feed(sync, frames(7)[6])) == 1


def test_drops_of_random_frames_every_set_has_min_views():
    rng = random.Random(11)
    evs = [e for fr in frames(200, jitter_ns=3 * MS, seed=5) for e in fr if rng.random() > 0.15]
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


def test_backward_jump_resets_and_continues():
    sync = make()
    feed(sync, [e for fr in frames(5) for e in fr])
    feed(sync, [('cam0', T0 + 5 * PERIOD)])
    res = sync.add('cam1', T0 - 10 * 10**9, 'loop')     # bag loops 10 s back
    assert res.reset and res.accepted and sync.resets == 1
    assert sync.stats['cam0'].dropped == 1                # the pending cam0 message cleared
    out = feed(sync, [('cam0', T0 - 10 * 10**9), ('cam2', T0 - 10 * 10**9)])
    assert len(out) == 1 and out[0].complete and out[0].stamp_ns == T0 - 10 * 10**9


def test_small_own_stream_reordering_is_not_a_jump():
    sync = make()
    feed(sync, [('cam0', T0 + 2 * PERIOD), ('cam0', T0 + PERIOD)])
    assert sync.resets == 0 and sync.pending() == 2


def test_memory_bounded_per_camera():
    sync = make(max_queue=8, min_views=3, max_wait_s=1000.0)
    feed(sync, [('cam0', T0 + f * PERIOD) for f in range(100)])
    assert sync.pending() == 8
    assert sync.stats['cam0'].dropped == 92


def test_duplicate_in_window_uses_nearest_and_drops_other():
    sync = make(cams=['a', 'b'])
    out = feed(sync, [('a', T0), ('b', T0 + 10 * MS), ('b', T0 + 2 * MS)])
    # 'a' + the first 'b' already complete the set: the nearer 'b' arrives late.
    assert len(out) == 1 and out[0].stamps_ns['b'] == T0 + 10 * MS
    sync = make(cams=['a', 'b', 'c'])
    out = feed(sync, [('a', T0), ('b', T0 + 10 * MS), ('b', T0 + 2 * MS), ('c', T0)])
    assert out[0].stamps_ns['b'] == T0 + 2 * MS
    assert sync.stats['b'].dropped == 1 and sync.stats['b'].used == 1


def test_flush_emits_pending_sets():
    sync = make()
    feed(sync, [('cam0', T0), ('cam1', T0), ('cam0', T0 + PERIOD)])
    out = sync.flush()
    assert [s.stamp_ns for s in out] == [T0]
    assert sync.pending() == 0 and sync.stats['cam0'].dropped == 1


def test_single_camera_rig():
    sync = make(cams=['only'], min_views=1)
    assert len(feed(sync, [('only', T0), ('only', T0 + PERIOD)])) == 2


@pytest.mark.parametrize('kw', [{'slop_s': -1.0}, {'min_views': 0}, {'max_queue': 0},
                                {'max_wait_s': float('nan')}, {'backward_jump_s': 0.0}])
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
