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

"""Bag tools: typestore, atomic writer, clear errors, and record / play over real DDS."""

import os
import shutil
import subprocess
import sys
import time

from fuzz_corpus import mcap_chunks
from mv3dpose_ros.commands.bag import info, qos_from_rclpy, qos_to_rclpy
from mv3dpose_ros.io.bag import BagError, BagReader, BagWriter, check_bag, get_typestore
from mv3dpose_ros.io.bag import make_qos
from mv3dpose_ros.nodes.roundtrip_probe import sample_message
from mv3dpose_ros.ros.messages import message_to_dict
from mv3dpose_ros.testing.spin import spin_until
import pytest
from rosbags.interfaces import QosDurability, QosReliability

MV3DPOSE = [sys.executable, '-m', 'mv3dpose_ros.cli']


def _person_msg(i: int):
    """Build a rosbags Person2DArray whose fields all depend on ``i``."""
    ts = get_typestore()
    t = ts.types
    kps = [t['mv3dpose_msgs/msg/Keypoint2D'](x=float(i + j), y=float(2 * j), confidence=0.5)
           for j in range(17)]
    person = t['mv3dpose_msgs/msg/Person2D'](
        roi=t['sensor_msgs/msg/RegionOfInterest'](
            x_offset=i, y_offset=2, height=3, width=4, do_rectify=False),
        score=0.25, id=f'p{i}', keypoints=kps)
    header = t['std_msgs/msg/Header'](stamp=t['builtin_interfaces/msg/Time'](sec=i, nanosec=7),
                                      frame_id='cam0_optical')
    return t['mv3dpose_msgs/msg/Person2DArray'](header=header, camera_id='cam0', image_width=640,
                                                image_height=480, layout='coco17',
                                                persons=[person] * (i % 3))


def _write_bag(path, storage='mcap', n=20, step_ns=50_000_000, t0=1_700_000_000 * 10 ** 9):
    """Write ``n`` Person2DArray and ``n`` String messages interleaved; return the stamps."""
    ts = get_typestore()
    string = ts.types['std_msgs/msg/String']
    stamps = []
    with BagWriter(path, storage=storage) as w:
        w.add_topic('/cam0/persons_2d', 'mv3dpose_msgs/msg/Person2DArray', [make_qos()])
        w.add_topic('/chatter', 'std_msgs/msg/String',
                    [make_qos(reliable=True, depth=5, transient_local=False)])
        for i in range(n):
            stamp = t0 + 2 * i * step_ns
            w.write_msg('/cam0/persons_2d', stamp, _person_msg(i),
                        'mv3dpose_msgs/msg/Person2DArray')
            w.write_msg('/chatter', stamp + step_ns, string(data=f'hello {i}'),
                        'std_msgs/msg/String')
            stamps += [stamp, stamp + step_ns]
    return stamps


# ------------------------------------------------------------------------------ no DDS

@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_writer_reader_round_trip_custom_messages(tmp_path, storage):
    path = tmp_path / 'bag'
    stamps = _write_bag(path, storage=storage, n=6)
    with BagReader(path) as reader:
        assert reader.storage == storage
        topics = reader.topics()
        assert topics['/cam0/persons_2d'].msgtype == 'mv3dpose_msgs/msg/Person2DArray'
        assert topics['/cam0/persons_2d'].count == 6
        assert topics['/chatter'].qos[0].depth == 5
        assert topics['/chatter'].qos[0].reliability == QosReliability.RELIABLE
        got = list(reader.decoded())
    assert [t for _, t, _ in got] == stamps
    people = [m for topic, _, m in got if topic == '/cam0/persons_2d']
    for i, msg in enumerate(people):
        expected = _person_msg(i)
        assert msg.header.stamp.sec == i and msg.header.frame_id == 'cam0_optical'
        assert len(msg.persons) == i % 3
        for p, q in zip(msg.persons, expected.persons):
            assert p.id == q.id and p.roi.x_offset == q.roi.x_offset
            assert [(k.x, k.y, k.confidence) for k in p.keypoints] == \
                [(k.x, k.y, k.confidence) for k in q.keypoints]
    assert os.listdir(tmp_path) == ['bag'], 'temporary files left beside the bag'


