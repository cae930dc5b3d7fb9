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

"""Image messages -> numpy: the encodings camera drivers publish, and CompressedImage."""

import math
import os

import cv2
from mv3dpose_ros.ros.images import (bgr_to_image, compressed_to_numpy, image_to_numpy, ImageError,
                                     numpy_to_compressed, numpy_to_image, parse_compressed_cdr,
                                     parse_image_cdr)
from mv3dpose_ros.ros.messages import message_to_dict
import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import CompressedImage, Image
from std_msgs.msg import Header


@pytest.fixture(scope='module')
def frame(shared_data):
    """Return a real 1920x1080 Panoptic frame, cropped to keep the tests quick."""
    img = cv2.imread(os.path.join(shared_data, 'panoptic_demo', '00_03', '00_03_00004500.jpg'))
    return np.ascontiguousarray(img[300:540, 800:1120])      # 320 x 240, people in it


def _image(array, encoding, bigendian=0, pad=0):
    h, w = array.shape[:2]
    rows = array.reshape(h, -1).view(np.uint8)
    step = rows.shape[1] + pad
    data = np.zeros((h, step), np.uint8)
    data[:, :rows.shape[1]] = rows
    return Image(height=h, width=w, encoding=encoding, is_bigendian=bigendian, step=step,
                 data=data.tobytes())


@pytest.mark.parametrize('encoding', ['bgra8', 'rgba8', '8UC4'])
def test_four_channel_encodings_drop_alpha(frame, encoding):
    rgb = encoding == 'rgba8'
    four = cv2.cvtColor(frame, cv2.COLOR_BGR2RGBA if rgb else cv2.COLOR_BGR2BGRA)
    four[..., 3] = 7
    arr, order = image_to_numpy(_image(four, encoding, pad=8))
    assert order == ('rgb' if rgb else 'bgr') and arr.shape == frame.shape
    assert arr.flags['C_CONTIGUOUS']
    assert np.array_equal(arr[..., ::-1] if rgb else arr, frame)


@pytest.mark.parametrize('bits, bigendian', [(16, 0), (12, 0), (10, 1)])
def test_mono16_scaled_by_its_bit_depth(frame, bits, bigendian):
    gray = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
    wide = (gray.astype(np.uint16) << (bits - 8)).astype('>u2' if bigendian else '<u2')
    arr, order = image_to_numpy(_image(wide, 'mono16', bigendian))
    assert order == 'gray' and arr.dtype == np.uint8 and np.array_equal(arr, gray)


@pytest.mark.parametrize('encoding', ['yuv422', 'yuv422_yuy2'])
def test_yuv422_decodes_to_bgr(frame, encoding):
    packed = np.frombuffer(bgr_to_image(frame, encoding).data, np.uint8).reshape(
        frame.shape[0], frame.shape[1], 2)
    arr, order = image_to_numpy(_image(packed, encoding, pad=4))
    assert order == 'bgr' and arr.shape == frame.shape
    err = np.abs(arr.astype(int) - frame.astype(int))
    assert np.median(err) <= 3 and err.mean() < 6           # chroma subsampling only
    swapped = image_to_numpy(_image(packed, 'yuv422' if encoding != 'yuv422' else 'yuyv'))[0]
    assert np.abs(swapped.astype(int) - frame.astype(int)).mean() > 20   # layout matters


@pytest.mark.parametrize('encoding', ['bgr8', 'rgb8', 'mono8', 'bgra8', 'rgba8', 'mono16',
                                      'yuv422', 'yuv422_yuy2'])
def test_every_driver_encoding_roundtrips_through_dds_bytes(frame, encoding):
    msg = bgr_to_image(frame, encoding)
    assert msg.encoding == encoding and msg.width == frame.shape[1]
    parsed, data = parse_image_cdr(serialize_message(msg))
    arr, order = image_to_numpy(parsed, data)
    ref = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY) if order == 'gray' else frame
    arr = arr[..., ::-1] if order == 'rgb' else arr
    assert arr.shape == ref.shape
    assert np.abs(arr.astype(int) - ref.astype(int)).mean() < (6 if 'yuv' in encoding else 0.01)


