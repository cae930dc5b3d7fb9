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
image_publisher -> pose2d_node -> Person2DArray over real DDS.

The crafted-ONNX tests always run (the "network" returns fixed people, so the expected
keypoints follow from the letterbox alone); the real-model test needs
``mv3dpose model fetch`` and the Panoptic frames, and skips with the reason otherwise.
Every wait is bounded; nothing asserts on speed.
"""

import os
import subprocess
import sys
import threading
import time

import cv2
from diagnostic_msgs.msg import DiagnosticArray
from mv3dpose_msgs.msg import Person2DArray, SkeletonInfo, SkippedImages
from mv3dpose_ros.pose2d import models
from mv3dpose_ros.pose2d.models import ModelNotFound, resolve_model_path
from mv3dpose_ros.pose2d.ops import Letterbox
from mv3dpose_ros.ros.images import numpy_to_image
from mv3dpose_ros.ros.messages import ns_to_stamp, stamp_to_ns
from mv3dpose_ros.ros.qos import latched_qos, reliable_qos
from mv3dpose_ros.testing.spin import spin_until
import numpy as np
from onnx_min import make_constant_model
import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import Header

pytestmark = [pytest.mark.ros]

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
W, H = 320, 240
NS = 1_000_000_000
REMAP = ['--ros-args', '-r', 'image:=image_raw']


def _crafted_model(tmp_path):
    """Write a YOLO-pose ONNX that always 'sees' two people; return path and expectations."""
    lb = Letterbox.fit((H, W), (640, 640))
    rng = np.random.default_rng(5)
    out = np.zeros((1, 56, 8400), np.float32)
    expected = []
    for col, (cx, cy), score in ((10, (100, 120), 0.9), (20, (230, 110), 0.6)):
        kpts = np.array([cx, cy]) + rng.uniform(-30, 30, size=(17, 2))
        conf = rng.uniform(0.4, 1.0, 17)
        x0, y0 = lb.to_input(kpts.min(0) - 5)
        x1, y1 = lb.to_input(kpts.max(0) + 5)
        k_in = lb.to_input(kpts)
        out[0, :5, col] = [(x0 + x1) / 2, (y0 + y1) / 2, x1 - x0, y1 - y0, score]
        out[0, 5:, col] = np.concatenate([k_in, conf[:, None]], 1).reshape(-1)
        expected.append((kpts, conf, score))
    path = tmp_path / 'crafted_pose.onnx'
    path.write_bytes(make_constant_model([('images', np.float32, [1, 3, 640, 640])],
                                         {'output0': out}, {'task': 'pose'}))
    return str(path), expected


def _image_folder(tmp_path, count=3):
    folder = tmp_path / 'frames'
    folder.mkdir()
    rng = np.random.default_rng(0)
    for i in range(count):
        cv2.imwrite(str(folder / f'frame_{i:03d}.png'),
                    rng.integers(0, 255, size=(H, W, 3), dtype=np.uint8))
    return str(folder)


class Probe:
    """Collect persons_2d, skeleton_info, diagnostics and debug images of one namespace."""

    def __init__(self, ctx, ns):
        self.node = rclpy.create_node('pose2d_probe', context=ctx)
        self.persons, self.infos, self.diags, self.debug = [], [], [], []
        self.node.create_subscription(Person2DArray, f'{ns}/persons_2d', self.persons.append,
                                      reliable_qos())
        self.node.create_subscription(DiagnosticArray, '/diagnostics', self.diags.append,
                                      reliable_qos())

    def watch_info(self, ns):
        self.node.create_subscription(SkeletonInfo, f'{ns}/skeleton_info', self.infos.append,
                                      latched_qos())

    def watch_debug(self, topic):
        self.node.create_subscription(Image, topic, self.debug.append, reliable_qos(1))


def test_crafted_model_end_to_end(ros_context, tmp_path):
    from mv3dpose_ros.nodes.image_publisher import ImagePublisher
    from mv3dpose_ros.nodes.pose2d.node import Pose2DNode
    model, expected = _crafted_model(tmp_path)
    folder = _image_folder(tmp_path, 3)
    start = int(time.time()) - 1
    # image_publisher publishes image_raw, as drivers do; pose2d reads 'image' (remapped)
    params = [
        Parameter('model.path', value=model), Parameter('model.threads', value=1),
        Parameter('image_qos.reliability', value='reliable'),
        Parameter('keypoint_threshold', value=0.5), Parameter('diagnostics_period_s', value=0.2)]
    node = Pose2DNode(context=ros_context, namespace='/camx', cli_args=REMAP,
                      parameter_overrides=params)
    assert node.active, node.error
    assert node.camera_id == 'camx'
    probe = Probe(ros_context, '/camx')
    pub = ImagePublisher(context=ros_context, namespace='/camx', parameter_overrides=[
        Parameter('source', value=folder), Parameter('rate_hz', value=20.0),
        Parameter('start_stamp', value=float(start)), Parameter('frame_id', value='camx_optical'),
        Parameter('reliability', value='reliable'), Parameter('wait_for_subscribers', value=1)])
    ex = SingleThreadedExecutor(context=ros_context)
    for n in (node, probe.node, pub):
        ex.add_node(n)
    threading.Thread(target=pub.run, name='publisher', daemon=True).start()
    try:
        assert spin_until(ex, lambda: pub.done.is_set() and len(probe.persons) + node.dropped
                          >= 3 and node.processed + node.dropped >= 3, timeout=30)
        spin_until(ex, lambda: len(probe.persons) >= node.processed, timeout=5)
        # Every image is either published or counted as dropped for a newer one.
        assert len(probe.persons) == node.processed and node.processed + node.dropped == 3
        stamps = {start * NS + k * NS // 20 for k in range(3)}
        for msg in probe.persons:
            assert stamp_to_ns(msg.header.stamp) in stamps
            assert msg.header.frame_id == 'camx_optical'
            assert (msg.camera_id, msg.image_width, msg.image_height, msg.layout) == (
                'camx', W, H, 'coco17')
            assert len(msg.persons) == 2
            for person, (kpts, conf, score) in zip(msg.persons, expected):
                got = np.array([[k.x, k.y, k.confidence] for k in person.keypoints])
                shown = conf >= 0.5
                np.testing.assert_allclose(got[shown, :2], kpts[shown], atol=0.05)
                np.testing.assert_allclose(got[:, 2], np.where(shown, conf, 0.0), atol=1e-6)
                assert person.score == pytest.approx(score, abs=1e-6)
                assert person.roi.width > 0 and person.roi.x_offset >= 0
        # The skeleton info is latched: a subscriber joining now still gets it.
        probe.watch_info('/camx')
        assert spin_until(ex, lambda: probe.infos, timeout=10)
        assert probe.infos[0].layout == 'coco17' and len(probe.infos[0].joint_names) == 17

        def latest():
            return next((s for d in reversed(probe.diags) for s in d.status
                         if 'camx inference' in s.name), None)

        # the first status may predate the last image: wait for one that counts it
        assert spin_until(ex, lambda: latest() is not None and int(
            {kv.key: kv.value for kv in latest().values}['Images processed'])
            == node.processed, timeout=10)
        status = latest()
        keys = {kv.key: kv.value for kv in status.values}
        assert status.hardware_id == 'camx'
        assert int(keys['Images processed']) == node.processed
        assert 'Inference latency median (ms)' in keys
        assert 'Dropped before inference (newer image arrived)' in keys
        assert keys['Execution provider'] == 'CPUExecutionProvider'
        assert keys['Inference rate mode'] == 'auto'            # the default
        assert keys['Inference rate (Hz)'] == 'every image'     # it keeps up here
        for stage in ('transport', 'wait', 'decode', 'pre', 'inference', 'post', 'publish'):
            assert float(keys[f'Stage {stage} median (ms)']) >= 0.0, stage

        # Direct calls of the node's path: encodings, zero stamps, a dynamic threshold.
        header = Header(stamp=ns_to_stamp((start + 5) * NS), frame_id='camx_optical')
        img = np.zeros((H, W, 3), np.uint8)
        for arr, enc in ((img, 'rgb8'), (img[..., 0], 'mono8'), (img, 'bgr8')):
            out = node.process(numpy_to_image(arr, header, enc))
            assert out is not None and len(out.persons) == 2 and out.header == header
        bad = numpy_to_image(img[..., 0], header, 'mono8')
        bad.encoding = '16UC1'
        assert node.process(bad) is None and node.rejected_encoding == 1
        assert node.process(numpy_to_image(img, Header(frame_id='x'), 'bgr8')) is None
        assert node.rejected_stamp == 1
        node.set_parameters([Parameter('score_threshold', value=0.95)])
        empty = node.process(numpy_to_image(img, header, 'bgr8'))
        assert empty is not None and empty.persons == [] and empty.header == header
        node.set_parameters([Parameter('score_threshold', value=0.7)])
        assert len(node.process(numpy_to_image(img, header, 'bgr8')).persons) == 1
        # The debug image is drawn only while someone subscribes.
        assert node._debug_pub.get_subscription_count() == 0
        probe.watch_debug('/camx/pose2d_node/debug_image')
        assert spin_until(ex, lambda: node._debug_pub.get_subscription_count() > 0, timeout=10)
        node.process(numpy_to_image(img, header, 'bgr8'))
        assert spin_until(ex, lambda: probe.debug, timeout=10)
        assert (probe.debug[0].encoding, probe.debug[0].width) == ('bgr8', W)
        assert probe.debug[0].header == header
    finally:
        for n in (pub, probe.node, node):
            ex.remove_node(n)
            n.destroy_node()


def _fake_cache(tmp_path, sizes, int8=()):
    """Return a model cache of crafted 'yolo11n-pose' files: fp32 ``sizes``, ``int8`` sizes."""
    import hashlib
    import json
    cache = tmp_path / 'cache'
    cache.mkdir()
    out = np.zeros((1, 56, 8400), np.float32)
    out[0, :5, 0] = [100, 100, 50, 80, 0.9]
    for hw, precision in [(s, 'fp32') for s in sizes] + [(s, 'int8') for s in int8]:
        data = make_constant_model([('images', np.float32, [1, 3, *hw])], {'output0': out},
                                   {'task': 'pose'})
        path = models.model_file('yolo11n-pose', hw, str(cache), precision)
        open(path, 'wb').write(data)
        open(models.sidecar_file(path), 'w').write(json.dumps(
            {'name': 'yolo11n-pose', 'family': 'yolo-pose', 'input_size': list(hw),
             'precision': precision, 'onnx_sha256': hashlib.sha256(data).hexdigest()}))
    return str(cache)


def test_precision_auto_runs_int8_on_the_cpu_and_fp32_on_a_gpu(ros_context, tmp_path,
                                                               monkeypatch):
    """model.precision auto (default): a size's int8 twin where fetched, on the CPU only."""
    from mv3dpose_ros.nodes.pose2d import node as pose2d_node
    from mv3dpose_ros.pose2d.estimator import CPU
    cache = _fake_cache(tmp_path, [(384, 640), (192, 320)], int8=[(288, 512), (192, 320)])
    node = pose2d_node.Pose2DNode(context=ros_context, namespace='/camprec', parameter_overrides=[
        Parameter('model.cache_dir', value=cache), Parameter('model.threads', value=1)])
    try:
        assert node.active, node.error
        assert node.get_parameter('model.precision').value == 'auto'
        assert node._fetched_sizes() == [(384, 640), (288, 512), (192, 320)]
        for size, precision in (((192, 320), 'int8'), ((288, 512), 'int8'),
                                ((384, 640), 'fp32')):
            path = node._registered_path(size)
            assert path == models.model_file('yolo11n-pose', size, cache, precision)
            assert node._open(path).precision == precision
        monkeypatch.setattr(pose2d_node, 'resolve_providers',
                            lambda request: (['CUDAExecutionProvider', CPU], []))
        assert node._fetched_sizes() == [(384, 640), (192, 320)]     # fp32 only on a GPU
        assert node._registered_path((192, 320)) == models.model_file(
            'yolo11n-pose', (192, 320), cache)
    finally:
        node.destroy_node()


