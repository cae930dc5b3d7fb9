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
CDR fast paths (``ros/cdr.py`` and its codecs) checked against rclpy's own (de)serialisation.

The decoder must read exactly what ``rclpy.serialization.serialize_message`` writes, for any
content, and accept exactly the bytes rclpy's deserialiser accepts (decoding them to the same
values); what rclpy refuses it refuses with a 'malformed' ``InvalidMessage``. The writers
(``tracks_to_cdr``, ``tracks_to_markers_cdr``, ``pose_array_cdr``) write rclpy's bytes, byte
for byte, with zeros where rclpy leaves its alignment padding uninitialised. No DDS.
"""

import math

from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseArray
from mv3dpose_msgs.msg import (Keypoint2D, Person2D, Person2DArray, TrackedSkeleton,
                               TrackedSkeletonArray)
from mv3dpose_ros.core.skeleton import get_layout
from mv3dpose_ros.core.types import PositionSource, Track, TrackState
from mv3dpose_ros.io.bag import get_typestore
from mv3dpose_ros.ros.cdr import CdrError, CdrReader, CdrWriter, PLAIN_CDR, STAMP
from mv3dpose_ros.ros.frames import pose_array_cdr, root_pose_array, root_poses
from mv3dpose_ros.ros.markers import MarkerOptions, tracks_to_markers, tracks_to_markers_cdr
from mv3dpose_ros.ros.messages import (decode_person2d_array, InvalidMessage, message_to_dict,
                                       msg_to_tracks, ns_to_stamp, person2d_array_to_numpy,
                                       Persons2D, tracks_to_cdr, tracks_to_msg)
import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import RegionOfInterest
from std_msgs.msg import Header
from visualization_msgs.msg import MarkerArray

ALPHABET = ['', 'a', 'cam_01', 'coco17', 'é', 'カメラ', '🙂x', 'Ω' * 7, 'left wrist']


def _text(rng):
    return ''.join(rng.choice(ALPHABET) for _ in range(rng.integers(0, 4)))


def _float32(rng):
    special = [0.0, -0.0, 1.0, float('nan'), float('inf'), -float('inf'), 3.4e38, 1e-45]
    if rng.random() < 0.1:
        return special[rng.integers(len(special))]
    return float(np.float32(rng.normal(0, 500)))


def random_person2d_array(rng) -> Person2DArray:
    """Return a random ``Person2DArray``: any content, including empty and odd-length parts."""
    msg = Person2DArray(
        header=Header(stamp=Time(sec=int(rng.integers(-2**31, 2**31)),
                                 nanosec=int(rng.integers(0, 10**9))), frame_id=_text(rng)),
        camera_id=_text(rng), image_width=int(rng.integers(0, 2**32)),
        image_height=int(rng.integers(0, 2**32)), layout=_text(rng))
    same = int(rng.integers(0, 20))
    for _ in range(rng.integers(0, 7)):
        count = same if rng.random() < 0.8 else int(rng.integers(0, 30))
        msg.persons.append(Person2D(
            roi=RegionOfInterest(x_offset=int(rng.integers(0, 2**32)),
                                 y_offset=int(rng.integers(0, 5000)),
                                 height=int(rng.integers(0, 5000)),
                                 width=int(rng.integers(0, 2**32)),
                                 do_rectify=bool(rng.random() < 0.5)),
            score=_float32(rng), id=_text(rng),
            keypoints=[Keypoint2D(x=_float32(rng), y=_float32(rng), confidence=_float32(rng))
                       for _ in range(count)]))
    return msg


def _bits(values):
    return np.asarray(values, dtype=np.float32).view(np.uint32)


def assert_same(decoded: Persons2D, msg: Person2DArray) -> None:
    """Every field of ``decoded`` equals ``msg`` (floats bit for bit, NaN included)."""
    assert isinstance(decoded, Persons2D)
    stamp = msg.header.stamp
    assert decoded.stamp_ns == stamp.sec * 1_000_000_000 + stamp.nanosec
    assert decoded.frame_id == msg.header.frame_id
    assert (decoded.camera_id, decoded.layout) == (msg.camera_id, msg.layout)
    assert (decoded.image_width, decoded.image_height) == (msg.image_width, msg.image_height)
    assert decoded.counts.tolist() == [len(p.keypoints) for p in msg.persons]
    flat = [(k.x, k.y, k.confidence) for p in msg.persons for k in p.keypoints]
    assert decoded.keypoints.shape == (len(flat), 3)
    assert decoded.keypoints.dtype == np.float32
    np.testing.assert_array_equal(_bits(decoded.keypoints).reshape(-1), _bits(flat).reshape(-1))
    assert decoded.rois.tolist() == [[p.roi.x_offset, p.roi.y_offset, p.roi.height,
                                      p.roi.width, int(p.roi.do_rectify)] for p in msg.persons]
    np.testing.assert_array_equal(_bits(decoded.scores), _bits([p.score for p in msg.persons]))
    assert decoded.ids == [p.id for p in msg.persons]


def test_decoder_reads_what_rclpy_writes_for_random_messages():
    rng = np.random.default_rng(2026)
    shapes = set()
    for _ in range(300):
        msg = random_person2d_array(rng)
        data = serialize_message(msg)
        assert_same(decode_person2d_array(data), deserialize_message(data, Person2DArray))
        shapes.add(len(msg.persons))
    assert 0 in shapes and max(shapes) >= 5


def test_decoder_empty_and_unicode_message():
    msg = Person2DArray(camera_id='カメラ_01', layout='', header=Header(frame_id='🙂'))
    decoded = decode_person2d_array(serialize_message(msg))
    assert_same(decoded, msg)
    assert person2d_array_to_numpy(decoded, 17).shape == (0, 17, 3)


def test_decoder_reads_big_endian_cdr():
    store = get_typestore()
    rng = np.random.default_rng(5)
    for _ in range(20):
        msg = random_person2d_array(rng)
        obj = store.deserialize_cdr(serialize_message(msg), 'mv3dpose_msgs/msg/Person2DArray')
        data = bytes(store.serialize_cdr(obj, 'mv3dpose_msgs/msg/Person2DArray',
                                         little_endian=False))
        assert data[:2] == b'\x00\x00'
        assert_same(decode_person2d_array(data), msg)


def _rclpy_reads(data: bytes):
    """Return rclpy's message for ``data``, or None where rclpy refuses it."""
    try:
        return deserialize_message(data, Person2DArray)
    except Exception:  # noqa: B902 - rclpy raises RMWError and friends
        return None


