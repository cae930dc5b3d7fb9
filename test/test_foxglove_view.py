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
mv3dpose_foxglove_view as its own process, checked by a real Foxglove WebSocket client.

The test process publishes, over DDS, the real Pose2Sim detections (4 cameras) and the tracks
``Fusion.step`` makes of them; ``mv3dpose_foxglove_view`` serves them; the client
(``io/foxglove_ws.py``, the ``websockets`` package speaking ``foxglove.sdk.v1``) checks that the
channels are advertised with their schemas and that every message it receives decodes with the
advertised schema alone and carries what was published. A picture of the received scene is drawn
by ``ros/scene.render_scene`` (set ``MV3DPOSE_FOXGLOVE_PNG=path`` to keep it).
"""

import asyncio
import base64
import contextlib
import os
import socket
import subprocess
import threading
import time

import cv2
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from google.protobuf.timestamp_pb2 import Timestamp
from mv3dpose_msgs.msg import Person2DArray, TrackedSkeletonArray
from mv3dpose_ros.core.fusion.pipeline import Fusion
from mv3dpose_ros.core.skeleton import get_layout
from mv3dpose_ros.core.types import TrackState
from mv3dpose_ros.io.foxglove_ws import FoxgloveClient
from mv3dpose_ros.ros.messages import person2d_array_to_numpy, stamp_to_ns, tracks_to_msg
from mv3dpose_ros.ros.qos import reliable_qos
from mv3dpose_ros.testing.processes import interrupt
from mv3dpose_ros.viz.palette import track_rgb
from mv3dpose_ros.viz.scene import frustum_points, latest_entities, render_scene
import numpy as np
import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from real_feed import LAYOUT, Pose2Sim
from std_msgs.msg import Header

pytestmark = [pytest.mark.ros]

SCENE, CAMERAS, TRACKS = '/mv3dpose/scene', '/mv3dpose/cameras', '/fusion_node/tracks'
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def free_port() -> int:
    with socket.socket() as s:
        s.bind(('127.0.0.1', 0))
        return s.getsockname()[1]


class Feeder:
    """Publishes the Pose2Sim detections and their tracks at 30 Hz, looping, from a thread."""

    def __init__(self, feed: Pose2Sim):
        self.feed = feed
        self.frames = self.frames_of(feed)
        self.ctx = rclpy.Context()
        rclpy.init(context=self.ctx)
        self.node = rclpy.create_node('foxglove_feeder', context=self.ctx)
        self.tracks_pub = self.node.create_publisher(TrackedSkeletonArray, TRACKS,
                                                     reliable_qos(10))
        self.pubs = {c: self.node.create_publisher(Person2DArray, f'/{c}/persons_2d',
                                                   reliable_qos(20)) for c in feed.cameras}
        self.garbage = 0
        self.diagnostics = []
        self.node.create_subscription(DiagnosticArray, '/diagnostics', self.diagnostics.append,
                                      reliable_qos(50))
        self.stopping = threading.Event()
        self.thread = threading.Thread(target=self.run, daemon=True)

    @staticmethod
    def frames_of(feed: Pose2Sim):
        """Return [(stamp_ns, {cam: Person2DArray}, TrackedSkeletonArray)] of Fusion.step."""
        fusion = Fusion(feed.cameras, LAYOUT)
        frames = []
        for i in range(len(feed.frames)):
            msgs = dict(feed.messages(i))
            views = {c: person2d_array_to_numpy(m, 25).astype(np.float32).astype(np.float64)
                     for c, m in msgs.items()}
            tracks = fusion.step(views, feed.stamp_ns(i) / 1e9)
            header = Header(stamp=msgs['cam_01'].header.stamp, frame_id='world')
            frames.append((feed.stamp_ns(i), msgs, tracks_to_msg(tracks, header, LAYOUT)))
        return frames

    def matched(self) -> bool:
        return self.tracks_pub.get_subscription_count() > 0 and \
            all(p.get_subscription_count() for p in self.pubs.values())

    def start(self):
        self.thread.start()

    def run(self):
        i = 0
        while not self.stopping.is_set():
            _, msgs, tracks = self.frames[i % len(self.frames)]
            for cam, m in msgs.items():
                self.pubs[cam].publish(m)
            if i == 5:        # unreadable bytes on the tracks topic: dropped, view keeps going
                self.tracks_pub.publish(b'\x00\x01\x00\x00\xff\xff\xff\x7f')
                self.garbage += 1
            self.tracks_pub.publish(tracks)
            i += 1
            time.sleep(1 / 30)

    def close(self):
        self.stopping.set()
        if self.thread.is_alive():
            self.thread.join(5)
        self.node.destroy_node()
        rclpy.shutdown(context=self.ctx)


@contextlib.contextmanager
def running_view(args, tmp_path, feeder):
    """Run mv3dpose_foxglove_view with ``args`` until ``feeder``'s publishers matched it."""
    port = free_port()
    log_path = tmp_path / 'foxglove_view.log'
    log = open(log_path, 'w')
    proc = subprocess.Popen(['mv3dpose_foxglove_view', '--port', str(port)] + args,
                            stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
    executor = SingleThreadedExecutor(context=feeder.ctx)
    executor.add_node(feeder.node)
    try:
        # Up = its WebSocket is served (logged last in its constructor) and DDS matched; a
        # loaded 2-core host can take tens of seconds to import and start it.
        deadline = time.monotonic() + 90

        def up():
            return 'Foxglove WebSocket on' in log_path.read_text() and feeder.matched()
        while time.monotonic() < deadline and not up():
            assert proc.poll() is None, log_path.read_text()
            executor.spin_once(timeout_sec=0.05)
        assert up(), 'foxglove_view never came up: ' + log_path.read_text()
        executor.remove_node(feeder.node)
        yield f'ws://127.0.0.1:{port}', proc, log_path
    finally:
        feeder.close()
        code = interrupt(proc, 10)
        log.close()
    assert code == 0, log_path.read_text()


@pytest.fixture
def view(shared_data, tmp_path):
    feed = Pose2Sim(shared_data, frames=40)
    feeder = Feeder(feed)
    with running_view(['--rig', feed.rig_path], tmp_path, feeder) as (url, proc, log_path):
        feeder.start()
        yield url, feeder, proc, log_path


def test_client_receives_decodable_scene_tracks_and_detections(view, tmp_path):
    url, feeder, proc, log_path = view
    cams = list(feeder.feed.cameras)
    det_topics = [f'/{c}/persons_2d' for c in cams]

    async def session():
        async with FoxgloveClient(url) as client:
            await client.wait_for_topics([SCENE, CAMERAS, TRACKS] + det_topics, 30.0)
            adv = client.topics()
            await client.subscribe([SCENE, CAMERAS, TRACKS] + det_topics)

            def enough(got):
                seen = {m.topic for m in got}
                tracks = [m for m in got if m.topic == TRACKS]
                return seen >= {SCENE, CAMERAS, TRACKS, *det_topics} and len(tracks) >= 20
            return client.server_info, adv, await client.receive(60.0, enough)

    info, adv, got = asyncio.run(session())
    assert info['op'] == 'serverInfo' and info['name'] == 'mv3dpose'
    assert adv[SCENE]['schemaName'] == 'foxglove.SceneUpdate'
    assert adv[SCENE]['encoding'] == adv[SCENE]['schemaEncoding'] == 'protobuf'
    assert adv[TRACKS]['schemaName'] == 'mv3dpose_msgs/msg/TrackedSkeletonArray'
    assert (adv[TRACKS]['encoding'], adv[TRACKS]['schemaEncoding']) == ('cdr', 'ros2msg')
    assert 'MSG: mv3dpose_msgs/Joint3D' in adv[TRACKS]['schema']        # nested definitions
    for t in det_topics:
        assert adv[t]['schemaName'] == 'mv3dpose_msgs/msg/Person2DArray'

    by_stamp = {stamp: (msgs, tracks) for stamp, msgs, tracks in feeder.frames}
    # Tracks: decoded from the advertised ros2msg schema (rosbags), equal to what was published.
    tracks_rx = [m for m in got if m.topic == TRACKS]
    assert len(tracks_rx) >= 20
    for m in tracks_rx:
        stamp = m.decoded.header.stamp.sec * 10**9 + m.decoded.header.stamp.nanosec
        _, sent = by_stamp[stamp]
        assert m.log_time == stamp
        assert [s.track_id for s in m.decoded.skeletons] == [s.track_id for s in sent.skeletons]
        for a, b in zip(m.decoded.skeletons, sent.skeletons):
            assert (a.position.x, a.position.y, a.position.z) == \
                (b.position.x, b.position.y, b.position.z)
            assert a.state == b.state and len(a.joints) == len(b.joints) == 25
    # Detections: same keypoints as published (float32 on the wire).
    for m in (m for m in got if m.topic in det_topics):
        msgs, _ = by_stamp[m.log_time]
        cam = m.decoded.camera_id
        sent = person2d_array_to_numpy(msgs[cam], 25)
        rx = np.array([[[k.x, k.y, k.confidence] for k in p.keypoints]
                       for p in m.decoded.persons]).reshape(-1, 25, 3)
        np.testing.assert_allclose(rx, sent, atol=1e-3)
    # Scene: one entity per live track, joints at the published positions, coloured by id.
    scene_rx = [m for m in got if m.topic == SCENE]
    bones = get_layout(LAYOUT).bones
    checked = 0
    for m in scene_rx:
        _, sent = by_stamp[m.log_time]
        live = {s.track_id: s for s in sent.skeletons if s.state != TrackState.DELETED}
        ents = {e['id']: e for e in m.decoded.get('entities', [])}
        assert set(ents) == {f'person/{i}' for i in live}
        for tid, s in live.items():
            e = ents[f'person/{tid}']
            assert e['frame_id'] == 'world'         # the tracks' frame
            [line] = e['lines']
            assert line['type'] == 'LINE_LIST'
            valid = [j for j in s.joints if j.state != 0]
            pts = np.array([[p.get(k, 0.0) for k in 'xyz'] for p in line['points']])
            want = np.array([[j.position.x, j.position.y, j.position.z] for j in valid])
            np.testing.assert_allclose(pts, want, atol=1e-9)
            assert len(line.get('indices', [])) <= 2 * len(bones)
            r, g, b = track_rgb(tid)
            assert (line['color']['r'], line['color']['g'], line['color']['b']) == \
                pytest.approx((r, g, b))
            assert e['texts'][0]['text'].startswith(f'#{tid} ')
            checked += 1
    assert checked >= 10
    # Cameras: one frustum per rig camera, apex at the camera centre.
    cam_ents = latest_entities([m.decoded for m in got if m.topic == CAMERAS])
    assert set(cam_ents) == {f'camera/{c}' for c in cams}
    assert {e['frame_id'] for e in cam_ents.values()} == {'world'}    # the rig's world_frame
    for c, cam in feeder.feed.cameras.items():
        apex = cam_ents[f'camera/{c}']['lines'][0]['points'][0]
        np.testing.assert_allclose([apex.get(k, 0.0) for k in 'xyz'],
                                   frustum_points(cam, 0.5)[0], atol=1e-9)
    # The unreadable message was dropped with a reason, and data kept flowing after it.
    assert feeder.garbage == 1
    assert any(stamp_to_ns(m.decoded.header.stamp) for m in tracks_rx)
    # The picture of what the client received, drawn from the received scene messages only.
    ents = latest_entities([m.decoded for m in got if m.topic in (SCENE, CAMERAS)])
    picture = render_scene(ents, f'Foxglove client: {len(scene_rx)} scene updates received')
    colours = {tuple(int(round(255 * c)) for c in reversed(track_rgb(int(i.split('/')[1]))))
               for i in ents if i.startswith('person/')}
    assert colours, 'no skeleton in the last scene'
    for bgr in colours:
        assert np.any(np.all(picture == bgr, axis=-1)), f'track colour {bgr} not drawn'
    out = os.environ.get('MV3DPOSE_FOXGLOVE_PNG') or str(tmp_path / 'foxglove_scene.png')
    from mv3dpose_ros.viz.pictures import write_png
    write_png(picture, out)
    print(f'\nFoxglove client: {len(got)} messages ({len(tracks_rx)} tracks, {len(scene_rx)} '
          f'scene updates); picture {out}')
    # ... logged with its reason, and counted on /diagnostics.
    executor = SingleThreadedExecutor(context=feeder.ctx)
    executor.add_node(feeder.node)

    def counted():
        return [s for a in feeder.diagnostics for s in a.status
                if s.name == 'foxglove_view: web view' and
                {kv.key: kv.value for kv in s.values}.get('dropped tracks') == '1']
    deadline = time.monotonic() + 20
    while not counted() and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.1)
    executor.remove_node(feeder.node)
    assert counted(), 'drop not counted on /diagnostics'
    assert any(s.level == DiagnosticStatus.WARN for s in counted()) or \
        any(s.level == DiagnosticStatus.WARN for a in feeder.diagnostics for s in a.status
            if s.name == 'foxglove_view: web view')
    assert 'unreadable TrackedSkeletonArray dropped' in log_path.read_text()
    assert proc.poll() is None