@pytest.mark.parametrize('image_hw, sizes, chosen', [
    ((1080, 1920), [(640, 640), (384, 640), (640, 384)], (384, 640)),
    ((1920, 1088), [(640, 640), (384, 640), (640, 384)], (640, 384)),
    ((1080, 1920), [(640, 640)], (640, 640)),          # the better fit is not fetched: kept
    ((1080, 1920), [(640, 384)], (640, 384)),          # only a poor fit fetched: still runs
])
def test_input_size_auto_fits_the_first_image(ros_context, tmp_path, image_hw, sizes, chosen):
    """model.input_size auto: the first image picks the fetched size that fits its aspect."""
    from mv3dpose_ros.nodes.pose2d.node import Pose2DNode
    cache = _fake_cache(tmp_path, sizes)
    node = Pose2DNode(context=ros_context, namespace='/camfit', parameter_overrides=[
        Parameter('model.cache_dir', value=cache), Parameter('model.threads', value=1)])
    try:
        assert node.active, node.error
        assert node.get_parameter('model.input_size').value == 'auto'
        node.set_parameters([Parameter('score_threshold', value=0.5)])
        header = Header(stamp=ns_to_stamp(5 * NS), frame_id='f')
        out = node.process(numpy_to_image(np.zeros((*image_hw, 3), np.uint8), header, 'bgr8'))
        assert out is not None and len(out.persons) == 1
        assert tuple(node.estimator.input_size) == chosen
        assert node.estimator.score_threshold == 0.5          # dynamic values carried over
        assert node.estimator.path == models.model_file('yolo11n-pose', chosen, cache)
        before = node.estimator
        node.process(numpy_to_image(np.zeros((480, 480, 3), np.uint8), header, 'bgr8'))
        assert node.estimator is before                        # chosen once, at the first image
    finally:
        node.destroy_node()