def _same_or_nan(decoded: Persons2D, msg: Person2DArray) -> None:
    """
    Every field of ``decoded`` equals ``msg``; floats by value with NaN equal to NaN.

    rclpy hands float32 fields through a Python float (double), which quiets signalling NaNs,
    so their bits may differ; every other float is compared exactly.
    """
    flat = np.array([(k.x, k.y, k.confidence) for p in msg.persons for k in p.keypoints],
                    dtype=np.float32).reshape(-1, 3)
    assert decoded.keypoints.dtype == np.float32
    np.testing.assert_array_equal(decoded.keypoints, flat)
    np.testing.assert_array_equal(decoded.scores,
                                  np.array([p.score for p in msg.persons], np.float32))
    stamp = msg.header.stamp
    assert decoded.stamp_ns == stamp.sec * 1_000_000_000 + stamp.nanosec
    assert (decoded.frame_id, decoded.camera_id, decoded.layout) == (
        msg.header.frame_id, msg.camera_id, msg.layout)
    assert (decoded.image_width, decoded.image_height) == (msg.image_width, msg.image_height)
    assert decoded.counts.tolist() == [len(p.keypoints) for p in msg.persons]
    assert decoded.rois.tolist() == [[p.roi.x_offset, p.roi.y_offset, p.roi.height,
                                      p.roi.width, int(p.roi.do_rectify)] for p in msg.persons]
    assert decoded.ids == [p.id for p in msg.persons]


