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
Tracks as JSON Lines: one JSON object per line and per processed frame.

Schema (units are always metres on write)::

    {"frame": 12, "layout": "coco17", "units": "m", "stamp": 0.2,
     "tracks": [{"id": 3, "state": "confirmed",
                 "joints": [[x, y, z] or null, ...],      # J entries, world frame, z up
                 "confidence": [c, ...],                  # J entries in [0, 1]
                 "joint_state": [1, ...],                 # 0 missing, 1 triangulated, 2 predicted
                 "num_views": [3, ...], "position": [x, y, z] or null,
                 "position_source": "hips",
                 "velocity": [vx, vy, vz] or null, "score": 0.9}]}

``state`` is one of ``tentative``, ``confirmed``, ``coasting``, ``deleted`` (a deleted track
appears once, as a tombstone). ``position_source`` says what ``position`` is: ``hips`` (the hip
midpoint), ``body`` (a hip is unknown: the body centre) or ``none`` (position is null); files
without it read as ``hips``. Only ``frame``, ``tracks`` and per track ``id``, ``state``,
``joints`` are required on read; readers ignore unknown keys. Coordinates are rounded to
micrometres, confidences to 1e-4. Reading is strict (``core.files.load_json`` limits, every
known field type- and range-checked): a bad line raises ``TracksFormatError`` naming the field,
and ``read_tracks`` reports it as ``path:line: reason`` and skips it.
"""

from dataclasses import dataclass, field
import json
import logging
import math
from typing import IO, Iterable, Iterator, List, Optional, Sequence, Tuple, Union

from mv3dpose_ros.core.files import load_json, LoadError
from mv3dpose_ros.core.types import PositionSource, Track, TrackState
import numpy as np

logger = logging.getLogger(__name__)

_UNITS = {'m': 1.0, 'cm': 0.01, 'mm': 0.001}
_STATES = {s.name.lower(): s for s in TrackState}
_SOURCES = {s.name.lower(): s for s in PositionSource}


def _xyz(v: np.ndarray) -> Optional[List[float]]:
    v = np.asarray(v, dtype=float)
    return [round(float(c), 6) for c in v] if np.isfinite(v).all() else None


def track_to_dict(track: Track) -> dict:
    """Convert a core :class:`Track` to its JSON object (missing joints become null)."""
    valid = np.asarray(track.valid) & np.isfinite(track.joints).all(-1)
    source = PositionSource(track.position_source)
    position = None if source == PositionSource.NONE else _xyz(track.position)
    if position is None:
        source = PositionSource.NONE
    return {
        'id': int(track.track_id),
        'state': TrackState(track.state).name.lower(),
        'joints': [_xyz(p) if ok else None for p, ok in zip(track.joints, valid)],
        'confidence': [round(float(c), 4) if math.isfinite(c) else 0.0
                       for c in np.asarray(track.confidence, dtype=float)],
        'joint_state': [int(s) for s in track.joint_state],
        'num_views': [int(n) for n in track.num_views],
        'position': position,
        'position_source': source.name.lower(),
        'velocity': _xyz(track.velocity),
        'score': round(float(track.score), 4),
    }


def frame_to_line(frame: int, tracks: Sequence[Track], layout: str,
                  stamp: Optional[float] = None) -> str:
    """Serialise one frame to a JSON line (without the newline)."""
    obj = {'frame': int(frame), 'layout': layout, 'units': 'm',
           'stamp': None if stamp is None else round(float(stamp), 6),
           'tracks': [track_to_dict(t) for t in tracks]}
    return json.dumps(obj, separators=(',', ':'), allow_nan=False)


def poses_to_line(frame: int, ids: Sequence[int], joints: np.ndarray, layout: str,
                  stamp: Optional[float] = None, state: str = 'confirmed') -> str:
    """
    Serialise plain poses ``[N, J, 3]`` (NaN = missing) with ids as one line, e.g. ground truth.

    Confidence is 1 for present joints, 0 for missing ones.
    """
    joints = np.asarray(joints, dtype=float)
    if len(ids) != len(joints):
        raise ValueError(f'{len(ids)} ids for {len(joints)} poses')
    tracks = []
    for i, pose in zip(ids, joints):
        ok = np.isfinite(pose).all(-1)
        tracks.append({'id': int(i), 'state': state,
                       'joints': [_xyz(p) if v else None for p, v in zip(pose, ok)],
                       'confidence': [1.0 if v else 0.0 for v in ok]})
    obj = {'frame': int(frame), 'layout': layout, 'units': 'm',
           'stamp': None if stamp is None else round(float(stamp), 6), 'tracks': tracks}
    return json.dumps(obj, separators=(',', ':'), allow_nan=False)


class TracksWriter:
    """Write frames of tracks to a JSON Lines file (a path or an open text stream)."""

    def __init__(self, target: Union[str, IO[str]], layout: str):
        """Open ``target`` for writing; ``layout`` is recorded on every line."""
        self.layout = layout
        self._own = isinstance(target, str)
        self._f = open(target, 'w', encoding='utf-8') if self._own else target
        self.frames = 0

    def write(self, frame: int, tracks: Sequence[Track], stamp: Optional[float] = None) -> None:
        """Append one frame."""
        self._f.write(frame_to_line(frame, tracks, self.layout, stamp) + '\n')
        self.frames += 1

    def close(self) -> None:
        """Flush, and close the file if this writer opened it."""
        self._f.flush()
        if self._own:
            self._f.close()

    def __enter__(self) -> 'TracksWriter':
        """Return self."""
        return self

    def __exit__(self, *exc) -> None:
        """Close."""
        self.close()


@dataclass
class TrackRecord:
    """One track of one frame as read back: joints ``[J, 3]`` metres, NaN where null."""

    id: int  # noqa: A003 (the JSON key; readers use it as t.id)
    state: TrackState
    joints: np.ndarray
    confidence: np.ndarray
    joint_state: Optional[np.ndarray] = None
    extra: dict = field(default_factory=dict)
    position_source: PositionSource = PositionSource.HIPS   # of extra['position']


@dataclass
class TracksFrame:
    """One line of a tracks file."""

    frame: int
    stamp: Optional[float]
    layout: Optional[str]
    tracks: List[TrackRecord]

    def select(self, states: Iterable[TrackState]) -> List[TrackRecord]:
        """Return the tracks whose state is in ``states``."""
        states = set(states)
        return [t for t in self.tracks if t.state in states]


class TracksFormatError(ValueError):
    """A line of a tracks file that does not follow the schema."""


#: Largest plausible coordinate magnitude [m] and joint count; beyond them a line is corrupt.
MAX_COORDINATE_M = 1e6
MAX_JOINTS = 1000
_MAX_ID = 2 ** 64          # ids are uint64 in TrackedSkeleton
_MAX_FRAME = 2 ** 63


def _integer(value: object, what: str, lo: int, hi: int) -> int:
    """Return ``value`` as an int in ``[lo, hi)``; integral floats (``12.0``) are accepted."""
    if isinstance(value, float) and value.is_integer():
        value = int(value)
    if isinstance(value, bool) or not isinstance(value, int):
        raise TracksFormatError(f'{what} {repr(value)[:40]} is not an integer')
    if not lo <= value < hi:
        raise TracksFormatError(f'{what} {value} is out of range [{lo}, {hi})')
    return value


def _number(value: object, what: str, limit: float) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise TracksFormatError(f'{what} {repr(value)[:40]} is not a number')
    v = float(value)
    if not abs(v) <= limit:
        raise TracksFormatError(f'{what} {v:.6g} is out of range (|value| <= {limit:g})')
    return v


def _numbers(value: object, what: str, count: Optional[int], limit: float,
             nullable: bool = False) -> Optional[np.ndarray]:
    """Return a list of ``count`` numbers as float64 (None for null when ``nullable``)."""
    if value is None and nullable:
        return None
    if not isinstance(value, list):
        raise TracksFormatError(f'{what} is {type(value).__name__}, expected a list')
    if count is not None and len(value) != count:
        raise TracksFormatError(f'{what} has {len(value)} values, expected {count}')
    return np.array([_number(v, what, limit) for v in value], dtype=float)


def _parse_track(obj: object, scale: float) -> TrackRecord:
    if not isinstance(obj, dict):
        raise TracksFormatError(f'track is {type(obj).__name__}, expected an object')
    for key in ('id', 'state', 'joints'):
        if key not in obj:
            raise TracksFormatError(f'track without "{key}"')
    tid = _integer(obj['id'], 'track id', 0, _MAX_ID)
    state = _STATES.get(obj['state'].lower()) if isinstance(obj['state'], str) else None
    if state is None:
        raise TracksFormatError(f'track {tid}: unknown state {repr(obj["state"])[:40]} '
                                f'(known: {", ".join(_STATES)})')
    joints_in = obj['joints']
    if not isinstance(joints_in, list):
        raise TracksFormatError(f'track {tid}: "joints" is not a list')
    if len(joints_in) > MAX_JOINTS:
        raise TracksFormatError(f'track {tid}: {len(joints_in)} joints (at most {MAX_JOINTS})')
    n = len(joints_in)
    joints = np.full((n, 3), np.nan)
    for j, p in enumerate(joints_in):
        if p is None:
            continue
        if not (isinstance(p, list) and len(p) == 3):
            raise TracksFormatError(f'track {tid}: joint {j} is not [x, y, z] or null')
        joints[j] = _numbers(p, f'track {tid}: joint {j}', 3, MAX_COORDINATE_M / scale) * scale
    conf = obj.get('confidence')
    if conf is None:
        conf = np.where(np.isfinite(joints).all(-1), 1.0, 0.0)
    else:
        conf = _numbers(conf, f'track {tid}: confidence', n, 1e6)
    js = obj.get('joint_state')
    if js is not None:
        if not isinstance(js, list) or len(js) != n:
            raise TracksFormatError(f'track {tid}: "joint_state" is not a list of {n} values')
        js = np.array([_integer(v, f'track {tid}: joint_state', 0, 3) for v in js], np.uint8)
    rest = {k: v for k, v in obj.items()
            if k not in ('id', 'state', 'joints', 'confidence', 'joint_state', 'position_source')}
    source = obj.get('position_source', 'hips')
    source = _SOURCES.get(source.lower()) if isinstance(source, str) else None
    if source is None:
        raise TracksFormatError(f'track {tid}: unknown position_source '
                                f'{repr(obj["position_source"])[:40]} '
                                f'(known: {", ".join(_SOURCES)})')
    for key in ('position', 'velocity'):
        if key in rest:
            v = _numbers(rest[key], f'track {tid}: {key}', 3, MAX_COORDINATE_M, nullable=True)
            rest[key] = None if v is None else (v * scale).tolist()
    if rest.get('num_views') is not None:
        views = rest['num_views']
        if not isinstance(views, list) or len(views) != n:
            raise TracksFormatError(f'track {tid}: "num_views" is not a list of {n} values')
        rest['num_views'] = [_integer(v, f'track {tid}: num_views', 0, 256) for v in views]
    if rest.get('score') is not None:
        rest['score'] = _number(rest['score'], f'track {tid}: score', 1e6)
    if source == PositionSource.NONE:
        rest['position'] = None
    return TrackRecord(id=tid, state=state, joints=joints, confidence=conf, joint_state=js,
                       extra=rest, position_source=source)


def parse_line(line: str) -> TracksFrame:
    """Parse one JSON line; raises :class:`TracksFormatError` naming the problem and field."""
    try:
        obj = load_json(line)
    except LoadError as e:
        raise TracksFormatError(str(e)) from None
    if not isinstance(obj, dict):
        raise TracksFormatError(f'line is {type(obj).__name__}, expected an object')
    if 'frame' not in obj or 'tracks' not in obj:
        raise TracksFormatError('object without "frame" or "tracks"')
    units = obj.get('units', 'm')
    if not isinstance(units, str) or units not in _UNITS:
        raise TracksFormatError(f'unknown units {repr(units)[:40]} (known: {", ".join(_UNITS)})')
    if not isinstance(obj['tracks'], list):
        raise TracksFormatError('"tracks" is not a list')
    frame = _integer(obj['frame'], 'frame', -_MAX_FRAME, _MAX_FRAME)
    stamp = obj.get('stamp')
    if stamp is not None:
        stamp = _number(stamp, 'stamp', 1e12)
    layout = obj.get('layout')
    if layout is not None and not isinstance(layout, str):
        raise TracksFormatError(f'layout {repr(layout)[:40]} is not a string')
    return TracksFrame(frame=frame, stamp=stamp, layout=layout,
                       tracks=[_parse_track(t, _UNITS[units]) for t in obj['tracks']])


#: Longest line read [bytes] (a frame of 100 people is ~0.2 MB).
MAX_LINE_BYTES = 16 * 1024 * 1024


def _lines(f: IO[bytes]) -> Iterator[Tuple[Optional[str], Optional[str]]]:
    """Yield ``(text, None)`` per line, or ``(None, reason)`` for an unreadable one."""
    while True:
        raw = f.readline(MAX_LINE_BYTES + 1)
        if not raw:
            return
        if len(raw) > MAX_LINE_BYTES and not raw.endswith(b'\n'):
            while raw and not raw.endswith(b'\n'):      # skip the rest of the long line
                raw = f.readline(MAX_LINE_BYTES)
            yield None, f'line longer than {MAX_LINE_BYTES} bytes'
            continue
        try:
            yield raw.decode('utf-8'), None
        except UnicodeDecodeError as e:
            yield None, f'not UTF-8 text (byte {e.start})'


def read_tracks(path: str, issues: Optional[List[str]] = None) -> Iterator[TracksFrame]:
    """
    Yield the frames of a tracks file in file order.

    Bad lines are reported (``path:line: reason``) in ``issues`` and the log, and skipped;
    blank lines are ignored.
    """
    with open(path, 'rb') as f:
        for n, (line, problem) in enumerate(_lines(f), start=1):
            if line is not None and not line.strip():
                continue
            try:
                if problem is not None:
                    raise TracksFormatError(problem)
                yield parse_line(line)
            except TracksFormatError as e:
                msg = f'{path}:{n}: {e}'
                logger.warning('skipped %s', msg)
                if issues is not None:
                    issues.append(msg)