def test_unsupported_and_inconsistent_images_are_named():
    msg = Image(height=2, width=3, encoding='bayer_rggb8', step=3, data=bytes(6))
    with pytest.raises(ImageError, match="unsupported image encoding 'bayer_rggb8'.*yuv422"):
        image_to_numpy(msg)
    msg = Image(height=2, width=3, encoding='yuv422', step=6, data=bytes(12))
    with pytest.raises(ImageError, match='even width'):
        image_to_numpy(msg)
    msg = Image(height=2, width=4, encoding='mono16', step=7, data=bytes(16))
    with pytest.raises(ImageError, match='step 7 < width 4 x 2 bytes'):
        image_to_numpy(msg)


def test_raw_cdr_of_new_encodings(frame):
    four = cv2.cvtColor(frame, cv2.COLOR_BGR2BGRA)
    msg = _image(four, 'bgra8')
    msg.header = Header(frame_id='cam0_optical_frame')
    msg.header.stamp.sec, msg.header.stamp.nanosec = 12, 34
    parsed, data = parse_image_cdr(serialize_message(msg))
    assert parsed.encoding == 'bgra8' and parsed.header.stamp.nanosec == 34
    assert np.array_equal(image_to_numpy(parsed, data)[0], frame)


@pytest.mark.parametrize('fmt', ['jpeg', 'png'])
def test_compressed_roundtrip_as_image_transport_writes_it(frame, fmt):
    header = Header(frame_id='cam0_optical_frame')
    header.stamp.sec, header.stamp.nanosec = 1000, 5
    msg = numpy_to_compressed(frame, header, fmt)
    assert msg.format == f'bgr8; {fmt} compressed bgr8'
    parsed, data = parse_compressed_cdr(serialize_message(msg))
    assert parsed.format == msg.format and parsed.header.stamp.sec == 1000
    assert parsed.header.frame_id == 'cam0_optical_frame'
    arr, order = compressed_to_numpy(parsed, data)
    assert order == 'bgr' and arr.shape == frame.shape
    err = np.abs(arr.astype(int) - frame.astype(int))
    assert err.max() == 0 if fmt == 'png' else err.mean() < 4
    gray = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
    arr, order = compressed_to_numpy(numpy_to_compressed(gray, header, fmt))
    assert order == 'gray' and arr.shape == gray.shape


def test_compressed_from_other_publishers_and_bad_bytes(frame):
    ok, jpg = cv2.imencode('.jpg', frame)
    # older publishers write just 'jpeg'; an 'rgb8' source is still compressed as bgr8
    for fmt in ('jpeg', 'rgb8; jpeg compressed bgr8'):
        arr, order = compressed_to_numpy(CompressedImage(format=fmt, data=jpg.tobytes()))
        assert order == 'bgr' and arr.shape == frame.shape
    with pytest.raises(ImageError, match='cannot decode CompressedImage'):
        compressed_to_numpy(CompressedImage(format='jpeg', data=jpg.tobytes()[:200]))
    with pytest.raises(ImageError, match='depth image'):
        compressed_to_numpy(CompressedImage(format='16UC1; compressedDepth png', data=b'x'))
    with pytest.raises(ImageError, match='empty CompressedImage'):
        compressed_to_numpy(CompressedImage(format='jpeg'))
    wire = serialize_message(CompressedImage(format='jpeg', data=jpg.tobytes()))
    with pytest.raises(ImageError, match='declares'):
        parse_compressed_cdr(wire[:-10])
    with pytest.raises(ImageError, match='not a plain CDR'):
        parse_compressed_cdr(b'\x00\x07' + wire[2:])


