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
The live core (``core.live.loop.LiveFusion``) on real detections, driven by a fake clock.

The Pose2Sim session (4 cameras, 2 people, OpenPose BODY_25B at 60 fps) goes through the real
synchroniser and the real ``Fusion``; the steady (arrival) clock and the node clock are plain
integers the test advances, so idle steps, coasting, release timing, resets and late messages
are checked without DDS and without waiting.
"""

import os

from mv3dpose_ros.core.fusion.pipeline import FusionConfig
from mv3dpose_ros.core.geometry.calibration import load_calibration
from mv3dpose_ros.core.live.config import complete_live_config
from mv3dpose_ros.core.live.loop import IDLE_STEP_S, LiveFusion, LiveLog
from mv3dpose_ros.core.live.sync import SyncConfig
from mv3dpose_ros.core.types import NS_PER_S, TrackState
from mv3dpose_ros.io.openpose import match_camera_folders, OpenPoseSequence
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RIG = os.path.join(ROOT, 'config', 'rigs', 'pose2sim_multiperson.yaml')
FPS = 60.0
PERIOD_NS = round(NS_PER_S / FPS)
T0 = 1_000 * NS_PER_S            # stamp of frame 0 (node clock = stamps: a live rig)
ARRIVAL_NS = 5_000_000           # capture -> arrival (steady clock, same origin here)


@pytest.fixture(scope='module')
def pose2sim(shared_data):
    """Return the rig and the first 60 frames ``[(frame, {camera: poses})]``."""
    cameras = load_calibration(RIG)
    folders, missing = match_camera_folders(
        os.path.join(shared_data, 'pose2sim_multiperson', 'pose'), list(cameras))
    assert not missing
    return cameras, list(OpenPoseSequence(folders, num_joints=25))[:60]


class Notes(LiveLog):
    """A LiveLog that keeps what the live core says."""

    def __init__(self) -> None:
        self.lines = []
        super().__init__(info=self.lines.append, warning=self.lines.append,
                         throttled=lambda key, text: self.lines.append(text))


def make_live(cameras, lag=0, **fusion):
    notes = Notes()
    live = LiveFusion(list(cameras), 'body25b', SyncConfig(), FusionConfig(**fusion), lag=lag,
                      log=notes)
    live.start(cameras)
    return live, notes


def feed(live, frames, first=0, skip=(), period_ns=PERIOD_NS):
    """Send frames through ``add`` as a live rig would; return (publications, steady now)."""
    out, now = [], 0
    for k, (_, views) in enumerate(frames):
        stamp = T0 + (first + k) * period_ns
        for j, (cam, poses) in enumerate(views.items()):
            if (first + k, cam) in skip:
                continue
            now = stamp + ARRIVAL_NS + j * 1_000_000
            intake = live.add(cam, stamp, poses, now, now)
            assert intake.accepted, intake.reason
            out += intake.publications
    return out, now


def published(pubs):
    return [(p.stamp_ns, [(t.track_id, t.state) for t in p.tracks]) for p in pubs
            if not p.smoothed]


def test_live_sets_equal_the_offline_sets(pose2sim):
    """Through the synchroniser, every frame is one complete set: what track writes."""
    cameras, frames = pose2sim
    live, _ = make_live(cameras)
    pubs, _ = feed(live, frames)
    offline, _ = make_live(cameras)
    expected = []
    for k, (_, views) in enumerate(frames):
        expected += offline.step_set(views, T0 + k * PERIOD_NS)
    assert live.counts['sets'] == len(frames) and live.counts['partial_sets'] == 0
    assert published(pubs) == published(expected)
    assert {t.track_id for t in pubs[-1].tracks if t.state == TrackState.CONFIRMED} == {1, 2}


def test_idle_steps_age_the_tracks_once_no_input_came_for_max_coast(pose2sim):
    cameras, frames = pose2sim
    live, _ = make_live(cameras)
    _, now = feed(live, frames)
    last = T0 + (len(frames) - 1) * PERIOD_NS
    coast = int(live.fusion_config.max_coast_s * NS_PER_S)
    step = int(IDLE_STEP_S * NS_PER_S)
    clock, states = now, []
    while len(live.fusion.tracker.tracks) and clock < now + 4 * coast:
        clock += step
        pubs = live.idle_step(clock, clock)
        if clock <= now + coast:
            assert pubs == []                  # within max_coast_s: nothing
        for pub in pubs:
            assert last < pub.stamp_ns < clock and not pub.latency
            assert pub.stamp_ns - last == clock - now - live.sync.max_wait_ns - \
                live.sync.frame_period_ns     # the node clock since, less the wait
            states.append(({t.state for t in live.last_tracks},
                           {(t.track_id, t.state) for t in pub.tracks}))
    assert live.counts['idle_steps'] == len(states) > 1
    assert live.counts['sets'] == len(frames)      # idle steps are no sets
    # aged first: COASTING (withheld after fusion.publish_coast_s), ...
    assert states[0] == ({TrackState.COASTING}, set())
    # ... then ended, with the tombstones of the published tracks
    assert states[-1] == (set(), {(1, TrackState.DELETED), (2, TrackState.DELETED)})
    assert not len(live.fusion.tracker.tracks) and live.last_tracks == []


def test_no_idle_step_while_inputs_still_arrive(pose2sim):
    """Inputs that are dropped (e.g. under a stalled clock) still show the rig is not idle."""
    cameras, frames = pose2sim
    live, _ = make_live(cameras)
    _, now = feed(live, frames[:20])
    coast = int(live.fusion_config.max_coast_s * NS_PER_S)
    clock = now + coast + int(IDLE_STEP_S * NS_PER_S)
    live.heard(now + coast)
    assert live.idle_step(clock, clock) == [] and live.counts['idle_steps'] == 0
    assert len(live.idle_step(now + 2 * coast + 1, clock)) == 1


def test_tracks_coast_at_least_two_and_a_half_set_periods(pose2sim):
    """Sets every 4 s (an overloaded rig): tracks outlive fusion.max_coast_s (3 s) between."""
    cameras, frames = pose2sim
    live, notes = make_live(cameras)
    period = 4 * NS_PER_S
    ids = []
    for k in range(8):
        _, views = frames[k]
        pubs = live.step_set(views, T0 + k * period, clock_ns=T0 + k * period)
        ids.append({t.track_id: t.state for t in pubs[0].tracks})
    assert live.fusion.tracker.config.max_coast_s == pytest.approx(10.0)
    assert live.fusion_config.max_coast_s == 3.0               # the parameter is unchanged
    assert any('tracks coast 10.00 s (sets every 4.00 s' in n for n in notes.lines)
    # from the adaptation on, the same two tracks in every set and none deleted
    assert ids[-1] == ids[-2] == ids[-3]
    assert sorted(ids[-1].values()) == [TrackState.CONFIRMED] * 2
    fast, _ = make_live(cameras)
    feed(fast, frames[:10])
    assert fast.fusion.tracker.config.max_coast_s == 3.0       # 60 fps: the parameter


def test_release_waits_max_wait_for_a_missing_camera_then_sends_a_partial_set(pose2sim):
    cameras, frames = pose2sim
    live, _ = make_live(cameras)
    _, now = feed(live, frames[:10])
    cams = list(frames[10][1])
    pubs, now = feed(live, frames[10:11], first=10, skip={(10, cams[-1])})
    assert pubs == [] and live.sync.pending() == 3
    due = live.next_release_ns(now)
    first_arrival = T0 + 10 * PERIOD_NS + ARRIVAL_NS
    assert now < due <= first_arrival + live.sync.max_wait_ns
    assert live.release(due - 1, due - 1) == []                 # not before it is due
    pubs = live.release(due, due)
    assert [p.stamp_ns for p in pubs] == [T0 + 10 * PERIOD_NS]
    assert live.counts['partial_sets'] == 1 and live.sync.stats[cams[-1]].missing == 1
    assert live.next_release_ns(due) is None                    # nothing pending: asleep


@pytest.mark.parametrize('view_updates', [True, False])
def test_a_late_message_updates_the_tracks_at_its_stamp(pose2sim, view_updates):
    cameras, frames = pose2sim
    live, _ = make_live(cameras, view_updates=view_updates)
    feed(live, frames[:10])
    cams = list(frames[10][1])
    _, now = feed(live, frames[10:11], first=10, skip={(10, cams[-1])})
    due = live.next_release_ns(now)
    live.release(due, due)
    tracker = live.fusion.tracker
    stamp = T0 + 10 * PERIOD_NS
    intake = live.add(cams[-1], stamp, frames[10][1][cams[-1]], due + 1, due + 1)
    assert (intake.accepted, intake.kind) == (False, 'late') and intake.publications == []
    assert live.fusion.tracker is tracker and live.counts['resets'] == 0
    if view_updates:
        assert intake.late_used and not intake.late_refused
        assert live.fusion.counts['late_views_used'] == 1
    else:
        assert intake.late_refused and not intake.late_used
        assert live.fusion.counts['late_views_used'] == 0


def test_reset_publishes_tombstones_and_new_ids_follow(pose2sim):
    """A clock jump back (or ~/reset): synchroniser and tracks cleared, ended once."""
    cameras, frames = pose2sim
    live, notes = make_live(cameras, lag=3)
    pubs, _ = feed(live, frames[:20])
    first = {t.track_id for t in pubs[-2].tracks}          # last ~/tracks set (not smoothed)
    assert first == {1, 2}
    out = live.reset('node clock jumped back 5.000 s')
    assert notes.lines[-1] == ('reset: node clock jumped back 5.000 s; synchroniser and tracks '
                               'cleared')
    live_pubs = [p for p in out if not p.smoothed]
    assert len(live_pubs) == 1 and live_pubs[0].stamp_ns == T0 + 19 * PERIOD_NS
    assert {(t.track_id, t.state) for t in live_pubs[0].tracks} == \
        {(1, TrackState.DELETED), (2, TrackState.DELETED)}
    # the 3 sets the fixed-lag stream still held, then the tombstones on it too
    assert [p.stamp_ns for p in out if p.smoothed] == \
        [T0 + k * PERIOD_NS for k in (17, 18, 19, 19)]
    assert live.counts['resets'] == 1 and live.sync.pending() == 0
    assert live.last_set_ns is None and live.last_tracks == []
    pubs, _ = feed(live, frames[20:40], first=20)
    new = {t.track_id for p in pubs if not p.smoothed for t in p.tracks
           if t.state == TrackState.CONFIRMED}
    assert len(new) == 2 and min(new) > max(first)


def test_a_sustained_stamp_jump_back_resets_through_the_synchroniser(pose2sim):
    """A bag loop: every camera's stamps jump back; the third outlier in a row resets."""
    cameras, frames = pose2sim
    live, _ = make_live(cameras)
    _, now = feed(live, frames[:20])
    resets, outliers, pubs = [], 0, []
    for k, (_, views) in enumerate(frames[:5]):      # the stamps start over, 10 s back
        stamp = T0 - 10 * NS_PER_S + k * PERIOD_NS
        for cam, poses in views.items():
            now += 2_000_000
            intake = live.add(cam, stamp, poses, now, now)
            outliers += intake.kind == 'outlier'
            resets += [intake.reset]
            pubs += intake.publications
    assert sum(resets) == 1 and live.counts['resets'] == 1 and outliers >= 3
    tombs = [p for p in pubs if p.tracks and
             all(t.state == TrackState.DELETED for t in p.tracks)]
    assert tombs and tombs[0].stamp_ns == T0 + 19 * PERIOD_NS
    assert live.counts['sets'] > 20                # the stream goes on from the new stamps