class ImageFeeder:
    """Publishes one real Panoptic image and, 0.1 s later, detections with its stamp."""

    def __init__(self, shared_data):
        from mv3dpose_ros.ros.images import numpy_to_image
        from mv3dpose_ros.ros.messages import ns_to_stamp, numpy_to_person2d_array
        from sensor_msgs.msg import Image
        self.bgr = cv2.imread(os.path.join(shared_data, 'panoptic_demo', '00_03',
                                           '00_03_00004500.jpg'))
        assert self.bgr is not None and self.bgr.shape == (1080, 1920, 3)
        stamp = ns_to_stamp(time.time_ns())
        header = Header(stamp=stamp, frame_id='cam00_03_optical_frame')
        self.image = numpy_to_image(self.bgr, header, 'bgr8')
        # one COCO-17 person: a vertical stick figure in the image centre (only input here)
        kp = np.zeros((1, 17, 3))
        for j, (x, y) in {5: (900, 400), 6: (1020, 400), 11: (920, 650), 12: (1000, 650),
                          13: (920, 850), 14: (1000, 850)}.items():
            kp[0, j] = (x, y, 0.9)
        self.keypoints = kp
        self.persons = numpy_to_person2d_array(kp, header, '00_03', 1920, 1080, 'coco17')
        self.ctx = rclpy.Context()
        rclpy.init(context=self.ctx)
        self.node = rclpy.create_node('image_feeder', context=self.ctx)
        self.image_pub = self.node.create_publisher(Image, '/cam00_03/image_raw',
                                                    reliable_qos(2))
        self.det_pub = self.node.create_publisher(Person2DArray, '/cam00_03/persons_2d',
                                                  reliable_qos(5))

    def matched(self):                 # the images only once a client watches their channel
        return self.det_pub.get_subscription_count() > 0

    def publish(self):
        self.image_pub.publish(self.image)
        time.sleep(0.1)            # detections come later than the image, as from pose2d_node
        self.det_pub.publish(self.persons)

    def close(self):
        self.node.destroy_node()
        rclpy.shutdown(context=self.ctx)