def test_auto_mode_switches_the_model_along_the_ladder(ros_context, tmp_path):
    """Under load, inference_rate_hz auto moves the node to the next fetched smaller input."""
    from mv3dpose_ros.nodes.pose2d.node import Pose2DNode
    sizes = [(640, 640), (384, 640), (288, 512), (224, 384), (192, 320)]
    cache = _fake_cache(tmp_path, sizes)          # 192x320: not a registry size, still used
    node = Pose2DNode(context=ros_context, namespace='/camladder', parameter_overrides=[
        Parameter('model.cache_dir', value=cache), Parameter('model.threads', value=1),
        Parameter('model.min_input_side', value=320)])
    try:
        assert node.active, node.error
        node.set_parameters([Parameter('score_threshold', value=0.5)])
        image = np.zeros((1080, 1920, 3), np.uint8)
        t = 0

        def frame():
            nonlocal t
            t += NS // 10
            return node.process(numpy_to_image(image, Header(stamp=ns_to_stamp(t)), 'bgr8'))

        assert len(frame().persons) == 1
        assert tuple(node.estimator.input_size) == (384, 640)
        assert node._ladder == [(384, 640), (288, 512), (224, 384), (192, 320)]
        # A camera at 10 Hz, 100 ms per image and images replaced: one step down per dwell
        # (0.6 of the pixels is estimated to fit at most 0.7 of the frame period).
        auto, clock = node._auto, 0.0
        for expected in [(288, 512), (224, 384), (192, 320)]:
            for _ in range(40):
                clock += 0.1
                auto.add_stamp(int(clock * NS))
                auto.add_replaced()
                auto.add_processing(0.1)
                if auto.update(clock):
                    break
            out = frame()
            assert tuple(node.estimator.input_size) == expected
            assert node.estimator.path == models.model_file('yolo11n-pose', expected, cache)
            assert node.estimator.score_threshold == 0.5      # dynamic values carried over
            assert len(out.persons) == 1 and out.header.stamp == ns_to_stamp(t)
        status = node._diagnose()[0]
        values = {kv.key: kv.value for kv in status.values}
        assert values['Input size (HxW)'] == '192x320'
        assert values['Input size steps (auto)'] == '384x640, 288x512, 224x384, 192x320'
        # Leaving auto mode goes back to the size fitted to the camera.
        assert node.set_parameters([Parameter('inference_rate_hz', value=0)])[0].successful
        frame()
        assert tuple(node.estimator.input_size) == (384, 640)
    finally:
        node.destroy_node()