def test_a_camera_stamped_20_ms_late_at_10_hz_is_named_with_its_offset(pose2sim):
    """A host clock 20 ms ahead: that camera's arrival delays stand apart from the others'."""
    cameras, frames = pose2sim
    live, notes = make_live(cameras)
    period = NS_PER_S // 10
    late = list(cameras)[2]
    for k, (_, views) in enumerate(frames):
        capture = T0 + k * period
        for j, (cam, poses) in enumerate(views.items()):
            now = capture + 40_000_000 + j * 1_000_000 + (k * 7919 % 11) * 1_000_000
            live.add(cam, capture + (20_000_000 if cam == late else 0), poses, now, now)
    assert set(live.clocks.suspects) == {late}
    assert abs(live.clocks.suspects[late] - 0.020) < 0.005
    assert any(f'camera {late}' in line and 'ms later than the rest of the rig' in line
               for line in notes.lines), notes.lines
    others = [c for c in cameras if c != late]
    assert all(abs(live.clocks.offsets.offsets_s()[c]) < 0.005 for c in others)


def test_a_camera_alone_needs_view_updates_so_min_views_becomes_two():
    """Without single-view updates a one-camera set updates nothing: 2 views, with a warning."""
    sync, fusion = SyncConfig(min_views=1), FusionConfig(view_updates=False)
    done_sync, done_fusion, warnings = complete_live_config(sync, fusion, sim_time=False)
    assert done_sync.min_views == 2 and done_fusion == fusion
    assert warnings == ['sync.min_views 1 needs fusion.view_updates: using 2']
    assert sync.min_views == 1                       # what was passed in is left as it was
    kept, _, quiet = complete_live_config(sync, FusionConfig(), sim_time=False)
    assert kept.min_views == 1 and not quiet and kept.stream_ahead_check


def test_sim_time_turns_the_arrival_clock_checks_off():
    """Under sim time stamps follow /clock: no stream-ahead check, no offset warning."""
    sync = SyncConfig()
    done, _, warnings = complete_live_config(sync, FusionConfig(), sim_time=True)
    assert not done.stream_ahead_check and done.offset_warn_fraction == 0.0 and not warnings
    assert sync.stream_ahead_check and sync.offset_warn_fraction == 0.1


def test_a_config_that_cannot_work_is_refused_naming_the_field():
    """Both configs are validated before anything is completed."""
    with pytest.raises(ValueError, match='max_wait_s'):
        complete_live_config(SyncConfig(max_wait_s=-1.0), FusionConfig(), sim_time=False)
    with pytest.raises(ValueError, match='min_views'):
        complete_live_config(SyncConfig(), FusionConfig(min_views=1), sim_time=False)