def test_images_with_the_2d_skeletons_drawn(shared_data, tmp_path):
    rig = os.path.join(ROOT, 'config', 'rigs', 'panoptic_demo.yaml')
    feeder = ImageFeeder(shared_data)
    topic = '/cam00_03/image_skeletons'
    with running_view(['--rig', rig, '--image-topic', '/{camera}/image_raw'], tmp_path,
                      feeder) as (url, proc, log_path):
        async def until(test, timeout):
            deadline = time.monotonic() + timeout
            while not test() and time.monotonic() < deadline:
                await asyncio.sleep(0.05)
            return test()

        def image_subscribers():
            return feeder.image_pub.get_subscription_count()

        async def session():
            async with FoxgloveClient(url) as client:
                await client.wait_for_topics([topic], 30.0)
                adv = client.topics()[topic]
                await asyncio.sleep(0.5)
                assert image_subscribers() == 0, 'images taken with nobody watching'
                await client.subscribe([topic])
                assert await until(lambda: image_subscribers() == 1, 15.0), \
                    'the watched camera images were not subscribed: ' + log_path.read_text()
                await asyncio.sleep(0.3)
                for _ in range(3):
                    feeder.publish()
                    got = await client.receive(3.0, lambda got: len(got) >= 1)
                    if got:
                        return adv, got
                return adv, []
        adv, got = asyncio.run(session())
        assert asyncio.run(until(lambda: image_subscribers() == 0, 15.0)), \
            'the images stayed subscribed after the client left: ' + log_path.read_text()
        # The node logs just after it released the subscription: wait for the line too.
        assert asyncio.run(until(lambda: 'no longer watched' in log_path.read_text(), 5.0)), \
            log_path.read_text()
    assert adv['schemaName'] == 'foxglove.CompressedImage' and adv['encoding'] == 'protobuf'
    assert got, 'no annotated image received: ' + log_path.read_text()
    msg = got[0].decoded
    assert msg['format'] == 'jpeg' and msg['frame_id'] == 'cam00_03_optical_frame'
    stamp = feeder.image.header.stamp
    ts = Timestamp()
    ts.FromJsonString(msg['timestamp'])              # a well-known type: RFC 3339 in JSON
    assert (ts.seconds, ts.nanos) == (stamp.sec, stamp.nanosec)
    jpeg = np.frombuffer(base64.b64decode(msg['data']), np.uint8)
    drawn = cv2.imdecode(jpeg, cv2.IMREAD_COLOR)
    assert drawn.shape == (540, 960, 3)                     # scaled to image_max_width 960
    plain = cv2.resize(feeder.bgr, (960, 540), interpolation=cv2.INTER_AREA)
    diff = np.abs(drawn.astype(int) - plain.astype(int)).sum(axis=2)
    # along the left thigh (hip 11 -> knee 13, x = 920 px full size = 460 px here): drawn
    thigh = diff[340:410, 455:466]
    assert np.median(thigh.max(axis=1)) > 100, 'skeleton not drawn on the image'
    # far from the figure: the image itself, up to JPEG noise
    assert np.median(diff[:150, :300]) < 25