@pytest.mark.skipif(not hasattr(os, 'getpriority'), reason='POSIX thread priorities')
@pytest.mark.parametrize('nice', [5, 0])
def test_inference_thread_yields_the_cpu_to_the_light_work(ros_context, tmp_path, nice):
    """inference_nice: only the inference thread is niced; the executor thread is not."""
    from mv3dpose_ros.nodes.pose2d.node import Pose2DNode
    cache = _fake_cache(tmp_path, [(384, 640)])
    node = Pose2DNode(context=ros_context, namespace='/camnice', parameter_overrides=[
        Parameter('model.cache_dir', value=cache), Parameter('model.threads', value=1),
        Parameter('inference_nice', value=nice)])
    try:
        assert node.active, node.error
        base = os.getpriority(os.PRIO_PROCESS, threading.get_native_id())
        deadline = time.monotonic() + 5
        while os.getpriority(os.PRIO_PROCESS, node._worker.native_id) != base + nice:
            assert time.monotonic() < deadline, 'inference thread priority not set'
            time.sleep(0.01)
        assert os.getpriority(os.PRIO_PROCESS, threading.get_native_id()) == base
    finally:
        node.destroy_node()


def test_ctrl_c_is_no_error_of_the_intake_nor_of_the_inference(tmp_path):
    """Ctrl-C: rclpy shuts the context down under the worker; no error, no failed image."""
    from mv3dpose_ros.nodes.pose2d.node import Pose2DNode
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    node = Pose2DNode(context=ctx, namespace='/camint', parameter_overrides=[
        Parameter('model.cache_dir', value=_fake_cache(tmp_path, [(384, 640)])),
        Parameter('model.threads', value=1)])
    said = []
    node._rl = lambda key, text, now: said.append(text)
    try:
        assert node.active, node.error
        time.sleep(0.3)                          # the inference thread waits in the intake
        rclpy.shutdown(context=ctx)              # as Ctrl-C does
        time.sleep(0.5)
        # ... or it was inferring an image: publishing the detections fails
        node._on_image(numpy_to_image(np.zeros((48, 64, 3), np.uint8),
                                      Header(stamp=ns_to_stamp(10**18), frame_id='c')))
        time.sleep(0.5)
        assert node._pending is None and node.failed == 0
        assert not said, said
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)


def test_missing_model_is_a_clear_start_error(tmp_path):
    env = dict(os.environ, MV3DPOSE_MODEL_DIR=str(tmp_path))
    res = subprocess.run([sys.executable, '-m', 'mv3dpose_ros.nodes.pose2d.node', '--ros-args',
                          '-p', 'model.path:=' + str(tmp_path / 'nope.onnx')],
                         capture_output=True, text=True, timeout=60, env=env)
    assert res.returncode == 1
    assert 'model file not found' in res.stdout + res.stderr
    res = subprocess.run([sys.executable, '-m', 'mv3dpose_ros.nodes.pose2d.node'],
                         capture_output=True, text=True, timeout=60, env=env)
    assert res.returncode == 1
    assert 'mv3dpose model fetch --model yolo11n-pose' in res.stdout + res.stderr


def _stop(proc):
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def test_console_processes_with_namespace_and_params_file(ros_context, tmp_path):
    """Both scripts as separate processes under -r __ns:=/cam0 with the shipped YAML."""
    model, expected = _crafted_model(tmp_path)
    folder = _image_folder(tmp_path, 2)
    log = open(tmp_path / 'nodes.log', 'w')
    probe = Probe(ros_context, '/cam0')
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(probe.node)
    node = subprocess.Popen(
        [sys.executable, '-m', 'mv3dpose_ros.nodes.pose2d.node', '--ros-args',
         '-r', '__ns:=/cam0', '-r', 'image:=image_raw', '--params-file',
         os.path.join(ROOT, 'config', 'pose2d.yaml'),
         '-p', f'model.path:={model}', '-p', 'model.threads:=1'],
        stdout=log, stderr=subprocess.STDOUT)
    images = None
    try:
        assert spin_until(ex, lambda: probe.node.count_publishers('/cam0/persons_2d') > 0,
                          timeout=30), open(tmp_path / 'nodes.log').read()
        images = subprocess.Popen(
            [sys.executable, '-m', 'mv3dpose_ros.nodes.image_publisher', folder, '--rate', '5',
             '--start-stamp', '1000.5', '--reliable', '--wait-for-subscribers', '1',
             '--ros-args', '-r', '__ns:=/cam0'], stdout=log, stderr=subprocess.STDOUT)
        assert spin_until(ex, lambda: images.poll() is not None and probe.persons, timeout=60), \
            open(tmp_path / 'nodes.log').read()
        spin_until(ex, lambda: len(probe.persons) >= 2, timeout=3)
        assert images.returncode == 0
        for msg in probe.persons:
            assert stamp_to_ns(msg.header.stamp) in (1000_500_000_000, 1000_700_000_000)
            assert msg.header.frame_id == 'cam0_optical_frame' and msg.camera_id == 'cam0'
            assert len(msg.persons) == 2
    finally:
        for proc in (images, node):
            if proc is not None:
                _stop(proc)
        log.close()
        ex.remove_node(probe.node)
        probe.node.destroy_node()


