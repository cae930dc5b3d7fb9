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
fusion_node's standard output ``~/poses`` and its ``~/reset`` service, over DDS, as a process.

The real Pose2Sim detections go in; ``~/poses`` (``geometry_msgs/PoseArray``) must carry, for
every ``~/tracks`` message, the roots of the same skeletons in the same order with the same
header; ``~/reset`` (``std_srvs/Trigger``) must end every track (DELETED tombstones, an empty
PoseArray) and tracking must start again with new ids.
"""

import math
import os

from geometry_msgs.msg import PoseArray
from mv3dpose_msgs.msg import Person2DArray, TrackedSkeletonArray
from mv3dpose_ros.core.types import TrackState
from mv3dpose_ros.ros.frames import yaw_from_quaternion
from mv3dpose_ros.ros.messages import stamp_to_ns
from mv3dpose_ros.ros.qos import reliable_qos
from mv3dpose_ros.testing.probe import Probe
from mv3dpose_ros.testing.processes import NodeProcess
import pytest
from real_feed import Pose2Sim
from std_srvs.srv import Trigger
import yaml

pytestmark = [pytest.mark.ros]

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def test_pose_array_in_sync_with_tracks_and_reset_service(shared_data, tmp_path, ros_context):
    feed = Pose2Sim(shared_data, frames=60)
    params = tmp_path / 'params.yaml'
    params.write_text(yaml.safe_dump({'/**/fusion_node': {'ros__parameters': {
        'rig_config': feed.rig_path, 'layout': 'body25b', 'world_frame': 'map',
        # 60 fps: frames 16.7 ms apart; a loaded host may deliver one camera 1 s late
        'sync': {'slop_s': 0.008, 'max_wait_s': 2.0}}}}))
    log_path = tmp_path / 'fusion_node.log'
    proc = NodeProcess(['fusion_node', '--ros-args', '--params-file',
                        os.path.join(ROOT, 'config', 'fusion.yaml'), '--params-file',
                        str(params)], log_path)
    probe = Probe('outputs_probe', context=ros_context)
    tracks = probe.subscribe(TrackedSkeletonArray, '/fusion_node/tracks', reliable_qos(200))
    poses = probe.subscribe(PoseArray, '/fusion_node/poses', reliable_qos(200))
    pubs = probe.camera_publishers(Person2DArray, feed.cameras)
    reset = probe.node.create_client(Trigger, '/fusion_node/reset')

    def spin_until(pred, timeout):
        return probe.spin_until(pred, timeout, processes=[proc])

    def play(frames):
        for i in frames:
            n = len(tracks)
            for cam, msg in feed.messages(i):
                pubs[cam].publish(msg)
            assert spin_until(lambda: len(tracks) > n and len(poses) > n, 10.0), \
                f'no output for frame {i}: ' + log_path.read_text()[-3000:]

    try:
        assert spin_until(lambda: all(p.get_subscription_count() for p in pubs.values()) and
                          probe.node.count_publishers('/fusion_node/poses') > 0 and
                          reset.service_is_ready(), 30.0), log_path.read_text()
        play(range(30))
        before = len(tracks)
        future = reset.call_async(Trigger.Request())
        assert spin_until(future.done, 10.0), 'no reply from ~/reset'
        reply = future.result()
        assert spin_until(lambda: len(tracks) > before and len(poses) > before, 10.0)
        tombstones = tracks[before]
        after_reset = len(tracks)
        play(range(30, 60))
    finally:
        code = proc.interrupt(10)
        probe.close()
    assert code == 0, log_path.read_text()

    # ~/poses pairs with ~/tracks message for message: same header, roots in the same order.
    assert len(poses) == len(tracks)
    for t, p in zip(tracks, poses):
        assert p.header.frame_id == t.header.frame_id == 'map'
        assert stamp_to_ns(p.header.stamp) == stamp_to_ns(t.header.stamp)
        live = [s for s in t.skeletons if s.state != TrackState.DELETED]
        assert [(q.position.x, q.position.y, q.position.z) for q in p.poses] == \
            [(s.position.x, s.position.y, s.position.z) for s in live]
        for q in p.poses:
            o = q.orientation
            assert math.isclose(o.x * o.x + o.y * o.y + o.z * o.z + o.w * o.w, 1.0,
                                rel_tol=1e-9) and o.x == o.y == 0.0     # yaw only, z up
    first_ids = {s.track_id for m in tracks[:before] for s in m.skeletons
                 if s.state == TrackState.CONFIRMED}
    assert len(first_ids) == 2, f'expected the 2 Pose2Sim people, got {first_ids}'
    # Both people have their hips triangulated, so both poses carry a heading (not identity).
    last = poses[before - 1]
    yaws = [yaw_from_quaternion(q.orientation) for q in last.poses]
    assert len(yaws) == 2 and all(y != 0.0 for y in yaws)

    # ~/reset: success, every track ended once (DELETED), an empty PoseArray, then new ids.
    assert reply.success and reply.message == 'cleared 2 tracks and the synchroniser'
    assert {s.track_id for s in tombstones.skeletons} == first_ids
    assert all(s.state == TrackState.DELETED for s in tombstones.skeletons)
    assert poses[before].poses == []
    new_ids = {s.track_id for m in tracks[after_reset:] for s in m.skeletons
               if s.state == TrackState.CONFIRMED}
    assert len(new_ids) == 2 and min(new_ids) > max(first_ids)
    assert '~/reset service call' in log_path.read_text()
