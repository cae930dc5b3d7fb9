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
Identity figures of 3D multi-person tracks that need no ground truth (live runs, real rigs).

Without annotation a tracker still shows how well it keeps identities in its output alone:
N people in view should be carried by N ids, an id should not vanish and come back, new ids
should not keep appearing once everybody has been seen, and nobody should be published twice.
The input is what a tracks topic or file carries, one entry per published message (the
empty ones too, they count as messages)::

    frames: Iterable[Tuple[stamp_s, Sequence[Tuple[track_id, pose]]]]

with the confirmed skeletons only; ``pose`` is ``[J, 3]`` metres (NaN for missing joints) or a
root point ``[3]``. API:

- :func:`duplicate_rate` ``(frames, radius_m=0.3, distance='mean_joint') -> float``: the share
  of skeletons that have another skeleton of the same message closer than ``radius_m`` (mean
  distance over shared joints, or with ``distance='root'`` the distance of the centroids of
  the valid joints): a person published twice.
- :func:`identity_summary` ``(frames, people, warmup_s=1.0, radius_m=0.3,
  distance='mean_joint') -> IdentitySummary``: distinct ids, the share of skeletons carried
  by the ``people`` most frequent ids, returns (an id absent from at least one message and
  back), ids first seen after the warm-up, messages with more than ``people`` skeletons, and
  the duplicates above, in one pass.
- :func:`frame_period` ``(stamps) -> float`` and :func:`sequence_duration` ``(stamps, frames,
  fps=None) -> float``: the duration behind the per-minute figures here and in :mod:`.mot`,
  the number of frames (messages) times the frame period, ``1 / fps`` or else the median step
  of the stamps; gaps (frames left out of an evaluation, a stalled stream) do not count as
  time, so a rate is per minute of output.