@pytest.mark.parametrize('compressed', [False, True])
def test_raw_cdr_reads_exactly_what_rclpy_reads(compressed):
    """On truncated and mutated bytes the in-place parser and rclpy agree (strings too)."""
    rng = np.random.default_rng(4)
    array = rng.integers(0, 255, (6, 8, 3), dtype=np.uint8)
    header = Header(frame_id='cam_é')
    msg = numpy_to_compressed(array, header) if compressed else numpy_to_image(array, header)
    kind, parse = (CompressedImage, parse_compressed_cdr) if compressed else (Image,
                                                                              parse_image_cdr)
    wire = serialize_message(msg)
    cases = [wire[:cut] for cut in range(len(wire))]
    for _ in range(400):
        b = bytearray(wire)
        b[int(rng.integers(0, 64))] = int(rng.integers(0, 256))   # header, strings, sizes
        cases.append(bytes(b))
    read = 0
    for data in cases:
        try:
            want = deserialize_message(data, kind)
        except Exception:  # noqa: B902 - rclpy raises RMWError and friends
            want = None
        try:
            got, view = parse(data)
        except ImageError:
            assert want is None, f'rclpy reads what the parser refuses: {data.hex()}'
            continue
        assert want is not None, f'the parser reads what rclpy refuses: {data.hex()}'
        assert bytes(view) == bytes(want.data)
        want.data = []
        assert message_to_dict(got) == message_to_dict(want)
        read += 1
    assert 50 < read < len(cases) - 50         # both kinds in the corpus


def test_image_roundtrip_still_zero_copy(frame):
    msg = numpy_to_image(frame)
    parsed, data = parse_image_cdr(serialize_message(msg))
    arr, _ = image_to_numpy(parsed, data)
    assert np.array_equal(arr, frame) and not arr.flags['OWNDATA']


