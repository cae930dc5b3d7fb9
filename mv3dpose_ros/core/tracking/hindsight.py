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
Hindsight for batch runs: settle what a live tracker must decide without knowing the future.

A live tracker reports a new person as TENTATIVE for a few frames, keeps predicting a lost one
(COASTING) for up to ``max_coast_s``, and, when a person is lost and found again, starts a new
id. Offline the whole run is known, so ``settle_tracks`` links such fragments into one id,
reports tracks as confirmed from their first frame, drops predictions after a person's last
observation and drops tracks that were never confirmed (ghosts). ROS-free; used by
``mv3dpose track`` before the offline Gaussian smoothing.
"""

import dataclasses
from typing import Dict, List, Optional, Sequence, Tuple

from mv3dpose_ros.core.types import Track, TrackState
import numpy as np

OBSERVED = (TrackState.TENTATIVE, TrackState.CONFIRMED)


@dataclasses.dataclass
class _Span:
    first: int                       # frame index of the first observation
    last: int                        # frame index of the last observation
    start_pos: np.ndarray
    end_pos: np.ndarray


def _centre(track: Track) -> Optional[np.ndarray]:
    """Return the root position, or the centroid of the valid joints, or None."""
    if np.all(np.isfinite(track.position)):
        return np.asarray(track.position, dtype=float)
    joints = track.joints[track.valid]
    joints = joints[np.all(np.isfinite(joints), axis=1)]
    return joints.mean(axis=0) if len(joints) else None


def _spans(frames: Sequence[Sequence[Track]]) -> Dict[int, _Span]:
    spans: Dict[int, _Span] = {}
    confirmed = set()
    for k, tracks in enumerate(frames):
        for t in tracks:
            if t.state not in OBSERVED:
                continue
            confirmed.update([t.track_id] if t.state == TrackState.CONFIRMED else [])
            pos = _centre(t)
            span = spans.get(t.track_id)
            if span is None:
                if pos is not None:
                    spans[t.track_id] = _Span(k, k, pos, pos)
            else:
                span.last = k
                span.end_pos = pos if pos is not None else span.end_pos
    return {i: s for i, s in spans.items() if i in confirmed}


def _links(spans: Dict[int, _Span], stamps: Sequence[float], max_gap_s: float, gate_m: float,
           speed_mps: float) -> Dict[int, int]:
    """Return successor -> predecessor links, nearest pairs first, one each way."""
    pairs: List[Tuple[float, int, int]] = []
    for old, a in spans.items():
        for new, b in spans.items():
            if b.first <= a.last:
                continue
            dt = stamps[b.first] - stamps[a.last]
            if dt > max_gap_s:
                continue
            dist = float(np.linalg.norm(b.start_pos[:2] - a.end_pos[:2]))
            if dist <= gate_m + speed_mps * dt:
                pairs.append((dist, old, new))
    pred: Dict[int, int] = {}
    succ: Dict[int, int] = {}
    for _, old, new in sorted(pairs):
        if new not in pred and old not in succ:
            pred[new], succ[old] = old, new
    return pred


def settle_tracks(frames: Sequence[Sequence[Track]], stamps: Sequence[float],
                  max_gap_s: float = 1.0, gate_m: float = 0.5,
                  speed_mps: float = 1.5) -> List[List[Track]]:
    """
    Settle a finished run of ``Fusion.step`` outputs (one list of tracks per frame).

    - Tracks never CONFIRMED are dropped (with their tombstone).
    - A track that ends (last observation at frame a) is linked to a confirmed track born
      after a, within ``max_gap_s``, whose first ground-plane position is within
      ``gate_m + speed_mps * dt`` of the old one's last; the newer id takes the older id.
      The old track's predictions inside the gap are kept (smoothing interpolates them),
      its tombstone is dropped.
    - COASTING after a chain's last observation is dropped; TENTATIVE becomes CONFIRMED.
    """
    spans = _spans(frames)
    pred = _links(spans, stamps, max_gap_s, gate_m, speed_mps)
    succ = {old: new for new, old in pred.items()}

    def root(track_id: int) -> int:
        while track_id in pred:
            track_id = pred[track_id]
        return track_id

    settled = []
    for k, tracks in enumerate(frames):
        kept = []
        for t in tracks:
            span = spans.get(t.track_id)
            if span is None:
                continue
            nxt = succ.get(t.track_id)
            if t.state == TrackState.DELETED and nxt is not None:
                continue
            if t.state == TrackState.COASTING and k > span.last:
                if nxt is None or k >= spans[nxt].first:
                    continue
            state = TrackState.CONFIRMED if t.state == TrackState.TENTATIVE else t.state
            kept.append(dataclasses.replace(t, track_id=root(t.track_id), state=state))
        settled.append(kept)
    return settled
