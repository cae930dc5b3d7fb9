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

"""Unit tests of the batch hindsight pass (linking fragments, settling states)."""

from mv3dpose_ros.core.tracking.hindsight import settle_tracks
from mv3dpose_ros.core.types import Track, TrackState as S
import numpy as np


def _track(track_id, state, x=0.0):
    return Track(track_id=track_id, state=state, joints=np.full((2, 3), x),
                 confidence=np.ones(2), joint_state=np.ones(2, np.uint8),
                 num_views=np.full(2, 2, np.uint8), reprojection_error=np.zeros(2),
                 position=np.array([x, 0.0, 1.0]), velocity=np.full(3, np.nan),
                 first_seen=0.0, last_observed=0.0)


def _ids(frames):
    return [[(t.track_id, t.state) for t in f] for f in frames]


def test_settle_confirms_early_frames_and_drops_ghosts_and_trailing_predictions():
    frames = [[_track(1, S.TENTATIVE), _track(2, S.TENTATIVE, 5.0)],
              [_track(1, S.TENTATIVE), _track(2, S.DELETED, 5.0)],
              [_track(1, S.CONFIRMED)],
              [_track(1, S.COASTING)],      # a gap: kept
              [_track(1, S.CONFIRMED)],
              [_track(1, S.COASTING)],      # after the last observation: dropped
              [_track(1, S.DELETED)]]
    settled = settle_tracks(frames, np.arange(7) * 0.1)
    assert _ids(settled) == [
        [(1, S.CONFIRMED)], [(1, S.CONFIRMED)], [(1, S.CONFIRMED)], [(1, S.COASTING)],
        [(1, S.CONFIRMED)], [], [(1, S.DELETED)]]


def test_fragments_of_one_person_are_linked_nearest_first():
    # Tracks 1 (x=0) and 2 (x=3) are lost at frame 1; 3 appears at x=3.1, 4 at x=0.1.
    frames = [[_track(1, S.CONFIRMED), _track(2, S.CONFIRMED, 3.0)],
              [_track(1, S.CONFIRMED), _track(2, S.CONFIRMED, 3.0)],
              [_track(1, S.COASTING), _track(2, S.COASTING, 3.0), _track(3, S.TENTATIVE, 3.1)],
              [_track(1, S.COASTING), _track(2, S.COASTING, 3.0), _track(3, S.CONFIRMED, 3.1),
               _track(4, S.CONFIRMED, 0.1)],
              [_track(1, S.DELETED), _track(2, S.DELETED), _track(3, S.CONFIRMED, 3.1),
               _track(4, S.CONFIRMED, 0.1)]]
    settled = settle_tracks(frames, np.arange(5) * 0.1)
    assert _ids(settled) == [
        [(1, S.CONFIRMED), (2, S.CONFIRMED)],
        [(1, S.CONFIRMED), (2, S.CONFIRMED)],
        [(1, S.COASTING), (2, S.CONFIRMED)],     # 1 predicted inside its gap, 3 became 2
        [(2, S.CONFIRMED), (1, S.CONFIRMED)],    # 4 became 1
        [(2, S.CONFIRMED), (1, S.CONFIRMED)]]    # tombstones of linked tracks dropped


def test_far_or_late_fragments_are_not_linked():
    frames = [[_track(1, S.CONFIRMED)], [_track(1, S.CONFIRMED)], [],
              [_track(2, S.CONFIRMED, 3.0)], [_track(2, S.CONFIRMED, 3.0)],
              [], [], [_track(3, S.CONFIRMED, 3.0)]]
    stamps = np.array([0, 1, 2, 3, 4, 5, 6, 7]) * 0.1
    stamps[7] = 2.0        # 1.6 s after track 2 was last seen: beyond max_gap_s
    settled = settle_tracks(frames, stamps)
    assert sorted({t.track_id for f in settled for t in f}) == [1, 2, 3]