The ground-truth counterparts (IDF1, IDP, IDR, ID switches per minute, fragmentations,
duplicates near a ground-truth person) are in :mod:`.mot`.
"""

from dataclasses import asdict, dataclass, field
import math
from typing import Iterable, List, Optional, Sequence, Tuple

from mv3dpose_ros.eval.mpjpe import pose_distances, pose_roots
import numpy as np

# (track id, pose [J, 3] or root [3])
Skeleton = Tuple[int, np.ndarray]
# (stamp in seconds, the confirmed skeletons of one message)
Message = Tuple[float, Sequence[Skeleton]]

_DISTANCES = ('mean_joint', 'root')


def frame_period(stamps: Iterable[float]) -> float:
    """
    Return the median step (s) between distinct sorted stamps, NaN with fewer than two.

    The median rather than the span over the count, so that a gap (frames left out of an
    evaluation, messages not published) does not stretch the period of a frame.
    """
    s = np.asarray([x for x in stamps if x is not None], dtype=float)
    s = np.unique(s[np.isfinite(s)])
    return float(np.median(np.diff(s))) if s.size > 1 else float('nan')


def sequence_duration(stamps: Iterable[float], frames: int,
                      fps: Optional[float] = None) -> float:
    """
    Return ``frames`` times the frame period (``1 / fps``, else :func:`frame_period`), in s.

    One definition for every per-minute figure, so that rates with and without ground truth
    compare; NaN without frames or without a period.
    """
    period = 1.0 / fps if fps else frame_period(stamps)
    return frames * period if frames else float('nan')


def _check(radius_m: float, distance: str) -> None:
    if distance not in _DISTANCES:
        raise ValueError(f"distance must be 'mean_joint' or 'root', not {distance!r}")
    if not radius_m > 0:
        raise ValueError(f'radius_m must be positive, got {radius_m}')


def _duplicated(poses: Sequence[np.ndarray], radius_m: float, distance: str) -> np.ndarray:
    """Return ``[H]`` bools: the skeleton has another one of the message within ``radius_m``."""
    if len(poses) < 2:
        return np.zeros(len(poses), dtype=bool)
    arr = [np.asarray(p, dtype=float) for p in poses]
    arr = [p.reshape(1, 3) if p.shape == (3,) else p for p in arr]
    shapes = {p.shape for p in arr}
    if len(shapes) != 1 or arr[0].ndim != 2 or arr[0].shape[1] != 3:
        raise ValueError(f'the poses of one message must all be [J, 3] or [3], got '
                         f'{sorted(shapes)}')
    pts = np.stack(arr)
    if distance == 'root':
        pts = pose_roots(pts)[:, None]
    d = pose_distances(pts, pts)
    np.fill_diagonal(d, np.inf)
    return (d < radius_m).any(1)


def duplicate_rate(frames: Iterable[Message], radius_m: float = 0.3,
                   distance: str = 'mean_joint') -> float:
    """
    Return the share of skeletons with another one closer than ``radius_m`` in their message.

    Two confirmed skeletons that close are one person published twice (a split track, a
    ghost not merged), which no consumer can tell apart from two people. NaN without any
    skeleton.
    """
    _check(radius_m, distance)
    total = dup = 0
    for _, skeletons in frames:
        poses = [p for _, p in skeletons]
        total += len(poses)
        dup += int(_duplicated(poses, radius_m, distance).sum())
    return dup / total if total else float('nan')


def _nan_to_none(d: dict) -> dict:
    return {k: None if isinstance(v, float) and not math.isfinite(v) else v
            for k, v in d.items()}


@dataclass
class IdentitySummary:
    """Identity figures of a run without ground truth (NaN where undefined)."""

    people: int                  # the known number of people, as given
    messages: int
    skeletons: int               # confirmed skeletons over all messages
    duration_s: float            # messages times the frame period
    distinct_ids: int
    top_share: float             # skeletons carried by the `people` most frequent ids
    returns: int                 # times an id was absent from >= 1 message and came back
    returning_ids: int           # ids that did so at least once
    late_ids: int                # ids first seen more than warmup_s after the first message
    late_ids_per_min: float
    over_count_messages: int     # messages with more than `people` skeletons
    over_count_rate: float       # ... as a share of messages
    duplicates: int              # skeletons with another one within radius_m
    duplicate_rate: float        # ... as a share of skeletons
    warmup_s: float
    radius_m: float
    top_ids: List[int] = field(default_factory=list)

    def as_dict(self) -> dict:
        """Return the figures as a plain dict (strict JSON: NaN becomes ``None``)."""
        return _nan_to_none(asdict(self))

    def summary(self) -> str:
        """Format the figures on one line."""
        return (f'identity without GT ({self.people} people): {self.distinct_ids} ids, '
                f'top {self.people} carry {100 * self.top_share:.1f} %, {self.returns} '
                f'returns ({self.returning_ids} ids), {self.late_ids} new ids after '
                f'{self.warmup_s:g} s, {self.over_count_messages}/{self.messages} messages '
                f'with > {self.people}, duplicates {100 * self.duplicate_rate:.1f} % '
                f'(< {self.radius_m:g} m)')


def identity_summary(frames: Iterable[Message], people: int, warmup_s: float = 1.0,
                     radius_m: float = 0.3, distance: str = 'mean_joint') -> IdentitySummary:
    """
    Summarise how a run kept identities, from its confirmed skeletons alone.

    ``people`` is the number of people known to be in view. A tracker that keeps
    identities gives ``distinct_ids == people``, ``top_share == 1``, no returns, no late ids
    (after ``warmup_s`` everybody has been seen), no over-count and no duplicates; each figure
    points at another failure (ids spread over people, ids dropped and recovered, new ids for
    known people, ghosts, people published twice). Messages are taken in the given order.
    """
    _check(radius_m, distance)
    if int(people) != people or people < 0:
        raise ValueError(f'people must be a count, got {people}')
    people = int(people)
    stamps: List[float] = []
    ids: List[int] = []
    where: List[int] = []
    sizes: List[int] = []
    dup = 0
    for k, (stamp, skeletons) in enumerate(frames):
        stamps.append(float(stamp))
        skeletons = list(skeletons)
        ids.extend(int(i) for i, _ in skeletons)
        where.extend([k] * len(skeletons))
        sizes.append(len(skeletons))
        dup += int(_duplicated([p for _, p in skeletons], radius_m, distance).sum())
    t = np.asarray(stamps, dtype=float)
    if not np.isfinite(t).all():
        raise ValueError('every message needs a finite stamp (seconds)')
    nan = float('nan')
    ids_a = np.asarray(ids, dtype=np.int64)
    total = ids_a.size
    uid, counts = np.unique(ids_a, return_counts=True)
    top = np.argsort(-counts, kind='stable')[:people]     # ties: the lower id first
    # (id, message) once each, sorted by id then message: gaps within an id are returns
    pairs = np.unique(np.stack([ids_a, np.asarray(where, dtype=np.int64)], 1), axis=0)
    same = pairs[1:, 0] == pairs[:-1, 0]
    gap = same & (np.diff(pairs[:, 1]) > 1)
    first_msg = pairs[np.r_[True, ~same], 1] if total else np.zeros(0, dtype=np.int64)
    late = int((t[first_msg] - t[0] > warmup_s).sum()) if total else 0
    duration = sequence_duration(t, t.size)
    over = int((np.asarray(sizes) > people).sum())
    return IdentitySummary(
        people=people, messages=t.size, skeletons=total, duration_s=duration,
        distinct_ids=int(uid.size), top_share=float(counts[top].sum() / total) if total else nan,
        returns=int(gap.sum()), returning_ids=int(np.unique(pairs[1:, 0][gap]).size),
        late_ids=late, late_ids_per_min=60.0 * late / duration if duration > 0 else nan,
        over_count_messages=over, over_count_rate=over / t.size if t.size else nan,
        duplicates=dup, duplicate_rate=dup / total if total else nan,
        warmup_s=float(warmup_s), radius_m=float(radius_m),
        top_ids=[int(i) for i in uid[top]])