def test_bag_info_reports_topics_counts_duration(tmp_path):
    _write_bag(tmp_path / 'bag', n=10, step_ns=100_000_000)
    summary = info(str(tmp_path / 'bag'))
    assert summary['storage'] == 'mcap'
    assert summary['messages'] == 20
    assert summary['duration_s'] == pytest.approx(1.9)
    assert summary['topics']['/chatter'] == {
        'type': 'std_msgs/msg/String', 'count': 10,
        'qos': 'reliable/volatile/keep_last(5)'}


def test_writer_failure_leaves_nothing(tmp_path):
    path = tmp_path / 'out'
    with pytest.raises(RuntimeError):
        with BagWriter(path) as w:
            w.add_topic('/chatter', 'std_msgs/msg/String')
            w.write_msg('/chatter', 1, get_typestore().types['std_msgs/msg/String'](data='x'),
                        'std_msgs/msg/String')
            raise RuntimeError('simulated crash while writing')
    assert os.listdir(tmp_path) == []


def test_writer_refuses_existing_output_and_unknown_type(tmp_path):
    (tmp_path / 'exists').mkdir()
    with pytest.raises(BagError, match='exists'):
        BagWriter(tmp_path / 'exists')
    with pytest.raises(BagError, match='does not exist'):
        BagWriter(tmp_path / 'no' / 'such' / 'bag')
    with pytest.raises(BagError, match='nope_msgs/msg/Nothing'):
        with BagWriter(tmp_path / 'b') as w:
            w.add_topic('/x', 'nope_msgs/msg/Nothing')
    assert sorted(os.listdir(tmp_path)) == ['exists']


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_truncated_and_corrupt_bags_name_the_file(tmp_path, storage):
    good = tmp_path / 'good'
    _write_bag(good, storage=storage, n=40)
    data_file = next(p for p in good.iterdir() if p.name != 'metadata.yaml')
    assert check_bag(good) == 80

    truncated = tmp_path / 'truncated'
    shutil.copytree(good, truncated)
    inner = truncated / data_file.name
    inner.write_bytes(data_file.read_bytes()[: data_file.stat().st_size // 2])
    with pytest.raises(BagError, match='truncated'):
        check_bag(truncated)

    garbage = tmp_path / 'garbage'
    shutil.copytree(good, garbage)
    (garbage / data_file.name).write_bytes(b'\x00not a bag\x00' * 50)
    with pytest.raises(BagError) as err:
        check_bag(garbage)
    assert 'garbage' in str(err.value)

    with pytest.raises(BagError, match='no such bag'):
        BagReader(tmp_path / 'missing')
    (tmp_path / 'empty_dir').mkdir()
    with pytest.raises(BagError, match='metadata.yaml'):
        BagReader(tmp_path / 'empty_dir')


def _chunks(mcap):
    """Return ``(offset, length)`` of every chunk record of an MCAP file."""
    return mcap_chunks(mcap.read_bytes())


def _payload_corruptions(good, storage, count, seed):
    """Yield bags copied from ``good`` with one payload byte changed in each."""
    import random
    import sqlite3
    rng = random.Random(seed)
    data_file = next(p for p in good.iterdir() if p.name != 'metadata.yaml')
    for k in range(count):
        bad = good.parent / f'{storage}_corrupt_{k}'
        shutil.copytree(good, bad)
        target = bad / data_file.name
        if storage == 'mcap':
            raw = bytearray(target.read_bytes())
            offset, length = rng.choice(_chunks(target))
            pos = offset + 9 + 60 + rng.randrange(length - 60)   # inside the records
            raw[pos] ^= 1 << rng.randrange(8)
            target.write_bytes(bytes(raw))
        else:
            with sqlite3.connect(target) as conn:
                rowid, blob = conn.execute('SELECT id, data FROM messages ORDER BY random() '
                                           'LIMIT 1').fetchone()
                blob = bytearray(blob)
                blob[rng.randrange(len(blob))] ^= 1 << rng.randrange(8)
                conn.execute('UPDATE messages SET data = ? WHERE id = ?', (bytes(blob), rowid))
            conn.close()
        yield bad


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_payload_corruption_is_detected_naming_file_and_chunk(tmp_path, storage):
    """Bags carry CRCs: a changed payload byte is an error, never wrong values."""
    good = tmp_path / 'good'
    _write_bag(good, storage=storage, n=40)
    if storage == 'mcap':
        mcap = good / 'good.mcap'
        assert _chunks(mcap) and all(
            int.from_bytes(mcap.read_bytes()[o + 33:o + 37], 'little') != 0
            for o, _ in _chunks(mcap))                                   # real chunk CRCs
    rejected = 0
    for bad in _payload_corruptions(good, storage, 10, seed=7):
        with pytest.raises(BagError) as err:
            check_bag(bad)
        text = str(err.value)
        assert str(bad) in text and 'corrupt' in text, text
        assert ('chunk 0 (at byte' in text) if storage == 'mcap' else ('message on /' in text)
        with pytest.raises(BagError, match='corrupt'):
            info(bad, verify=True)                       # bag info checks every CRC
        rejected += 1
    assert rejected == 10
    # the summary (chunk index, statistics) is covered by the footer CRC
    if storage == 'mcap':
        bad = tmp_path / 'summary'
        shutil.copytree(good, bad)
        raw = bytearray((bad / 'good.mcap').read_bytes())
        raw[-60] ^= 0x10
        (bad / 'good.mcap').write_bytes(bytes(raw))
        with pytest.raises(BagError, match='summary section'):
            check_bag(bad)


def test_overwrite_replaces_only_a_bag(tmp_path):
    """--overwrite refuses a folder holding the sources before deleting anything."""
    src = tmp_path / 'src'
    src.mkdir()
    (src / 'main.py').write_text('print(1)\n')
    with pytest.raises(BagError, match='not a rosbag2 bag'):
        BagWriter(src, overwrite=True)
    assert (src / 'main.py').read_text() == 'print(1)\n'
    (src / 'metadata.yaml').write_text('x: 1\n')     # a bag's name, and still sources inside
    with pytest.raises(BagError, match='not a rosbag2 bag'):
        BagWriter(src, overwrite=True)
    lone = tmp_path / 'notes.txt'
    lone.write_text('keep')
    with pytest.raises(BagError, match='is a file'):
        BagWriter(lone, overwrite=True)
    bag = tmp_path / 'bag'
    _write_bag(bag, n=3)
    _write_bag(bag.parent / 'bag2', n=5)
    with BagWriter(bag, overwrite=True) as w:            # a bag is replaced
        w.add_topic('/x', 'std_msgs/msg/String')
    assert check_bag(bag) == 0
    proc = subprocess.run(MV3DPOSE + ['bag', 'record', '-o', str(src), '--overwrite',
                                      '--duration', '1', '-q'],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 1 and str(src) in proc.stderr and 'Traceback' not in proc.stderr
    assert (src / 'main.py').exists()


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_checkpointed_partial_bag_is_salvaged(tmp_path, storage):
    """A writer that dies after a checkpoint keeps everything before it."""
    from mv3dpose_ros.commands.bag import recover
    ts = get_typestore()
    string = ts.types['std_msgs/msg/String']
    target = tmp_path / 'rec'
    w = BagWriter(target, storage=storage)
    w.add_topic('/chatter', 'std_msgs/msg/String', [make_qos(reliable=False, depth=7)])
    for i in range(50):
        w.write_msg('/chatter', 1000 + i, string(data=f'm{i}'), 'std_msgs/msg/String')
        if i == 29:
            w.checkpoint()
    # as SIGKILL would leave it: the OS has what was flushed, the process buffers are gone
    partial = tmp_path / f'.rec.partial-{os.getpid()}'
    dead = tmp_path / '.rec.partial-999999999'
    shutil.copytree(partial, dead)
    w.abort()
    results = recover(str(target))
    assert [r['source'] for r in results] == [str(dead)] and not dead.exists()
    with BagReader(target) as reader:
        data = [m.data for _, _, m in reader.decoded()]
        qos = reader.topics()['/chatter'].qos
    assert data[:30] == [f'm{i}' for i in range(30)]
    assert data == [f'm{i}' for i in range(len(data))]
    assert qos and qos[0].reliability == QosReliability.BEST_EFFORT and qos[0].depth == 7
    with pytest.raises(BagError, match='no interrupted recording'):
        recover(str(target))


def test_sigkilled_recorder_loses_at_most_its_last_checkpoint(tmp_path):
    """
    A real recorder process SIGKILLed while recording: ``bag recover`` gives back >= 95 %.

    The publisher stamps a sequence number into each message, so every message published
    between the first recorded one and the kill is accounted for.
    """
    import signal
    env = dict(os.environ)
    log = open(tmp_path / 'published.txt', 'w')    # a file: a full pipe would block it
    pub = subprocess.Popen([sys.executable, '-c', _PUBLISHER], stdout=log,
                           stderr=subprocess.DEVNULL, text=True, env=env)
    out = tmp_path / 'rec'
    rec = subprocess.Popen(MV3DPOSE + ['bag', 'record', '/seq', '-o', str(out), '-q',
                                       '--checkpoint', '0.2'],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        partial = None
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and partial is None:   # wait for the first chunk
            found = [p for p in tmp_path.glob('.rec.partial-*/rec/*.mcap')
                     if p.stat().st_size > 4096]
            partial = found[0] if found else None
            time.sleep(0.2)
        assert partial is not None, 'the recorder wrote nothing'
        time.sleep(4.0)
        rec.send_signal(signal.SIGKILL)
        rec.wait(timeout=10)
        killed_at = time.monotonic()
    finally:
        if rec.poll() is None:
            rec.kill()
            rec.wait()
        pub.send_signal(signal.SIGINT)
        try:
            pub.wait(timeout=20)
        except subprocess.TimeoutExpired:       # stuck in publish: never leave it running
            pub.kill()
            pub.wait()
        log.close()
        pout = (tmp_path / 'published.txt').read_text()
    published = [(float(t), int(n)) for t, n in (line.split() for line in pout.split('\n')
                                                 if line.strip())]
    proc = subprocess.run(MV3DPOSE + ['bag', 'recover', str(out)], capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert not list(tmp_path.glob('.rec.partial-*'))
    with BagReader(out) as reader:
        seqs = [int(m.data) for _, _, m in reader.decoded()]
    assert seqs == sorted(seqs) and len(set(seqs)) == len(seqs)
    sent = [n for t, n in published if seqs[0] <= n and t <= killed_at]
    kept = len(seqs) / len(sent)
    assert kept >= 0.95, f'kept {len(seqs)} of {len(sent)} messages'


# publishes std_msgs/String '0', '1', ... at 200 Hz; prints "monotonic_time seq" per message
_PUBLISHER = """
import sys, time
import rclpy
from rclpy.signals import SignalHandlerOptions
from std_msgs.msg import String
rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
node = rclpy.create_node('seq_pub')
pub = node.create_publisher(String, '/seq', 100)
n = 0
try:
    while True:
        pub.publish(String(data=str(n)))
        print(time.monotonic(), n, flush=True)
        n += 1
        time.sleep(0.005)
except KeyboardInterrupt:
    pass
"""


def test_cli_errors_are_one_line_naming_the_file(tmp_path):
    truncated = tmp_path / 'broken'
    _write_bag(truncated, n=30)
    mcap = truncated / 'broken.mcap'
    mcap.write_bytes(mcap.read_bytes()[:200])
    for argv in (['bag', 'info', str(truncated)], ['bag', 'play', str(truncated)],
                 ['bag', 'info', str(tmp_path / 'nothing')]):
        proc = subprocess.run(MV3DPOSE + argv, capture_output=True, text=True, timeout=60)
        assert proc.returncode == 1, proc.stderr
        assert proc.stderr.startswith('error: ') and str(tmp_path) in proc.stderr
        assert 'Traceback' not in proc.stderr


def test_qos_conversion_round_trip():
    from rclpy.qos import qos_profile_sensor_data
    qos = qos_from_rclpy(qos_profile_sensor_data)
    assert qos.reliability == QosReliability.BEST_EFFORT
    assert qos.durability == QosDurability.VOLATILE
    back = qos_to_rclpy([qos])
    assert back.reliability == qos_profile_sensor_data.reliability
    assert back.depth == qos_profile_sensor_data.depth
    # no recorded profile: rosbag2's default, reliable keep-last 10
    assert qos_to_rclpy([]).depth == 10


# ------------------------------------------------------------------------------ DDS

def _wait_subscribed(node, pubs, timeout=20.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if all(p.get_subscription_count() > 0 for p in pubs):
            return True
        time.sleep(0.05)
    return False


@pytest.mark.ros
@pytest.mark.timeout(120)
@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_record_reads_back_identically(ros_context, tmp_path, storage):
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    from rclpy.qos import qos_profile_sensor_data
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import Image

    out = tmp_path / 'rec'
    count = 5
    recorder = subprocess.Popen(
        MV3DPOSE + ['bag', 'record', '/t/persons', '/t/tracks', '/t/image', '-o', str(out),
                    '--storage', storage, '--count', str(3 * count), '--duration', '60', '-q'],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        node = Node('bag_test_publisher', context=ros_context)
        reliable = QoSProfile(depth=50, history=HistoryPolicy.KEEP_LAST,
                              reliability=ReliabilityPolicy.RELIABLE,
                              durability=DurabilityPolicy.VOLATILE)
        persons = [sample_message('person2d', i) for i in range(count)]
        tracks = [sample_message('tracks', i) for i in range(count)]
        images = []
        for i in range(count):
            img = Image(height=4, width=6, encoding='bgr8', step=18, is_bigendian=0)
            img.header.frame_id = 'cam'
            img.header.stamp.sec = i
            img.data = bytes((i * 7 + k) % 256 for k in range(72))
            images.append(img)
        pubs = {'/t/persons': node.create_publisher(type(persons[0]), '/t/persons', reliable),
                '/t/tracks': node.create_publisher(type(tracks[0]), '/t/tracks', reliable),
                '/t/image': node.create_publisher(Image, '/t/image', qos_profile_sensor_data)}
        executor = SingleThreadedExecutor(context=ros_context)
        executor.add_node(node)
        assert _wait_subscribed(node, pubs.values()), 'recorder never subscribed'
        time.sleep(0.5)  # best-effort image: let the reader match fully before sending
        for i in range(count):
            pubs['/t/persons'].publish(persons[i])
            pubs['/t/tracks'].publish(tracks[i])
            pubs['/t/image'].publish(images[i])
            time.sleep(0.02)
        stdout, stderr = recorder.communicate(timeout=60)
        assert recorder.returncode == 0, stderr
        node.destroy_node()
    finally:
        if recorder.poll() is None:
            recorder.kill()
    with BagReader(out) as reader:
        assert reader.storage == storage
        topics = reader.topics()
        assert topics['/t/image'].qos[0].reliability == QosReliability.BEST_EFFORT
        assert topics['/t/tracks'].qos[0].reliability == QosReliability.RELIABLE
        got = {}
        for m in reader.messages():
            got.setdefault(m.topic, []).append(m)
        decoded = {t: [msg for _, _, msg in reader.decoded([t])] for t in got}
    for topic, sent in (('/t/persons', persons), ('/t/tracks', tracks), ('/t/image', images)):
        cls = type(sent[0])
        back = [message_to_dict(deserialize_message(m.data, cls)) for m in got[topic]]
        assert back == [message_to_dict(s) for s in sent], topic
    # the rosbags typestore (Jazzy + our .msg files) decodes the same fields
    for msg, sent in zip(decoded['/t/tracks'], tracks):
        assert [s.track_id for s in msg.skeletons] == [s.track_id for s in sent.skeletons]
        assert [[j.position.x for j in s.joints] for s in msg.skeletons] == \
            [[j.position.x for j in s.joints] for s in sent.skeletons]
    for msg, sent in zip(decoded['/t/image'], images):
        assert bytes(msg.data) == bytes(sent.data)


@pytest.mark.ros
@pytest.mark.timeout(120)
def test_play_rate_2_delivers_everything_in_order_with_clock(ros_context, tmp_path):
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.parameter import Parameter
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    from rosgraph_msgs.msg import Clock
    from std_msgs.msg import String
    from mv3dpose_msgs.msg import Person2DArray

    n = 20
    stamps = _write_bag(tmp_path / 'bag', n=n, step_ns=50_000_000)
    node = Node('bag_test_listener', context=ros_context,
                parameter_overrides=[Parameter('use_sim_time', value=True)])
    qos = QoSProfile(depth=1000, history=HistoryPolicy.KEEP_LAST,
                     reliability=ReliabilityPolicy.RELIABLE)
    got = {'clock': [], 'persons': [], 'chatter': [], 'wall': []}
    node.create_subscription(Clock, '/clock', lambda m: got['clock'].append(
        m.clock.sec * 10 ** 9 + m.clock.nanosec), qos)
    node.create_subscription(Person2DArray, '/cam0/persons_2d', lambda m: (
        got['persons'].append(m), got['wall'].append(time.monotonic())), qos)
    node.create_subscription(String, '/chatter', lambda m: (
        got['chatter'].append(m.data), got['wall'].append(time.monotonic())), qos)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    player = subprocess.Popen(
        MV3DPOSE + ['bag', 'play', str(tmp_path / 'bag'), '--rate', '2',
                    '--wait-for-subscribers', '20', '-q'],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        ok = spin_until(executor, lambda: len(got['clock']) >= 2 * n
                        and len(got['persons']) >= n and len(got['chatter']) >= n,
                        timeout=60)
        stdout, stderr = player.communicate(timeout=30)
    finally:
        if player.poll() is None:
            player.kill()
    assert ok, f'received {[(k, len(v)) for k, v in got.items()]}; player: {stderr}'
    assert player.returncode == 0, stderr
    assert got['clock'] == stamps, 'clock must carry every recorded stamp, in order'
    assert got['chatter'] == [f'hello {i}' for i in range(n)]
    assert [m.header.stamp.sec for m in got['persons']] == list(range(n))
    assert [len(m.persons) for m in got['persons']] == [i % 3 for i in range(n)]
    # a use_sim_time node follows the bag's clock
    assert node.get_clock().now().nanoseconds == stamps[-1]
    # pacing: the bag spans (2n - 1) * 50 ms; at rate 2 playback cannot be faster than half
    span = (stamps[-1] - stamps[0]) * 1e-9
    assert max(got['wall']) - min(got['wall']) >= 0.8 * span / 2
    node.destroy_node()


@pytest.mark.ros
@pytest.mark.timeout(120)
def test_play_topic_filter_and_start_offset(ros_context, tmp_path):
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    from std_msgs.msg import String
    from mv3dpose_msgs.msg import Person2DArray

    n = 10
    stamps = _write_bag(tmp_path / 'bag', n=n, step_ns=10_000_000)
    node = Node('bag_test_filter', context=ros_context)
    qos = QoSProfile(depth=1000, history=HistoryPolicy.KEEP_LAST,
                     reliability=ReliabilityPolicy.RELIABLE)
    chatter, persons = [], []
    node.create_subscription(String, '/chatter', lambda m: chatter.append(m.data), qos)
    node.create_subscription(Person2DArray, '/cam0/persons_2d', persons.append, qos)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    # skip the first 5 chatter messages: they lie before t0 + 0.1 s (stamps at 20 ms steps)
    offset = (stamps[10] - stamps[0]) * 1e-9
    player = subprocess.Popen(
        MV3DPOSE + ['bag', 'play', str(tmp_path / 'bag'), '--topics', '/chatter', '--rate', '0',
                    '--start-offset', f'{offset:.3f}', '--wait-for-subscribers', '20', '-q'],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        spin_until(executor, lambda: len(chatter) >= 5, timeout=60)
        _, stderr = player.communicate(timeout=30)
        spin_until(executor, lambda: False, timeout=0.3)  # nothing more may arrive
    finally:
        if player.poll() is None:
            player.kill()
    assert player.returncode == 0, stderr
    assert chatter == [f'hello {i}' for i in range(5, n)]
    assert persons == []
    node.destroy_node()


@pytest.mark.ros
@pytest.mark.timeout(120)
def test_pace_on_waits_for_a_slow_node(ros_context, tmp_path):
    """A node that keeps only the newest message still sees every one with --pace-on."""
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    from std_msgs.msg import String

    n = 12
    _write_bag(tmp_path / 'bag', n=n, step_ns=1_000_000)
    node = Node('bag_test_slow', context=ros_context)
    newest_only = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST,
                             reliability=ReliabilityPolicy.RELIABLE)
    ack = node.create_publisher(String, '/ack', 10)
    seen = []

    def slow(msg):
        time.sleep(0.1)   # busy: messages arriving meanwhile replace each other
        seen.append(msg.data)
        ack.publish(String(data=msg.data))
    node.create_subscription(String, '/chatter', slow, newest_only)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    player = subprocess.Popen(
        MV3DPOSE + ['bag', 'play', str(tmp_path / 'bag'), '--topics', '/chatter', '--rate', '0',
                    '--pace-on', '/ack', '--pace-timeout', '20', '--wait-for-subscribers', '20',
                    '-q'], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        spin_until(executor, lambda: len(seen) >= n or player.poll() is not None, timeout=60)
        _, stderr = player.communicate(timeout=30)
    finally:
        if player.poll() is None:
            player.kill()
    assert player.returncode == 0, stderr
    assert seen == [f'hello {i}' for i in range(n)]
    assert 'pace:' not in stderr
    node.destroy_node()


@pytest.mark.ros
@pytest.mark.timeout(120)
def test_ctrl_c_stops_record_and_loop_play_cleanly(tmp_path):
    """SIGINT ends a looping player and a recorder; the recorded bag is complete and valid."""
    import signal
    _write_bag(tmp_path / 'bag', n=5, step_ns=20_000_000)
    out = tmp_path / 'rec'
    recorder = subprocess.Popen(MV3DPOSE + ['bag', 'record', '/chatter', '-o', str(out), '-q'],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    player = None
    try:
        # the recorder subscribes once it sees the player's publisher (to learn its QoS)
        player = subprocess.Popen(
            MV3DPOSE + ['bag', 'play', str(tmp_path / 'bag'), '--loop', '--topics', '/chatter',
                        '--wait-for-subscribers', '20', '-q'],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        # both processes run once the recorder's first checkpoint holds messages (a fixed
        # sleep sent SIGINT during their imports on a loaded machine)
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not any(
                p.stat().st_size > 1000 for p in tmp_path.glob('.rec.partial-*/rec/*.mcap')):
            time.sleep(0.1)
        time.sleep(1.0)   # several loops of the 0.18 s bag
        assert player.poll() is None, 'a looping player must keep playing'
        player.send_signal(signal.SIGINT)
        _, perr = player.communicate(timeout=20)
        time.sleep(0.5)
        recorder.send_signal(signal.SIGINT)
        rout, rerr = recorder.communicate(timeout=20)
    finally:
        for proc in (player, recorder):
            if proc is not None and proc.poll() is None:
                proc.kill()
    assert player.returncode == 0, perr
    assert recorder.returncode == 0, rerr
    with BagReader(out) as reader:
        data = [m.data for _, _, m in reader.decoded()]
    assert len(data) > 10, 'the loop should have played the 5 messages several times'
    assert data[:5] == [f'hello {i}' for i in range(5)]
    assert data[5:10] == data[:5], 'second loop differs'
    assert sorted(os.listdir(tmp_path)) == ['bag', 'rec']