def mutated_buffers(seed: int, count: int):
    """Yield ``count`` deterministic mutations of serialised random messages."""
    rng = np.random.default_rng(seed)
    bases = [bytes(serialize_message(random_person2d_array(rng))) for _ in range(30)]
    for _ in range(count):
        b = bytearray(bases[rng.integers(len(bases))])
        for _ in range(int(rng.choice([1, 1, 2, 3]))):
            if len(b) < 8:
                break
            kind = rng.integers(7)
            p = int(rng.integers(len(b)))
            w = int(rng.integers(0, len(b) - 4)) & ~3
            if kind == 0:
                b[p] ^= 1 << int(rng.integers(8))       # bit flip
            elif kind == 1:
                b = b[:p]                               # truncation
            elif kind == 2:
                b += rng.bytes(int(rng.integers(1, 9)))  # trailing bytes
            elif kind == 3:
                b[p] = int(rng.integers(256))           # byte
            elif kind == 4:
                b[w:w + 4] = rng.bytes(4)               # any word (lengths, counts)
            elif kind == 5:
                b[w:w + 4] = int(rng.integers(64)).to_bytes(4, 'little')  # small count
            else:
                b[0] = int(rng.choice([0, 0, 0, 1, 0x80]))  # encapsulation
                b[1] = int(rng.integers(256 if rng.random() < 0.2 else 16))
        yield bytes(b)


def test_decoder_accepts_exactly_what_rclpy_accepts_on_mutated_buffers():
    """One decoder path: on 4000 mutated buffers the fast decoder and rclpy agree."""
    agree = accepted = 0
    for data in mutated_buffers(2026, 4000):
        msg = _rclpy_reads(data)
        try:
            decoded = decode_person2d_array(data)
        except InvalidMessage as exc:
            assert msg is None, f'rclpy reads what the decoder refuses ({exc}): {data.hex()}'
            assert exc.reason == 'malformed'
        else:
            assert msg is not None, f'the decoder reads what rclpy refuses: {data.hex()}'
            _same_or_nan(decoded, msg)
            accepted += 1
        agree += 1
    assert agree == 4000 and 1000 < accepted < 3900   # the corpus has both kinds


def test_every_truncation_is_read_or_refused_as_rclpy_does():
    rng = np.random.default_rng(11)
    refused = 0
    for _ in range(6):
        data = serialize_message(random_person2d_array(rng))
        for cut in range(len(data)):
            msg = _rclpy_reads(data[:cut])
            if msg is None:
                with pytest.raises(InvalidMessage, match='malformed Person2DArray CDR') as info:
                    decode_person2d_array(data[:cut])
                assert info.value.reason == 'malformed'
                refused += 1
            else:
                _same_or_nan(decode_person2d_array(data[:cut]), msg)
    assert refused > 100


def _valid_message():
    kps = [Keypoint2D(x=float(i), y=2.0 * i, confidence=0.5) for i in range(17)]
    return Person2DArray(camera_id='cam0', layout='coco17',
                         persons=[Person2D(id='p', keypoints=kps) for _ in range(3)])


def test_rclpy_quirks_are_read_alike():
    data = bytearray(serialize_message(_valid_message()))
    # persons count (after header 4+8+4+1 -> 20, camera_id 4+5 -> 29, pad -> 32, sizes 8,
    # layout 4+7 -> 51, pad -> 52): a huge count fails at once instead of looping.
    huge = bytearray(data)
    huge[52:56] = (2**31).to_bytes(4, 'little')
    with pytest.raises(InvalidMessage, match='persons cannot fit'):
        decode_person2d_array(bytes(huge))
    assert _rclpy_reads(bytes(huge)) is None
    with pytest.raises(InvalidMessage, match='encapsulation none'):
        decode_person2d_array(b'')
    for kind in (4, 5, 12, 255):
        with pytest.raises(InvalidMessage, match='encapsulation'):
            decode_person2d_array(bytes([0, kind]) + bytes(data[2:]))
    cases = {'trailing': bytes(data) + bytes(8),
             'xcdr2': b'\x00\x07\x00\x00' + bytes(data[4:]),
             'pl_cdr': b'\x00\x03\xff\xff' + bytes(data[4:])}
    not_nul = bytearray(data)
    not_nul[28] = ord('x')                      # camera_id's terminating NUL
    cases['not_nul'] = bytes(not_nul)
    bad_utf8 = bytearray(data)
    bad_utf8[24] = 0xff                          # first byte of camera_id
    cases['bad_utf8'] = bytes(bad_utf8)
    inner_nul = bytearray(data)
    inner_nul[25] = 0
    cases['inner_nul'] = bytes(inner_nul)
    # the last person's keypoint count beyond the bytes left: an empty sequence for both
    last = bytearray(data)
    at = len(data) - 17 * 12 - 4
    last[at:at + 4] = (10**6).to_bytes(4, 'little')
    cases['count'] = bytes(last)
    bool_two = bytearray(data)
    bool_two[56 + 16] = 2                        # first person's roi.do_rectify
    cases['bool'] = bytes(bool_two)
    for name, raw in cases.items():
        msg = _rclpy_reads(raw)
        assert msg is not None, name
        assert_same(decode_person2d_array(raw), msg)
    assert decode_person2d_array(cases['not_nul']).camera_id == 'cam0x'
    assert decode_person2d_array(cases['bad_utf8']).camera_id == '\ufffdam0'
    assert decode_person2d_array(cases['inner_nul']).camera_id == 'c'
    assert decode_person2d_array(cases['count']).counts.tolist() == [17, 17, 0]
    assert decode_person2d_array(cases['bool']).rois[0, 4] == 1


