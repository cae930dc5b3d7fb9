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


"""Tracks JSON Lines: round trip of core tracks, schema checks on read."""

import io
import json

from mv3dpose_ros.core.types import JointState, PositionSource, Track, TrackState
from mv3dpose_ros.io.tracks_jsonl import (frame_to_line, parse_line, read_tracks,
                                          TracksFormatError, TracksWriter)
import numpy as np
import pytest


def make_track(tid: int, state=TrackState.CONFIRMED) -> Track:
    joints = np.array([[1.0, 2.0, 0.5], [np.nan] * 3, [1.1234567, 2.0, 1.5]])
    return Track(track_id=tid, state=state, joints=joints,
                 confidence=np.array([0.9, 0.0, 0.71234]),
                 joint_state=np.array([JointState.TRIANGULATED, JointState.MISSING,
                                       JointState.PREDICTED], dtype=np.uint8),
                 num_views=np.array([3, 0, 0], dtype=np.uint8),
                 reprojection_error=np.array([1.0, np.nan, np.nan]),
                 position=np.array([1.0, 2.0, 1.0]), velocity=np.full(3, np.nan),
                 first_seen=0.0, last_observed=0.1, score=0.8)


def test_round_trip(tmp_path):
    path = str(tmp_path / 't.jsonl')
    with TracksWriter(path, 'coco17') as w:
        w.write(0, [make_track(1), make_track(2, TrackState.TENTATIVE)], stamp=0.0)
        w.write(1, [], stamp=1 / 60)
        w.write(2, [make_track(1, TrackState.DELETED)])
    lines = open(path).read().splitlines()
    assert len(lines) == 3
    first = json.loads(lines[0])
    assert first['units'] == 'm' and first['layout'] == 'coco17' and first['frame'] == 0
    t = first['tracks'][0]
    assert t['id'] == 1 and t['state'] == 'confirmed'
    assert t['joints'][1] is None and t['joints'][2] == [1.123457, 2.0, 1.5]
    assert t['velocity'] is None and t['joint_state'] == [1, 0, 2]
    frames = list(read_tracks(path))
    assert [f.frame for f in frames] == [0, 1, 2]
    assert frames[1].stamp == pytest.approx(1 / 60, abs=1e-6) and frames[1].tracks == []
    rec = frames[0].tracks[0]
    np.testing.assert_allclose(rec.joints[0], [1.0, 2.0, 0.5])
    assert np.isnan(rec.joints[1]).all()
    np.testing.assert_allclose(rec.confidence, [0.9, 0.0, 0.7123])
    assert [t.id for t in frames[0].select([TrackState.CONFIRMED])] == [1]
    assert frames[2].tracks[0].state == TrackState.DELETED


def test_stream_target_and_units():
    buf = io.StringIO()
    w = TracksWriter(buf, 'shelf14')
    w.write(5, [make_track(7)])
    w.close()
    assert not buf.closed and buf.getvalue().count('\n') == 1
    f = parse_line('{"frame": 1, "units": "mm", "tracks": [{"id": 1, "state": "coasting", '
                   '"joints": [[1000, 0, 500], null]}]}')
    np.testing.assert_allclose(f.tracks[0].joints[0], [1.0, 0.0, 0.5])
    np.testing.assert_allclose(f.tracks[0].confidence, [1.0, 0.0])