def test_real_model_on_panoptic_frames(ros_context, shared_data):
    """The fetched default model finds the Panoptic people; CameraInfo comes along."""
    try:
        model = resolve_model_path()
    except ModelNotFound as exc:
        pytest.skip(str(exc))
    from mv3dpose_ros.nodes.image_publisher import ImagePublisher
    from mv3dpose_ros.nodes.pose2d.node import Pose2DNode
    demo = os.path.join(shared_data, 'panoptic_demo')
    # image_publisher publishes image_raw, as drivers do; pose2d reads 'image' (remapped)
    params = [
        Parameter('model.path', value=model), Parameter('model.threads', value=2),
        Parameter('image_qos.reliability', value='reliable')]
    node = Pose2DNode(context=ros_context, namespace='/p03', cli_args=REMAP,
                      parameter_overrides=params)
    assert node.active, node.error
    probe = Probe(ros_context, '/p03')
    infos = []
    probe.node.create_subscription(CameraInfo, '/p03/camera_info', infos.append, reliable_qos())
    pub = ImagePublisher(context=ros_context, namespace='/p03', parameter_overrides=[
        Parameter('source', value=os.path.join(demo, '00_03')), Parameter('rate_hz', value=4.0),
        Parameter('start_stamp', value=2000.0), Parameter('reliability', value='reliable'),
        Parameter('calibration', value=os.path.join(demo, 'camera_parameters.json')),
        Parameter('camera_name', value='00_03'), Parameter('wait_for_subscribers', value=1),
        Parameter('preload', value=True)])
    ex = SingleThreadedExecutor(context=ros_context)
    for n in (node, probe.node, pub):
        ex.add_node(n)
    threading.Thread(target=pub.run, name='publisher', daemon=True).start()
    try:
        ok = spin_until(ex, lambda: pub.done.is_set()
                        and node.processed + node.dropped >= 5, timeout=120)
        assert ok, (pub.done.is_set(), node.received, node.processed, node.dropped, node.failed)
        spin_until(ex, lambda: len(probe.persons) >= node.processed, timeout=5)
        assert node.processed >= 1 and len(probe.persons) == node.processed
        assert infos and infos[0].width == 1920 and infos[0].k[0] > 0
        for msg in probe.persons:
            assert msg.header.frame_id == 'cam00_03_optical_frame'
            assert (stamp_to_ns(msg.header.stamp) - 2000 * NS) % (NS // 4) == 0
            assert (msg.image_width, msg.image_height) == (1920, 1080)
            assert 2 <= len(msg.persons) <= 4, [p.score for p in msg.persons]
            for p in msg.persons:
                kp = np.array([[k.x, k.y, k.confidence] for k in p.keypoints])
                sure = kp[kp[:, 2] > 0.5]
                assert len(sure) >= 6
                assert np.all((sure[:, 0] >= 0) & (sure[:, 0] < 1920))
                assert np.all((sure[:, 1] >= 0) & (sure[:, 1] < 1080))
                assert p.score >= 0.25 and p.roi.width > 20 and p.roi.height > 40
    finally:
        for n in (pub, probe.node, node):
            ex.remove_node(n)
            n.destroy_node()


def test_lifecycle_without_autostart(ros_context, tmp_path):
    from mv3dpose_ros.nodes.pose2d.node import Pose2DNode
    from rclpy.lifecycle import TransitionCallbackReturn
    ok = TransitionCallbackReturn.SUCCESS
    model, _ = _crafted_model(tmp_path)
    node = Pose2DNode(context=ros_context, parameter_overrides=[
        Parameter('model.path', value=model), Parameter('autostart', value=False)])
    try:
        assert not node.active and node.estimator is None
        assert node.trigger_configure() == ok and node.trigger_activate() == ok and node.active
        assert node.trigger_deactivate() == ok and not node.active and node._worker is None
        assert node.trigger_cleanup() == ok and node.estimator is None
        assert node.trigger_configure() == ok and node.trigger_activate() == ok
        assert node._worker.is_alive() and node.estimator is not None
    finally:
        node.destroy_node()
    bad = Pose2DNode(context=ros_context, parameter_overrides=[
        Parameter('model.path', value=str(tmp_path / 'none.onnx'))])
    try:
        assert not bad.active and 'model file not found' in bad.error
    finally:
        bad.destroy_node()


def test_a_gpu_model_is_warmed_up_before_the_first_image(ros_context, tmp_path, monkeypatch):
    """A provider other than the CPU runs once on a blank input when opened (faked here)."""
    from mv3dpose_ros.nodes.pose2d import node as pose2d_node
    from mv3dpose_ros.pose2d.estimator import PoseEstimator
    real_open, real_run, runs = pose2d_node.open_estimator, PoseEstimator.run, []

    def run(self, tensor):
        runs.append((self.provider, tensor.shape))
        return real_run(self, tensor)

    monkeypatch.setattr(PoseEstimator, 'run', run)
    model, _ = _crafted_model(tmp_path)
    for provider, warmed in (('CUDAExecutionProvider', 1), ('CPUExecutionProvider', 0)):
        def open_on(*args, **kwargs):
            est = real_open(*args, **kwargs)
            est.provider = provider                   # as onnxruntime-gpu would report it
            return est

        runs.clear()
        monkeypatch.setattr(pose2d_node, 'open_estimator', open_on)
        node = pose2d_node.Pose2DNode(context=ros_context, parameter_overrides=[
            Parameter('model.path', value=model)])
        try:
            assert node.active and len(runs) == warmed       # before any image came
            if warmed:
                assert runs[0] == (provider, (1, 3, *node.estimator.input_size))
        finally:
            node.destroy_node()


def test_inference_rate_grid_keeps_cameras_on_the_same_instants(ros_context):
    """inference_rate_hz: only the first image of each stamp window reaches the model."""
    from mv3dpose_ros.nodes.pose2d.node import header_stamp_ns, Pose2DNode
    from rclpy.serialization import serialize_message
    nodes = [Pose2DNode(context=ros_context, namespace=f'/grid{i}', parameter_overrides=[
        Parameter('autostart', value=False), Parameter('inference_rate_hz', value=5.0)])
        for i in range(2)]
    img = np.zeros((4, 4, 3), np.uint8)
    try:
        taken = [[], []]
        for i, node in enumerate(nodes):
            # camera 1 misses some frames and receives them with jitter: same instants anyway
            steps = range(0, 20) if i == 0 else (1, 2, 5, 6, 7, 9, 12, 13, 17, 18, 19)
            for k in steps:
                stamp = 1000 * NS + k * 50_000_000             # 20 Hz camera
                wire = serialize_message(numpy_to_image(
                    img, Header(stamp=ns_to_stamp(stamp), frame_id='f'), 'bgr8'))
                assert header_stamp_ns(wire) == stamp
                before = node.skipped
                node._on_image(wire)
                if node.skipped == before:
                    taken[i].append(stamp)
        assert [t - 1000 * NS for t in taken[0]] == [k * 200_000_000 for k in range(5)]
        assert nodes[0].skipped == 15 and nodes[0].received == 20
        assert nodes[0].dropped == 4                # no worker: each replaced the previous
        # camera 1 took the first image it had of each window: where it had the window's
        # first frame (600 ms), both cameras infer the same instant
        assert [t - 1000 * NS for t in taken[1]] == [ms * 1_000_000 for ms in
                                                     (50, 250, 450, 600, 850)]
        assert set(taken[0]) & set(taken[1]) == {1000 * NS + 600_000_000}
        # a stamp jump back (a replay starting again) opens a new window at once
        back = serialize_message(numpy_to_image(
            img, Header(stamp=ns_to_stamp(990 * NS), frame_id='f'), 'bgr8'))
        nodes[0]._on_image(back)
        assert nodes[0]._pending is back
        assert not nodes[0].set_parameters([Parameter('inference_rate_hz', value=2000.0)])[
            0].successful
        nodes[0].set_parameters([Parameter('inference_rate_hz', value=0.0)])
        nodes[0]._on_image(back)
        assert nodes[0].skipped == 15                # 0 = every image reaches the mailbox
    finally:
        for node in nodes:
            node.destroy_node()


def test_grid_no_faster_than_the_camera_infers_every_image(ros_context):
    """A grid at the camera's own rate selects nothing: jittered stamps never skip a frame."""
    from mv3dpose_ros.nodes.pose2d.node import Pose2DNode
    from mv3dpose_ros.pose2d.scheduling import frame_period_ns
    from rclpy.serialization import serialize_message
    node = Pose2DNode(context=ros_context, namespace='/gridfree', parameter_overrides=[
        Parameter('autostart', value=False), Parameter('inference_rate_hz', value=10.0)])
    img = np.zeros((4, 4, 3), np.uint8)
    jitter = (4, -3, 2, -4, 3, -2, 4, -3, 1, -4) * 3          # ms, around the window boundary
    try:
        for k, ms in enumerate(jitter):                         # 10 Hz camera, 10 Hz grid
            stamp = 1000 * NS + k * 100_000_000 + ms * 1_000_000
            node._on_image(serialize_message(numpy_to_image(
                img, Header(stamp=ns_to_stamp(stamp), frame_id='f'), 'bgr8')))
        assert frame_period_ns(node._taken) == pytest.approx(100_000_000, rel=0.1)
        # the first image opens a window, every later one reaches the mailbox too (on the
        # grid, the +4 / -3 ms pairs would share a window and the next one would be empty)
        assert node.skipped == 0 and node.dropped == len(jitter) - 1
        assert node._doze_s() == 0.0
        assert node._rate_label() == '10: every image (camera not faster)'   # /diagnostics
        node.set_parameters([Parameter('inference_rate_hz', value=5.0)])  # half: selects
        for k in range(30, 40):
            stamp = 1000 * NS + k * 100_000_000 + jitter[k % 10] * 1_000_000
            node._on_image(serialize_message(numpy_to_image(
                img, Header(stamp=ns_to_stamp(stamp), frame_id='f'), 'bgr8')))
        assert node.skipped == 5 and node._rate_label() == 5.0
    finally:
        node.destroy_node()


def test_grid_mode_counts_a_window_it_never_took_as_dropped(ros_context):
    """Images the grid skips are skipped; a whole window lost while the model was busy dropped."""
    from mv3dpose_ros.nodes.pose2d.node import Pose2DNode
    from rclpy.serialization import serialize_message
    node = Pose2DNode(context=ros_context, namespace='/gridloss', parameter_overrides=[
        Parameter('autostart', value=False), Parameter('inference_rate_hz', value=2.5)])
    img = np.zeros((4, 4, 3), np.uint8)

    def take(k, frames):                                # the 10 Hz camera's k-th image
        stamp = 1000 * NS + k * 100_000_000
        node._on_image(serialize_message(numpy_to_image(
            img, Header(stamp=ns_to_stamp(stamp), frame_id='f'), 'bgr8')), frames)
    try:
        for k in range(8):                              # every image taken: 400 ms windows
            take(k, 1)
        assert (node.skipped, node.dropped) == (6, 1)   # 2 windows opened; 1 replaced pending
        node._pending = None                            # the model took it
        # images 8-15 never taken: the windows of 8-11 and 12-15 lost (one image each that
        # would have been inferred: dropped; the other 6 skipped), 16 opens the next one
        take(16, 9)
        assert (node.skipped, node.dropped) == (6 + 6, 1 + 2)
        assert node._grid_stamp == 1000 * NS + 1_600_000_000
        take(17, 1)                                     # same window: skipped
        assert (node.skipped, node.dropped) == (13, 3)
    finally:
        node.destroy_node()


def test_grid_mode_dozes_until_the_next_window_is_due(ros_context):
    """Between windows the inference thread takes nothing; it wakes half a frame early."""
    from mv3dpose_ros.nodes.pose2d.node import Pose2DNode
    node = Pose2DNode(context=ros_context, namespace='/doze', parameter_overrides=[
        Parameter('autostart', value=False), Parameter('inference_rate_hz', value=2.0)])
    ms = 1_000_000
    try:
        def history(speed):
            now = time.time_ns()
            window = 1000 * NS                      # a 500 ms window opened at 1000 s
            node._grid_stamp = window
            node._taken.clear()
            for k in range(-24, 3):                 # 20 Hz camera, up to 100 ms into it
                # the last image arrives now; stamps run at ``speed`` x the wall clock
                node._taken.append((now - int((100 - 50 * k) * ms / speed),
                                    window + k * 50 * ms, 1))
            return now

        def dozes(expected_s, now):
            """Tell whether the doze is ``expected_s`` less the wall time since ``now``."""
            before = (time.time_ns() - now) / 1e9
            doze = node._doze_s()
            after = (time.time_ns() - now) / 1e9
            return expected_s - after - 0.01 <= doze <= expected_s - before + 0.01
        # next window at +500 ms of stamps, due 400 ms after the last one; wake 25 ms early
        assert dozes(0.375, history(1.0))
        assert dozes(0.1875, history(2.0))          # a replay at twice real time
        node._grid_stamp = 1000 * NS + 10 * NS      # stamps far ahead: at most one window
        assert node._doze_s() <= 0.25 + 1e-6
        node.set_parameters([Parameter('inference_rate_hz', value=0.0)])
        assert node._doze_s() == 0.0                 # every image: never dozes
    finally:
        node.destroy_node()


def test_grid_mode_takes_few_images_infers_each_window_first_and_announces_the_rest(
        tmp_path, ros_context):
    """
    Real DDS: a 20 Hz camera, a 2 Hz grid; the images between windows are not copied.

    Each window's first image is inferred and the nine after it are not, so every
    Person2DArray follows a SkippedImages (persons_2d/skipped) from the one before (0 first):
    no Person2DArray is stamped inside an announced gap.
    """
    from mv3dpose_ros.nodes.pose2d.node import Pose2DNode
    model, _ = _crafted_model(tmp_path)
    node = Pose2DNode(context=ros_context, namespace='/lazy', cli_args=REMAP,
                      parameter_overrides=[
                          Parameter('model.path', value=model),
                          Parameter('model.threads', value=1),
                          Parameter('image_qos.reliability', value='reliable'),
                          Parameter('inference_rate_hz', value=2.0),
                          Parameter('rig_rate_topic', value='')])
    probe = rclpy.create_node('lazy_probe', context=ros_context)
    stamps, notes = [], []
    probe.create_subscription(Person2DArray, '/lazy/persons_2d',
                              lambda m: stamps.append(stamp_to_ns(m.header.stamp)),
                              reliable_qos(50))
    probe.create_subscription(SkippedImages, '/lazy/persons_2d/skipped',
                              lambda m: notes.append((stamp_to_ns(m.after),
                                                      stamp_to_ns(m.header.stamp), m.camera_id)),
                              reliable_qos(50))
    pub = probe.create_publisher(Image, '/lazy/image_raw', reliable_qos(5))
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(node)
    ex.add_node(probe)
    img = np.zeros((H, W, 3), np.uint8)
    try:
        assert node.active
        assert spin_until(ex, lambda: pub.get_subscription_count() > 0, 10.0)
        base = (time.time_ns() // NS + 2) * NS       # stamps on a 50 ms grid from a 500 ms one
        t0 = time.monotonic()
        for k in range(80):                          # 4 s of a 20 Hz camera, paced in real time
            pub.publish(numpy_to_image(img, Header(stamp=ns_to_stamp(base + k * 50_000_000),
                                                   frame_id='f'), 'bgr8'))
            while time.monotonic() < t0 + (k + 1) * 0.05:
                ex.spin_once(timeout_sec=0.01)
        assert spin_until(ex, lambda: node.received >= 80, 5.0), node.received
        spin_until(ex, lambda: False, 0.5)
        # each window of 10 images is inferred from its first one
        assert len(stamps) >= 6, stamps
        assert all((s - base) % 500_000_000 == 0 for s in stamps), [s - base for s in stamps]
        # and only about two of its ten images are copied out of DDS
        assert node.taken <= node.received // 2, (node.taken, node.received)
        assert node.skipped + node.processed + node.dropped == node.received
        assert notes == [(prev, cur, 'lazy') for prev, cur in zip([0] + stamps, stamps)], \
            (notes, stamps)
        assert node.skips_announced == len(notes)
    finally:
        ex.shutdown()
        node.destroy_node()
        probe.destroy_node()


def test_auto_cameras_of_a_rig_follow_the_slowest_announced_rate(tmp_path, ros_context):
    """Two auto-mode nodes announce their rates and take a slower camera's; fixed ones not."""
    from mv3dpose_ros.nodes.pose2d.node import Pose2DNode
    from std_msgs.msg import Float64
    model, _ = _crafted_model(tmp_path)
    topic = f'/test_rig_rate_{os.getpid()}'
    nodes = [Pose2DNode(context=ros_context, namespace=f'/rig{k}', parameter_overrides=[
        Parameter('model.path', value=model), Parameter('model.threads', value=1),
        Parameter('rig_rate_topic', value=topic),
        Parameter('inference_rate_hz', value='auto' if k < 2 else 1.0)]) for k in range(3)]
    probe = rclpy.create_node('rig_rate_probe', context=ros_context)
    heard = []
    probe.create_subscription(Float64, topic, lambda m: heard.append(m.data), reliable_qos(10))
    slow = probe.create_publisher(Float64, topic, reliable_qos(10))
    ex = SingleThreadedExecutor(context=ros_context)
    for n in nodes + [probe]:
        ex.add_node(n)
    auto = nodes[:2]
    try:
        assert all(n.active for n in nodes)
        # each auto node announces its own choice (every image: 0) once a second
        assert spin_until(ex, lambda: len(heard) >= 2, 10.0) and set(heard) == {0.0}
        assert all(n.inference_rate_hz == 0.0 for n in auto)
        slow.publish(Float64(data=float('nan')))          # malformed: ignored
        slow.publish(Float64(data=2.5))                   # a slower camera of the rig
        assert spin_until(ex, lambda: all(n.inference_rate_hz == 2.5 for n in auto), 5.0)
        assert nodes[2].inference_rate_hz == 1.0          # a fixed rate is the user's
        # the slow camera goes silent: after the TTL every auto node is on its own again
        assert spin_until(ex, lambda: all(n.inference_rate_hz == 0.0 for n in auto), 10.0)
        assert nodes[2].inference_rate_hz == 1.0
    finally:
        ex.shutdown()
        for n in nodes + [probe]:
            n.destroy_node()


def test_inference_rate_parameter_accepts_auto_int_and_float(ros_context):
    from mv3dpose_ros.nodes.pose2d.node import parse_inference_rate, Pose2DNode
    assert parse_inference_rate('auto') == -1.0 and parse_inference_rate(-1) == -1.0
    assert parse_inference_rate(1) == 1.0 and parse_inference_rate('2.5') == 2.5
    for bad in ('fast', 1e6, float('nan'), True):
        with pytest.raises(ValueError, match='inference_rate_hz'):
            parse_inference_rate(bad)
    node = Pose2DNode(context=ros_context, namespace='/rate', parameter_overrides=[
        Parameter('autostart', value=False)])
    try:
        assert node._auto is not None and node.inference_rate_hz == 0.0     # default: auto
        assert node.set_parameters([Parameter('inference_rate_hz', value=1)])[0].successful
        assert node._auto is None and node.inference_rate_hz == 1.0
        assert node.set_parameters([Parameter('inference_rate_hz', value='auto')])[0].successful
        assert node._auto is not None
        res = node.set_parameters([Parameter('inference_rate_hz', value='often')])[0]
        assert not res.successful and 'inference_rate_hz' in res.reason
        assert node.set_parameters([Parameter('inference_rate_hz', value=0)])[0].successful
        assert node._auto is None and node.inference_rate_hz == 0.0
    finally:
        node.destroy_node()
    bad = Pose2DNode(context=ros_context, namespace='/rate2', parameter_overrides=[
        Parameter('inference_rate_hz', value='often')])
    try:
        assert not bad.active and 'inference_rate_hz' in bad.error
    finally:
        bad.destroy_node()