def test_bringup_starts_the_web_view_beside_fusion_node(tmp_path):
    """mv3dpose_bringup --foxglove: the view runs as one more child, with the rig's cameras."""
    rig = os.path.join(ROOT, 'config', 'rigs', 'pose2sim_multiperson.yaml')
    port = free_port()
    log_path = tmp_path / 'bringup.log'
    log = open(log_path, 'w')
    proc = subprocess.Popen(['mv3dpose_bringup', '--rig', rig, '--no-pose2d', '--foxglove',
                             str(port)], stdout=log, stderr=subprocess.STDOUT,
                            start_new_session=True)
    dets = [f'/cam_0{i}/persons_2d' for i in range(1, 5)]

    async def session():
        deadline = time.monotonic() + 90
        while True:
            assert proc.poll() is None, log_path.read_text()
            try:
                async with FoxgloveClient(f'ws://127.0.0.1:{port}') as client:
                    await client.wait_for_topics([SCENE, CAMERAS, TRACKS] + dets, 30.0)
                    await client.subscribe([CAMERAS])
                    return await client.receive(5.0, lambda got: len(got) >= 1)
            except OSError:
                if time.monotonic() > deadline:
                    raise
                await asyncio.sleep(0.5)
    try:
        got = asyncio.run(session())
        deadline = time.monotonic() + 60        # stop once fusion_node is up too
        while 'fusing 4 cameras' not in log_path.read_text() and time.monotonic() < deadline:
            assert proc.poll() is None, log_path.read_text()
            time.sleep(0.2)
    finally:
        code = interrupt(proc, 20)
        log.close()
    assert got, log_path.read_text()
    assert set(latest_entities([m.decoded for m in got])) == \
        {f'camera/cam_0{i}' for i in range(1, 5)}
    assert code == 0, log_path.read_text()