@pytest.mark.parametrize('line,reason', [
    ('{"frame": 1', 'invalid JSON'),
    ('{"tracks": []}', 'without "frame"'),
    ('{"frame": 1, "units": "ft", "tracks": []}', 'unknown units'),
    ('{"frame": 1, "tracks": [{"id": 1, "state": "lost", "joints": []}]}', 'unknown state'),
    ('{"frame": 1, "tracks": [{"id": 1, "state": "confirmed", "joints": [[1, 2]]}]}',
     'not [x, y, z]'),
    ('{"frame": 1, "tracks": [{"id": 1, "state": "confirmed", "joints": [null], '
     '"confidence": [1, 1]}]}', 'confidence has 2 values'),
    # out-of-range, non-numeric, huge and deeply nested values: each named, never a bare
    # Python exception (a traceback in every command reading tracks) nor read as garbage
    ('{"frame": 1e400, "tracks": []}', '1e400 is out of range'),
    ('{"frame": 1, "stamp": "abc", "tracks": []}', 'stamp .abc. is not a number'),
    ('{"frame": ' + '9' * 400 + ', "tracks": []}', 'integer with 400 digits'),
    ('{"frame": 1, "tracks": ' + '[' * 5000 + ']' * 5000 + '}', 'nesting 5001 levels'),
    ('{"frame": 2.5, "tracks": []}', 'frame 2.5 is not an integer'),
    ('{"frame": 1, "tracks": [{"id": "x", "state": "confirmed", "joints": []}]}',
     'track id .x. is not an integer'),
    ('{"frame": 1, "tracks": [{"id": -1, "state": "confirmed", "joints": []}]}',
     'track id -1 is out of range'),
    ('{"frame": 1, "tracks": [{"id": 1, "state": ["c"], "joints": []}]}', 'unknown state'),
    ('{"frame": 1, "tracks": [{"id": 1, "state": "confirmed", "joints": [[1, "a", 2]]}]}',
     'joint 0 .a. is not a number'),
    ('{"frame": 1, "tracks": [{"id": 1, "state": "confirmed", "joints": [[1, 2, NaN]]}]}',
     'NaN is not a JSON number'),
    ('{"frame": 1, "tracks": [{"id": 1, "state": "confirmed", "joints": [[1, 2, 1e300]]}]}',
     'out of range'),
    ('{"frame": 1, "tracks": [{"id": 1, "state": "confirmed", "joints": [null], '
     '"joint_state": [7]}]}', 'joint_state 7 is out of range'),
    ('{"frame": 1, "tracks": [{"id": 1, "state": "confirmed", "joints": [null], '
     '"position": [1, 2]}]}', 'position has 2 values'),
    ('{"frame": 1, "tracks": [{"id": 1, "state": "confirmed", "joints": [null], '
     '"num_views": ["x"]}]}', 'num_views .x. is not an integer'),
    ('{"frame": 1, "tracks": [{"id": 1, "state": "confirmed", "joints": [null], '
     '"score": {}}]}', 'score {} is not a number'),
    ('{"frame": 1, "layout": 5, "tracks": []}', 'layout 5 is not a string'),
    ('{"frame": 1, "tracks": [{"id": 1, "state": "confirmed", "joints": [null], '
     '"position_source": "feet"}]}', "unknown position_source 'feet'"),
])
def test_bad_lines_are_reported_and_skipped(tmp_path, line, reason):
    with pytest.raises(TracksFormatError, match=reason.replace('[', r'\[')):
        parse_line(line)
    path = tmp_path / 'bad.jsonl'
    path.write_text('{"frame": 0, "tracks": []}\n' + line + '\n\n{"frame": 2, "tracks": []}\n')
    issues = []
    frames = list(read_tracks(str(path), issues))
    assert [f.frame for f in frames] == [0, 2]
    assert len(issues) == 1 and issues[0].startswith(f'{path}:2: ')


def test_line_that_is_not_utf8_is_reported_and_skipped(tmp_path):
    path = tmp_path / 'bad.jsonl'
    path.write_bytes(b'{"frame": 0, "tracks": []}\n{"frame": \xff}\n{"frame": 2, "tracks": []}\n')
    issues = []
    assert [f.frame for f in read_tracks(str(path), issues)] == [0, 2]
    assert issues == [f'{path}:2: not UTF-8 text (byte 10)']


def test_position_source_round_trip_and_default(tmp_path):
    """What position is travels with it; files from before the field read as hips."""
    from mv3dpose_ros.ros.bag_convert import record_to_track
    body = make_track(1)
    body.position_source = PositionSource.BODY
    unknown = make_track(2)
    unknown.position = np.full(3, np.nan)        # HIPS claimed, nothing known: said so
    none = make_track(3)
    none.position_source = PositionSource.NONE   # a position it does not vouch for: dropped
    line = json.loads(frame_to_line(0, [make_track(4), body, unknown, none], 'coco17'))
    got = [(t['position_source'], t['position']) for t in line['tracks']]
    assert got == [('hips', [1.0, 2.0, 1.0]), ('body', [1.0, 2.0, 1.0]), ('none', None),
                   ('none', None)]
    frame = parse_line(json.dumps(line))
    assert [t.position_source for t in frame.tracks] == [
        PositionSource.HIPS, PositionSource.BODY, PositionSource.NONE, PositionSource.NONE]
    assert 'position_source' not in frame.tracks[1].extra
    back = record_to_track(frame.tracks[1], 0.0)
    assert back.position_source == PositionSource.BODY and back.position.tolist() == [1, 2, 1]
    old = parse_line('{"frame": 0, "tracks": [{"id": 1, "state": "confirmed", "joints": [], '
                     '"position": [1, 2, 3]}]}')
    assert old.tracks[0].position_source == PositionSource.HIPS
    assert record_to_track(old.tracks[0], 0.0).position_source == PositionSource.HIPS