@pytest.mark.parametrize('kind,reason', [('count', 'keypoint_count'), ('nan', 'non_finite'),
                                         ('inf', 'non_finite'),
                                         ('negative', 'confidence_range'),
                                         ('above_one', 'confidence_range')])
def test_bad_content_gives_the_same_reason_from_bytes_and_from_messages(kind, reason):
    msg = _valid_message()
    kps = msg.persons[1].keypoints
    if kind == 'count':
        msg.persons[1].keypoints = kps[:16]
    elif kind == 'nan':
        kps[3].x = math.nan
    elif kind == 'inf':
        kps[4].y = -math.inf
    elif kind == 'negative':
        kps[5].confidence = -0.25
    else:
        kps[6].confidence = 1.5
    decoded = decode_person2d_array(serialize_message(msg))
    for source in (msg, decoded):
        with pytest.raises(InvalidMessage) as info:
            person2d_array_to_numpy(source, 17)
        assert info.value.reason == reason


def test_poses_from_bytes_equal_poses_from_the_deserialised_message():
    rng = np.random.default_rng(3)
    msg = _valid_message()
    for p in msg.persons:
        for k in p.keypoints:
            k.x, k.y = (float(v) for v in rng.uniform(0, 1920, 2))
            k.confidence = float(rng.choice([0.0, rng.uniform(0, 1)]))
    data = serialize_message(msg)
    fast = person2d_array_to_numpy(decode_person2d_array(data), 17)
    slow = person2d_array_to_numpy(deserialize_message(data, Person2DArray), 17)
    assert fast.dtype == slow.dtype == np.float64
    np.testing.assert_array_equal(fast, slow)
    assert np.all(fast[fast[..., 2] == 0.0][:, :2] == 0.0)


def _with_specials(rng, values, rate=0.15):
    values = np.array(values, dtype=np.float64)
    special = np.array([np.nan, np.inf, -np.inf, -0.0, 1e300])
    hit = rng.random(values.shape) < rate
    values[hit] = rng.choice(special, size=int(hit.sum()))
    return values


def random_track(rng, joints) -> Track:
    """Return a track with random content, including NaN/inf anywhere the core may put them."""
    return Track(
        track_id=int(rng.integers(1, 2**63)), state=TrackState(int(rng.integers(0, 4))),
        joints=_with_specials(rng, rng.normal(0, 3, (joints, 3))),
        confidence=_with_specials(rng, rng.uniform(-0.5, 1.5, joints)),
        joint_state=rng.integers(0, 3, joints).astype(np.uint8),
        num_views=rng.integers(0, 40, joints).astype(np.uint8),
        reprojection_error=_with_specials(rng, rng.uniform(0, 20, joints)),
        position=_with_specials(rng, rng.normal(0, 3, 3), 0.2),
        velocity=_with_specials(rng, rng.normal(0, 1, 3), 0.3),
        first_seen=float(rng.choice([rng.uniform(-5, 2e9), np.nan, np.inf])),
        last_observed=float(rng.uniform(0, 2e9)), age=int(rng.integers(0, 2**32)),
        missed=int(rng.integers(0, 100)), score=float(_with_specials(rng, [rng.random()])[0]),
        source_cameras=tuple(_text(rng) for _ in range(rng.integers(0, 17))),
        joint_variance=(None if rng.random() < 0.2 else
                        _with_specials(rng, rng.uniform(-1e-3, 0.1, joints))),
        position_covariance=(None if rng.random() < 0.2 else _with_specials(
            rng, np.eye(3) * rng.uniform(-1e-3, 0.1), 0.05)),
        first_seen_ns=None if rng.random() < 0.3 else int(rng.integers(0, 2**62)),  # odd too
        last_observed_ns=None if rng.random() < 0.3 else int(rng.integers(0, 2**31 * 10**9)),
        position_source=PositionSource(int(rng.integers(0, 3))))