def _run_publisher(args, topic, msg_type, count, ros_context, timeout=90.0):
    """Start mv3dpose_image_publisher, collect ``count`` messages of ``topic``, stop it."""
    import subprocess
    import sys
    import time

    from mv3dpose_ros.testing.processes import interrupt
    from mv3dpose_ros.testing.spin import spin_until
    from mv3dpose_ros.ros.qos import sensor_qos
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from sensor_msgs.msg import CameraInfo

    node = rclpy.create_node('image_probe', context=ros_context)
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(node)
    got, infos = [], []
    node.create_subscription(msg_type, topic, lambda m: got.append((time.time_ns(), m)),
                             sensor_qos('best_effort', 50))
    node.create_subscription(CameraInfo, topic.rsplit('/', 2)[0] + '/camera_info'
                             if topic.endswith('/compressed') else
                             topic.rsplit('/', 1)[0] + '/camera_info', infos.append,
                             sensor_qos('best_effort', 50))
    proc = subprocess.Popen([sys.executable, '-m', 'mv3dpose_ros.nodes.image_publisher',
                             *args, '--wait-for-subscribers', '1'],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        spin_until(ex, lambda: len(got) >= count, timeout)
    finally:
        interrupt(proc, 20)
        out = proc.stdout.read()
        ex.shutdown()
        node.destroy_node()
    assert len(got) >= count, out
    return got, infos, out


@pytest.mark.ros
def test_image_publisher_publishes_like_a_driver(shared_data, ros_context):
    folder = os.path.join(shared_data, 'panoptic_demo', '00_03')
    calib = os.path.join(shared_data, 'panoptic_demo', 'camera_parameters.json')
    got, infos, out = _run_publisher([folder, '--camera', '00_03', '--rate', '10', '--loop',
                                      '--calibration', calib], '/cam00_03/image_raw', Image, 12,
                                     ros_context)
    stamps = [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for _, m in got]
    assert all(s % 100_000_000 == 0 for s in stamps), stamps        # grid capture instants
    assert all(b > a for a, b in zip(stamps, stamps[1:]))
    assert all(arrival >= s for (arrival, _), s in zip(got, stamps))  # stamped at capture
    assert got[0][1].header.frame_id == 'cam00_03_optical_frame'
    # frame (stamp / period) mod 5 at each instant: every publisher of a rig shows the same
    # moment whenever it started; one loop later the same bytes (cached), new stamp
    first = {s: bytes(m.data) for s, (_, m) in zip(stamps, got)}
    frames = sorted(os.listdir(folder))
    for s in stamps[:5]:
        want = cv2.imread(os.path.join(folder, frames[(s // 100_000_000) % 5]))
        assert np.array_equal(np.frombuffer(first[s], np.uint8).reshape(want.shape), want)
        if s + 500_000_000 in first:
            assert first[s] == first[s + 500_000_000]
    arr, order = image_to_numpy(got[0][1])
    assert arr.shape == (1080, 1920, 3) and order == 'bgr'
    info_stamps = {i.header.stamp.sec * 10**9 + i.header.stamp.nanosec for i in infos}
    assert set(stamps[:5]) <= info_stamps and infos[0].width == 1920


@pytest.mark.ros
def test_image_publisher_loops_a_video_on_the_instants(tmp_path, ros_context):
    """A looping video shows frame (instant / period) mod N, like a folder: rig-wide in step."""
    video, n = str(tmp_path / 'cam.avi'), 13
    writer = cv2.VideoWriter(video, cv2.VideoWriter_fourcc(*'MJPG'), 10, (64, 48))
    for k in range(n):
        writer.write(np.full((48, 64, 3), 15 * k, np.uint8))
    writer.release()
    got, _, out = _run_publisher([video, '--camera', 'v0', '--rate', '20', '--loop'],
                                 '/v0/image_raw', Image, 30, ros_context)
    for _, msg in got:
        stamp = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
        arr, _ = image_to_numpy(msg)
        assert round(arr.mean() / 15) == (stamp // 50_000_000) % n, out


def _write_video(path, n, step):
    writer = cv2.VideoWriter(path, cv2.VideoWriter_fourcc(*'MJPG'), 10, (64, 48))
    for k in range(n):
        writer.write(np.full((48, 64, 3), step * k, np.uint8))
    writer.release()


def _bounced(slot, n):
    """Frame of ``slot`` bouncing over ``n`` frames, written out the long way."""
    order = list(range(n)) + list(range(n - 2, 0, -1))
    return order[slot % len(order)]


def _played(ros_context, source, step, params, clock=None, stats=None):
    """
    Run an ImagePublisher in this process; return (stamp ns, frame shown) per message.

    ``clock`` replaces the node clock (its ``now()`` readings); ``stats`` gets the publisher's
    ``count`` and ``skipped``.
    """
    from mv3dpose_ros.nodes.image_publisher import ImagePublisher
    from rclpy.parameter import Parameter
    from rclpy.serialization import deserialize_message
    pub = ImagePublisher(context=ros_context, namespace='/bounce', parameter_overrides=[
        Parameter('source', value=source)] + [Parameter(k, value=v) for k, v in params.items()])
    sent = []
    pub.image_pub.publish = sent.append
    if clock is not None:
        pub.get_clock = lambda: clock
    try:
        pub.run()
        if stats is not None:
            stats.update(count=pub.count, skipped=pub.skipped)
    finally:
        pub.destroy_node()
    shown = []
    for msg in sent:                # looping: serialised bytes (cached ones with a new stamp)
        msg = deserialize_message(msg, Image) if isinstance(msg, bytes) else msg
        arr, _ = image_to_numpy(msg)
        shown.append((msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec,
                      round(arr.mean() / step)))
    return shown


class _LateClock:
    """A node clock whose ``now()`` reads the given instants [ns], one per call."""

    def __init__(self, *instants):
        self.instants = iter(instants)

    def now(self):
        from rclpy.time import Time
        return Time(nanoseconds=next(self.instants))


@pytest.mark.ros
def test_image_publisher_behind_steps_over_the_frames_of_skipped_instants(tmp_path,
                                                                          ros_context):
    """Read in order (no loop), a publisher that fell behind keeps its frames on time."""
    video, period = str(tmp_path / 'cam.avi'), 100_000_000     # 10 Hz
    _write_video(video, 6, 30)
    stats = {}
    # start at 0 (first instant: 1 period), on time, 3 instants late, then 5 instants late
    shown = _played(ros_context, video, 30, {}, stats=stats,
                    clock=_LateClock(0, period, 5 * period, 11 * period))
    # frame 0 on time; 3 instants skipped: frames 1-3 too, frame 4 at its instant; 5 skipped:
    # past the end, no loop: the end
    assert shown == [(period, 0), (5 * period, 4)]
    assert stats == {'count': 2, 'skipped': 8}


@pytest.mark.ros
def test_image_publisher_bounces_a_folder_forward_then_backward(tmp_path, ros_context):
    """--bounce: 0, 1, .., N-1, N-2, .., 1, 0, 1, ..: no jump at the wrap; stamps increase."""
    for k in range(4):
        cv2.imwrite(str(tmp_path / f'{k:02d}.png'), np.full((48, 64, 3), 40 * k, np.uint8))
    # from frame 0 with reproducible stamps (as with --trigger free)
    shown = _played(ros_context, str(tmp_path), 40, {
        'bounce': True, 'rate_hz': 100.0, 'start_stamp': 100.0, 'max_frames': 15})
    assert [f for _, f in shown] == [0, 1, 2, 3, 2, 1, 0, 1, 2, 3, 2, 1, 0, 1, 2]
    stamps = [s for s, _ in shown]
    assert stamps == [100 * 10**9 + k * 10**7 for k in range(15)]


@pytest.mark.ros
def test_image_publisher_bounces_a_video_on_the_instants(tmp_path, ros_context):
    """On the grid, instant i shows frame i mod (2N - 2) reflected: every publisher in step."""
    video, n = str(tmp_path / 'cam.avi'), 5
    _write_video(video, n, 30)
    shown = _played(ros_context, video, 30, {'bounce': True, 'rate_hz': 100.0,
                                             'max_frames': 3 * (2 * n - 2)})
    period = 10**7
    stamps = [s for s, _ in shown]
    assert all(b > a for a, b in zip(stamps, stamps[1:])) and stamps[0] % period == 0
    assert [f for _, f in shown] == [_bounced(s // period, n) for s in stamps]
    # one step at a time at consecutive instants: never a jump from the last frame to the first
    steps = [abs(fb - fa) for (sa, fa), (sb, fb) in zip(shown, shown[1:]) if sb - sa == period]
    assert steps and set(steps) == {1}
    assert {f for _, f in shown} == set(range(n))


def test_image_publisher_bounce_option_and_frame_order():
    from mv3dpose_ros.nodes.image_publisher import ImagePublisher, parse_cli
    params = {p.name: p.value for p in parse_cli(['clip.mp4', '--bounce', '--rate', '10'])}
    assert params == {'source': 'clip.mp4', 'bounce': True, 'rate_hz': 10.0}

    class _Source:
        length = 0

    pub = ImagePublisher.__new__(ImagePublisher)          # frame_of needs no node
    pub.source, pub.bounce = _Source(), True
    for n in (1, 2, 3, 7):
        _Source.length = n
        assert [pub.frame_of(i) for i in range(40)] == (
            [0] * 40 if n == 1 else [_bounced(i, n) for i in range(40)])
    pub.bounce = False
    assert [pub.frame_of(i) for i in range(9)] == [i % 7 for i in range(9)]


def test_frame_source_plays_a_video_backward_without_a_seek_per_frame(tmp_path, monkeypatch):
    """Bouncing, frames decoded lately are kept (bounded); a frame before them: one seek."""
    from mv3dpose_ros.io.media import FrameSource, VideoReader
    video, n = str(tmp_path / 'clip.avi'), 40
    _write_video(video, n, 6)
    frame_bytes = 48 * 64 * 3
    seeks, seek = [], VideoReader.seek

    def counted_seek(reader, index):   # counts the seeks of the video
        seeks.append(index)
        seek(reader, index)

    monkeypatch.setattr(VideoReader, 'seek', counted_seek)
    src = FrameSource(video, back_bytes=8 * frame_bytes)
    order = list(range(n)) + list(range(n - 2, -1, -1)) + list(range(1, n))
    for k in order:
        assert round(src.frame_at(k).mean() / 6) == k
        assert src.back_bytes_used <= 8 * frame_bytes and len(src.back_frames) <= 8
    # forward: no seek; back from 38: 32-38 kept, then one seek per 8 frames (24-31, .., 0-7);
    # forward again from 0-7 kept, then on from the decoder's position: no seek
    assert len(seeks) == math.ceil((n - 8) / 8), seeks
    src.forget(n - 1)
    src.forget(n - 1)                                   # not kept: nothing to drop
    assert (n - 1) not in src.back_frames
    assert src.back_bytes_used == len(src.back_frames) * frame_bytes
    # without the buffer (not bouncing), every frame back is a seek
    plain = FrameSource(video)
    seeks.clear()
    for k in range(n - 1, -1, -1):
        assert round(plain.frame_at(k).mean() / 6) == k
    assert len(seeks) == n - 1 and not plain.back_frames     # 39 by stepping, then 38 .. 0


def test_image_publisher_ends_quietly_when_ctrl_c_races_a_publish(tmp_path, capfd):
    """Ctrl-C shuts the context down while the thread publishes: the end, with the count."""
    import rclpy
    from mv3dpose_ros.nodes.image_publisher import ImagePublisher
    from rclpy.parameter import Parameter
    for k in range(3):
        cv2.imwrite(str(tmp_path / f'{k}.png'), np.full((48, 64, 3), 40 * k, np.uint8))
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    pub = ImagePublisher(context=ctx, namespace='/race', parameter_overrides=[
        Parameter('source', value=str(tmp_path)), Parameter('rate_hz', value=50.0),
        Parameter('loop', value=True)])
    publish = pub.image_pub.publish
    calls = []

    def publish_then_interrupted(msg):
        calls.append(msg)
        if len(calls) < 3:
            return publish(msg)
        rclpy.shutdown(context=ctx)             # as rclpy's SIGINT handler does
        return publish(msg)                     # raises: the publisher's context is invalid

    pub.image_pub.publish = publish_then_interrupted
    try:
        pub.run()                               # returns instead of raising
        assert len(calls) == 3 and pub.count == 2 and pub.done.is_set()
        assert '[image_publisher] published 2 frames' in capfd.readouterr().err
    finally:
        pub.destroy_node()
        rclpy.try_shutdown(context=ctx)


@pytest.mark.ros
def test_image_publisher_compressed(shared_data, ros_context):
    folder = os.path.join(shared_data, 'panoptic_demo', '00_06')
    got, _, _ = _run_publisher([folder, '--camera', '00_06', '--rate', '10', '--loop',
                                '--compressed', 'jpeg', '--encoding', 'mono8', '--trigger',
                                'free'], '/cam00_06/image_raw/compressed', CompressedImage, 7,
                               ros_context)
    for _, msg in got:
        arr, order = compressed_to_numpy(msg)
        assert msg.format == 'mono8; jpeg compressed mono8'
        assert order == 'gray' and arr.shape == (1080, 1920)


def test_image_publisher_bad_input_exits_2(tmp_path):
    import subprocess
    import sys
    res = subprocess.run([sys.executable, '-m', 'mv3dpose_ros.nodes.image_publisher',
                          str(tmp_path / 'none'), '--camera', 'c'], capture_output=True,
                         text=True, timeout=60)
    assert res.returncode == 2 and 'source not found' in res.stderr
    (tmp_path / 'empty').mkdir()
    res = subprocess.run([sys.executable, '-m', 'mv3dpose_ros.nodes.image_publisher',
                          str(tmp_path / 'empty'), '--trigger', 'free', '--rate', '-1'],
                         capture_output=True, text=True, timeout=60)
    assert res.returncode == 2 and 'rate_hz must be > 0' in res.stderr
