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
fusion_node over real DDS with inputs that are wrong, late or short of a camera.

Bad messages are dropped, counted and named while tracking goes on; one mis-stamped message
neither resets nor changes ids; a set short of a camera goes when its wait runs out, or at
once when the camera announces the image it skipped. The harness is ``fusion_harness``'s.
"""

import time

from fusion_harness import base_ns, FPS, NS, person_msg, stream
from mv3dpose_msgs.msg import SkippedImages
from mv3dpose_ros.core.types import TrackState
from mv3dpose_ros.ros.messages import ns_to_stamp, stamp_to_ns
from mv3dpose_ros.ros.qos import reliable_qos
import numpy as np
import pytest
from rclpy.serialization import serialize_message
from std_msgs.msg import Header

pytestmark = [pytest.mark.ros]
pytest_plugins = ['fusion_harness']      # the scene, rig_path and harness_factory fixtures


def _bad_messages(scene, cam, stamp_ns, last_emitted_ns):
    """Return {reason: message} of one bad Person2DArray per kind."""
    poses = scene.views[10][cam]
    assert len(poses) > 0
    good = lambda s=stamp_ns: person_msg(scene, cam, poses, s)  # noqa: E731
    bad = {}
    m = good()
    m.persons[0].keypoints = m.persons[0].keypoints[:-1]
    for p in m.persons[1:]:
        p.keypoints = p.keypoints[:-1]
    bad['keypoint_count'] = m
    m = good()
    m.persons[0].keypoints[3].x = float('nan')
    bad['non_finite'] = m
    m = good()
    m.persons[0].keypoints[2].y = float('inf')
    bad['non_finite_inf'] = m
    m = good()
    m.persons[0].keypoints[0].confidence = -0.5
    bad['confidence_range'] = m
    bad['zero_stamp'] = good(0)
    bad['future_stamp'] = good(time.time_ns() + 3600 * NS)
    m = good()
    m.camera_id = 'no_such_camera'
    bad['unknown_camera'] = m
    bad['late'] = good(last_emitted_ns - 5_000_000)
    m = good()
    m.image_width, m.image_height = 640, 480
    bad['image_size'] = m
    m = good()
    m.layout = 'no_such_layout'
    bad['unknown_layout'] = m
    return bad


def test_bad_inputs_dropped_counted_and_tracking_continues(harness_factory, scene):
    h = harness_factory()
    t0 = base_ns(60)
    for cam, msg, _ in stream(scene, t0, range(20)):
        h.publish(cam, msg)
    assert h.wait_sets(20)                      # 20 complete frames: 20 sets
    state = h.node.fusion.tracker
    cam = 'cam_03'
    last_ns = h.node.live.sync.last_emitted_ns
    bad = _bad_messages(scene, cam, t0 + 20 * NS // 30, last_ns)
    n_tracks = len(h.tracks)
    for kind, msg in bad.items():
        h.publish(cam, msg)
    # a late message is not bad: it updates the tracks at its own stamp (view_updates)
    reasons = {k.replace('_inf', '') for k in bad} - {'late'}
    expected = {r: 2 if r == 'non_finite' else 1 for r in reasons}
    assert h.spin_until(lambda: dict(h.node.cams[cam].rejected) == expected, 5.0), \
        dict(h.node.cams[cam].rejected)
    # stamped 5 ms before the last set (the same instant for a free-running rig): another
    # view of it, used at its own stamp, counted 'late, used', not a rejection
    assert h.node.live.sync.stats[cam].late == 1 and h.node.cams[cam].late_used == 1
    assert h.node.fusion.counts['late_views_used'] == 1
    assert len(h.tracks) == n_tracks           # nothing bad reached the tracker
    assert h.node.fusion.tracker is state and h.node.live.counts['resets'] == 0
    for cam_, msg, _ in stream(scene, t0, range(20, 40)):
        h.publish(cam_, msg)
    assert h.wait_sets(39)
    confirmed = [t for t in h.tracks[-1].skeletons if t.state == TrackState.CONFIRMED]
    assert len(confirmed) == scene.num_people
    h.diags.clear()
    assert h.spin_until(lambda: h.latest_status(f'{cam} input') is not None, 3.0)
    values = {kv.key: kv.value for kv in h.latest_status(f'{cam} input').values}
    for reason, n in expected.items():
        assert values[f'rejected: {reason}'] == str(n)


def test_raw_input_malformed_dropped_and_lenient_bytes_read_by_rclpy(harness_factory, scene,
                                                                     capfd):
    """Truncated CDR is dropped as 'malformed', quietly; bytes rclpy reads count as input."""
    h = harness_factory()
    cam = 'cam_02'
    msgs = {c: m for c, m, _ in stream(scene, base_ns(10), [0])}
    data = serialize_message(msgs[cam])
    h.publish(cam, data[:len(data) // 2])
    assert h.spin_until(lambda: h.node.cams[cam].rejected['malformed'] == 1, 5.0)
    # the last person's keypoint count beyond the bytes left: rclpy reads an empty sequence
    # (and its type support prints a line to stderr), so the decoder does too: then the
    # keypoint count is wrong for the layout
    persons = msgs[cam].persons
    assert persons
    quirk = bytearray(data)
    at = len(data) - 12 * len(persons[-1].keypoints) - 4
    quirk[at:at + 4] = (10 ** 6).to_bytes(4, 'little')
    h.publish(cam, bytes(quirk))
    assert h.spin_until(lambda: h.node.cams[cam].rejected['keypoint_count'] == 1, 5.0)
    h.publish(cam, data + bytes(8))            # trailing bytes: rclpy and the decoder read them
    for c, m in msgs.items():
        if c != cam:
            h.publish(c, m)
    assert h.wait_sets(1)
    st = h.node.cams[cam]
    assert (st.received, st.accepted) == (3, 1)
    assert dict(st.rejected) == {'malformed': 1, 'keypoint_count': 1}
    # one decoder path: no rclpy fallback printing a stderr line per malformed message
    assert 'exceeds remaining buffer' not in capfd.readouterr().err
    assert h.node.live.counts['partial_sets'] == 0   # the set used cam_02's message


@pytest.mark.parametrize('glitch_s', [1.0, -1.0])
def test_single_mis_stamped_message_no_reset_no_id_change(harness_factory, scene, glitch_s):
    """One message stamped +-1 s is dropped and counted; ids stay."""
    h = harness_factory()
    t0 = base_ns(60)
    for cam, msg, _ in stream(scene, t0, range(30)):
        h.publish(cam, msg)
    assert h.wait_sets(30)
    before = {t.track_id for t in h.tracks[-1].skeletons if t.state == TrackState.CONFIRMED}
    assert len(before) == scene.num_people
    glitch = person_msg(scene, 'cam_02', scene.views[30]['cam_02'],
                        t0 + 30 * NS // 30 + int(glitch_s * NS))
    h.publish('cam_02', glitch)
    for cam, msg, _ in stream(scene, t0, range(30, 60)):
        h.publish(cam, msg)
    assert h.wait_sets(59), dict(h.node.live.counts)
    assert h.node.live.counts['resets'] == 0
    assert h.node.live.sync.stats['cam_02'].outliers == 1
    after = {t.track_id for m in h.tracks[30:] for t in m.skeletons}
    assert after == before


def test_persons_over_the_limit_dropped_whole_and_counted(harness_factory, scene):
    """A message over limits.max_persons never reaches association."""
    h = harness_factory(**{'limits.max_persons': 5})
    t0 = base_ns(20)
    crowd = np.concatenate([scene.views[0]['cam_01']] * 4)      # 12 persons
    for cam, msg, f in stream(scene, t0, range(10)):
        if cam == 'cam_01' and f == 3:
            msg = person_msg(scene, cam, crowd, stamp_to_ns(msg.header.stamp))
        h.publish(cam, msg)
    assert h.wait_sets(10)
    assert dict(h.node.cams['cam_01'].rejected) == {'too_many_persons': 1}
    assert h.node.live.counts['partial_sets'] == 1


def test_set_short_of_a_camera_released_when_its_wait_runs_out_without_new_input(
        harness_factory, scene):
    """The release timer: the last set, a camera short, goes when its wait ran out."""
    h = harness_factory(**{'sync.max_wait_s': 0.3, 'sync.max_wait_cap_s': 0.3})
    t0 = base_ns(12)
    for cam, msg, _ in stream(scene, t0, range(10)):
        h.publish(cam, msg)
    assert h.wait_sets(10)
    assert h.node.live.sync.pending() == 0 and not h.node.release_armed  # asleep
    for cam, msg, _ in stream(scene, t0, [10], skip=lambda c, f: c == 'cam_04'):
        h.publish(cam, msg)
    # Nothing else arrives: only the timer armed for the end of the wait can let it go.
    assert h.wait_sets(11, timeout=5.0), f'pending {h.node.live.sync.pending()}'
    last = h.tracks[-1]
    assert stamp_to_ns(last.header.stamp) == t0 + int(round(10 * NS / FPS))
    assert h.node.live.counts['partial_sets'] == 1
    assert h.node.live.sync.stats['cam_04'].missing == 1
    assert sum(t.state == TrackState.CONFIRMED for t in last.skeletons) == scene.num_people
    assert h.node.live.sync.pending() == 0 and not h.node.release_armed


def test_set_short_of_a_camera_goes_at_once_when_the_camera_announces_the_skip(
        harness_factory, scene):
    """pose2d_node's SkippedImages: a set stops waiting for the image a camera never infers."""
    h = harness_factory(**{'sync.max_wait_s': 5.0, 'sync.max_wait_cap_s': 5.0})
    notes = h.probe.create_publisher(SkippedImages, '/cam_04/persons_2d/skipped',
                                     reliable_qos(10))
    assert h.spin_until(lambda: notes.get_subscription_count() > 0)
    t0 = base_ns(24)
    stamp = [t0 + int(round(f * NS / FPS)) for f in range(24)]
    for cam, msg, _ in stream(scene, t0, range(20)):
        h.publish(cam, msg)
    assert h.wait_sets(20)
    for cam, msg, _ in stream(scene, t0, [20], skip=lambda c, f: c == 'cam_04'):
        h.publish(cam, msg)
    h.spin_for(0.3)
    assert h.node.live.counts['sets'] == 20        # waiting up to 5 s for cam_04's frame 20
    # cam_04 replaced frame 20 with frame 21 before inference and says so (its frame 19 was
    # the last it published). A malformed notice first: dropped, counted, nothing decided.
    notes.publish(SkippedImages(header=Header(stamp=ns_to_stamp(stamp[19])),
                                camera_id='cam_04', after=ns_to_stamp(stamp[21])))
    h.spin_for(0.2)
    assert h.node.live.counts['sets'] == 20 and h.node.cams['cam_04'].skips_rejected == 1
    t_note = time.monotonic()
    notes.publish(SkippedImages(header=Header(stamp=ns_to_stamp(stamp[21])),
                                camera_id='cam_04', after=ns_to_stamp(stamp[19])))
    assert h.wait_sets(21, timeout=2.5), 'the set still waited for the skipped image'
    assert time.monotonic() - t_note < 2.5
    assert stamp_to_ns(h.tracks[-1].header.stamp) == stamp[20]
    assert h.node.live.sync.stats['cam_04'].missing == 1 and h.node.cams['cam_04'].skips == 1
    assert h.node.live.sync.counts.decisions['skipped (announced)'] == 1
    # Frame 21 then completes its set as usual; a skip never covers its own end stamps.
    for cam, msg, _ in stream(scene, t0, [21]):
        h.publish(cam, msg)
    assert h.wait_sets(22)
    assert stamp_to_ns(h.tracks[-1].header.stamp) == stamp[21]
    assert h.node.live.counts['partial_sets'] == 1
    # Frame 20 is counted as skipped by the camera, not as lost upstream.
    cam_04 = h.node.live.sync.stats['cam_04']
    assert (cam_04.skipped, cam_04.lost) == (1, 0)