def test_tracks_to_cdr_equals_serialised_tracks_to_msg():
    rng = np.random.default_rng(7)
    for i in range(200):
        joints = [17] * int(rng.integers(0, 7))
        if i % 10 == 0:                              # mixed and empty joint counts
            joints += [int(rng.integers(0, 26)) for _ in range(3)]
        tracks = [random_track(rng, j) for j in joints]
        header = Header(stamp=ns_to_stamp(int(rng.integers(0, 2**31 * 10**9))),
                        frame_id=_text(rng))
        layout = _text(rng)
        data = tracks_to_cdr(tracks, header, layout)
        assert isinstance(data, bytes)
        got = message_to_dict(deserialize_message(data, TrackedSkeletonArray))
        want = message_to_dict(deserialize_message(
            serialize_message(tracks_to_msg(tracks, header, layout)), TrackedSkeletonArray))
        assert got == want
        assert len(got['skeletons']) == len(tracks)
        assert [len(s['joints']) for s in got['skeletons']] == joints
        floats = [v for sk in got['skeletons'] for j in sk['joints']
                  for v in (*j['position'].values(), j['confidence'], j['reprojection_error'],
                            j['position_variance'])]
        floats += [v for sk in got['skeletons'] for v in sk['position_covariance']]
        assert all(math.isfinite(v) for v in floats)
        for track, sk in zip(tracks, got['skeletons']):
            if track.last_observed_ns is not None:          # exact, not via float seconds
                stamp = sk['last_observed']
                assert stamp['sec'] * 10**9 + stamp['nanosec'] == track.last_observed_ns
            known = (track.position_source != PositionSource.NONE
                     and np.isfinite(track.position).all())
            if known:                                       # published as the core says
                assert sk['position_source'] == track.position_source
                assert list(sk['position'].values()) == track.position.tolist()
            else:                                           # said so, never a silent origin
                assert sk['position_source'] == TrackedSkeleton.POSITION_NONE
                assert list(sk['position'].values()) == [0.0, 0.0, 0.0]
                assert sk['position_covariance'][0] == -1.0


def _body_track(joints: int = 17) -> Track:
    """Return a CONFIRMED track whose root is the body centre (a hip unknown)."""
    pose = np.random.default_rng(5).normal([1.0, 2.0, 1.0], 0.3, (joints, 3))
    return Track(track_id=7, state=TrackState.CONFIRMED, joints=pose,
                 confidence=np.full(joints, 0.9), joint_state=np.ones(joints, np.uint8),
                 num_views=np.full(joints, 3, np.uint8),
                 reprojection_error=np.full(joints, 2.0), position=np.array([1.0, 2.0, 1.0]),
                 velocity=np.array([0.5, 0.0, 0.0]), first_seen=1.0, last_observed=2.0,
                 position_covariance=np.eye(3) * 0.0225, position_source=PositionSource.BODY)


@pytest.mark.parametrize('source', list(PositionSource))
def test_position_source_round_trip_through_rclpy(source):
    """The fast encoder's ``position_source`` byte is where rclpy reads it, and comes back."""
    track = _body_track()
    track.position_source = source
    header = Header(stamp=ns_to_stamp(2 * 10**9), frame_id='world')
    data = tracks_to_cdr([track, _body_track(0)], header, 'coco17')
    msg = deserialize_message(data, TrackedSkeletonArray)
    want = tracks_to_msg([track, _body_track(0)], header, 'coco17')
    assert message_to_dict(msg) == message_to_dict(
        deserialize_message(serialize_message(want), TrackedSkeletonArray))
    sk = msg.skeletons[0]
    assert sk.position_source == source
    assert msg.skeletons[1].position_source == TrackedSkeleton.POSITION_BODY
    back = msg_to_tracks(msg)[0]
    assert back.position_source == source
    if source == PositionSource.NONE:                  # nothing known: no origin either
        assert (sk.position.x, sk.position.y, sk.position.z) == (0.0, 0.0, 0.0)
        assert sk.position_covariance[0] == -1.0 and np.isnan(back.position).all()
    else:
        np.testing.assert_array_equal(back.position, track.position)
        np.testing.assert_array_equal(back.position_covariance, track.position_covariance)