def test_scene_update_deletes_ended_tracks_and_fades_coasting_ones(shared_data):
    """skeleton_update on real tracks: DELETED -> a deletion of its id, COASTING faded."""
    from mv3dpose_ros.ros.messages import msg_to_tracks
    from mv3dpose_ros.viz.scene import skeleton_update
    feed = Pose2Sim(shared_data, frames=10)
    *_, last = Feeder.frames_of(feed)[-1]
    tracks = [t for t in msg_to_tracks(last) if t.state == TrackState.CONFIRMED]
    assert len(tracks) == 2
    tracks[0].state, tracks[1].state = TrackState.DELETED, TrackState.COASTING
    update = skeleton_update(tracks, get_layout(LAYOUT).bones, 'world', 5_000_000_123, 0.5)
    from google.protobuf import descriptor_pb2, descriptor_pool, json_format, message_factory
    from foxglove.messages import SceneUpdate
    schema = SceneUpdate.get_schema()
    pool = descriptor_pool.DescriptorPool()
    for fd in descriptor_pb2.FileDescriptorSet.FromString(schema.data).file:
        pool.Add(fd)
    cls = message_factory.GetMessageClass(pool.FindMessageTypeByName(schema.name))
    d = json_format.MessageToDict(cls.FromString(update.encode()),
                                  preserving_proto_field_name=True)
    assert [x['id'] for x in d['deletions']] == [f'person/{tracks[0].track_id}']
    [entity] = d['entities']
    assert entity['id'] == f'person/{tracks[1].track_id}'
    assert entity['lines'][0]['color']['a'] == pytest.approx(0.35)
    assert entity['texts'][0]['text'] == f'#{tracks[1].track_id} coasting'
    assert entity['lifetime'] == '0.500s'
    assert entity['timestamp'] == '1970-01-01T00:00:05.000000123Z'