def test_position_source_constants_equal_the_core():
    assert [TrackedSkeleton.POSITION_HIPS, TrackedSkeleton.POSITION_BODY,
            TrackedSkeleton.POSITION_NONE] == [int(s) for s in PositionSource]
    assert TrackedSkeleton.get_fields_and_field_types()['position_source'] == 'uint8'


def _assert_rclpy_bytes(ours: bytes, msg, msgtype: str) -> None:
    """``ours`` is rclpy's serialisation of ``msg`` byte for byte, its padding as zeros."""
    theirs = serialize_message(msg)
    store = get_typestore()      # rosbags writes the same values with zero padding
    assert ours == bytes(store.serialize_cdr(store.deserialize_cdr(theirs, msgtype), msgtype))
    a, b = np.frombuffer(ours, np.uint8), np.frombuffer(theirs, np.uint8)
    assert len(a) == len(b) and not a[a != b].any()   # rclpy differs only in padding


def test_tracks_to_cdr_writes_rclpys_bytes():
    rng = np.random.default_rng(17)
    for i in range(100):
        joints = [17] * int(rng.integers(0, 7)) + [int(rng.integers(0, 26))] * (i % 5 == 0)
        tracks = [random_track(rng, j) for j in joints]
        header = Header(stamp=ns_to_stamp(int(rng.integers(0, 2**31 * 10**9))),
                        frame_id=_text(rng))
        layout = _text(rng)
        _assert_rclpy_bytes(tracks_to_cdr(tracks, header, layout),
                            tracks_to_msg(tracks, header, layout),
                            'mv3dpose_msgs/msg/TrackedSkeletonArray')


def test_markers_and_pose_array_cdr_write_rclpys_bytes():
    rng = np.random.default_rng(23)
    bones = get_layout('coco17').bones
    for i in range(40):
        tracks = [random_track(rng, 17) for _ in range(int(rng.integers(0, 6)))]
        header = Header(stamp=ns_to_stamp(int(rng.integers(0, 2**31 * 10**9))),
                        frame_id=_text(rng))
        opts = MarkerOptions(ns=_text(rng), show_velocity=i % 2 == 0, show_labels=i % 3 > 0,
                             lifetime_s=float(rng.uniform(0, 3)))
        _assert_rclpy_bytes(tracks_to_markers_cdr(tracks, bones, header, opts),
                            tracks_to_markers(tracks, bones, header, opts),
                            'visualization_msgs/msg/MarkerArray')
        yaws = [None if rng.random() < 0.3 else float(rng.uniform(-3, 3)) for _ in tracks]
        _assert_rclpy_bytes(pose_array_cdr(root_poses(tracks, yaws), header),
                            root_pose_array(tracks, yaws, header), 'geometry_msgs/msg/PoseArray')
    assert deserialize_message(pose_array_cdr(root_poses([], []), Header()), PoseArray).poses == []
    assert deserialize_message(tracks_to_markers_cdr([], bones, Header()),
                               MarkerArray).markers[0].action == 3      # DELETEALL


def test_cdr_writer_aligns_from_the_body_and_the_reader_reads_it_back():
    w = CdrWriter()
    w.raw(b'\x07')                                   # a uint8 at body offset 0
    w.pack(STAMP, -5, 6, align=8)                    # 8-aligned from the body, not the buffer
    assert w.getvalue()[4:] == b'\x07' + bytes(7) + STAMP.pack(-5, 6)
    header = Header(frame_id='wörld')
    header.stamp.sec, header.stamp.nanosec = 3, 4
    w.header(header, 'x')
    w.strings(('a', ''))
    w.sequence(np.arange(3, dtype='<f8'), align=8)
    r = CdrReader(w.getvalue(), PLAIN_CDR)
    assert r.unpack('B', align=1) == (7,) and r.unpack('iI', align=8) == (-5, 6)
    assert r.header() == (3, 4, 'wörld') and r.string() == 'x'
    assert [r.string() for _ in range(r.u32())] == ['a', '']
    assert r.u32() == 3 and r.unpack('3d', align=8) == (0.0, 1.0, 2.0) and r.remaining == 0
    with pytest.raises(CdrError, match='truncated'):
        r.u32()
    with pytest.raises(CdrError, match='expected plain CDR'):
        CdrReader(b'\x00\x07' + w.getvalue()[2:], PLAIN_CDR)
