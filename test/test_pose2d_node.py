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

The topics, the console processes, the lifecycle and the shutdown of the node.

The crafted-ONNX tests always run (the "network" returns fixed people, so the expected
keypoints follow from the letterbox alone: ``pose2d_models``); the real-model test needs
``mv3dpose model fetch`` and the Panoptic frames, and skips with the reason otherwise. Which
model runs is ``test_pose2d_model``'s, the inference rate ``test_pose2d_rate``'s. Every wait
is bounded; nothing asserts on speed.
"""

import os
import subprocess
import sys
import threading
import time
import types

from diagnostic_msgs.msg import DiagnosticArray
from mv3dpose_msgs.msg import Person2DArray, SkeletonInfo
from mv3dpose_ros.pose2d.models import ModelNotFound, resolve_model_path
from mv3dpose_ros.ros.images import numpy_to_image
from mv3dpose_ros.ros.messages import ns_to_stamp, stamp_to_ns
from mv3dpose_ros.ros.qos import latched_qos, reliable_qos
from mv3dpose_ros.testing.spin import spin_until
import numpy as np
from pose2d_models import crafted_model, fake_cache, H, image_folder, W
import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import Header

pytestmark = [pytest.mark.ros]

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
NS = 1_000_000_000
REMAP = ['--ros-args', '-r', 'image:=image_raw']


def inference_thread(node):
    """Return the node's inference thread (named after its camera) while it runs, else None."""
    return next((t for t in threading.enumerate() if t.name == f'pose2d-{node.camera_id}'),
                None)


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
    model, expected = crafted_model(tmp_path)
    folder = image_folder(tmp_path, 3)
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
        def done():
            counts = node.stats
            return pub.done.is_set() and len(probe.persons) + counts.dropped >= 3 and \
                counts.processed + counts.dropped >= 3

        assert spin_until(ex, done, timeout=30)
        spin_until(ex, lambda: len(probe.persons) >= node.stats.processed, timeout=5)
        # Every image is either published or counted as dropped for a newer one.
        counts = node.stats
        assert len(probe.persons) == counts.processed and counts.processed + counts.dropped == 3
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
            == node.stats.processed, timeout=10)
        status = latest()
        keys = {kv.key: kv.value for kv in status.values}
        assert status.hardware_id == 'camx'
        assert int(keys['Images processed']) == node.stats.processed
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
        assert node.process(bad) is None and node.stats.rejected_encoding == 1
        assert node.process(numpy_to_image(img, Header(frame_id='x'), 'bgr8')) is None
        assert node.stats.rejected_stamp == 1
        node.set_parameters([Parameter('score_threshold', value=0.95)])
        empty = node.process(numpy_to_image(img, header, 'bgr8'))
        assert empty is not None and empty.persons == [] and empty.header == header
        node.set_parameters([Parameter('score_threshold', value=0.7)])
        assert len(node.process(numpy_to_image(img, header, 'bgr8')).persons) == 1
        # The debug image is drawn only while someone subscribes.
        debug = '/camx/pose2d_node/debug_image'
        assert probe.node.count_subscribers(debug) == 0
        probe.watch_debug(debug)
        # (an image processed before the node's publisher matched the probe is not drawn)
        assert spin_until(ex, lambda: node.process(numpy_to_image(img, header, 'bgr8'))
                          is not None and probe.debug, timeout=10)
        assert (probe.debug[0].encoding, probe.debug[0].width) == ('bgr8', W)
        assert probe.debug[0].header == header
    finally:
        for n in (pub, probe.node, node):
            ex.remove_node(n)
            n.destroy_node()


@pytest.mark.skipif(not hasattr(os, 'getpriority'), reason='POSIX thread priorities')
@pytest.mark.parametrize('nice', [5, 0])
def test_inference_thread_yields_the_cpu_to_the_light_work(ros_context, tmp_path, nice):
    """inference_nice: only the inference thread is niced; the executor thread is not."""
    from mv3dpose_ros.nodes.pose2d.node import Pose2DNode
    cache = fake_cache(tmp_path, [(384, 640)])
    node = Pose2DNode(context=ros_context, namespace='/camnice', parameter_overrides=[
        Parameter('model.cache_dir', value=cache), Parameter('model.threads', value=1),
        Parameter('inference_nice', value=nice)])
    try:
        assert node.active, node.error
        base = os.getpriority(os.PRIO_PROCESS, threading.get_native_id())
        deadline = time.monotonic() + 5
        while os.getpriority(os.PRIO_PROCESS, inference_thread(node).native_id) != base + nice:
            assert time.monotonic() < deadline, 'inference thread priority not set'
            time.sleep(0.01)
        assert os.getpriority(os.PRIO_PROCESS, threading.get_native_id()) == base
    finally:
        node.destroy_node()


def test_ctrl_c_is_no_error_of_the_intake_nor_of_the_inference(tmp_path, monkeypatch):
    """Ctrl-C: rclpy shuts the context down under the worker; no error, no failed image."""
    from mv3dpose_ros.nodes.pose2d.node import Pose2DNode
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    node = Pose2DNode(context=ctx, namespace='/camint', parameter_overrides=[
        Parameter('model.cache_dir', value=fake_cache(tmp_path, [(384, 640)])),
        Parameter('model.threads', value=1)])
    said, logger = [], node.get_logger()           # the errors the node logs from now on
    monkeypatch.setattr(node, 'get_logger', lambda: types.SimpleNamespace(
        error=said.append, warning=logger.warning, info=logger.info, fatal=logger.fatal))
    try:
        assert node.active, node.error
        time.sleep(0.3)                          # the inference thread waits in the intake
        rclpy.shutdown(context=ctx)              # as Ctrl-C does
        time.sleep(0.5)
        # ... or it was inferring an image: publishing the detections fails
        node.offer(numpy_to_image(np.zeros((48, 64, 3), np.uint8),
                                  Header(stamp=ns_to_stamp(10**18), frame_id='c')))
        time.sleep(0.5)
        counts = node.stats
        assert counts.waiting_stamp_ns is None and counts.failed == 0
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
    model, expected = crafted_model(tmp_path)
    folder = image_folder(tmp_path, 2)
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
                        and node.stats.processed + node.stats.dropped >= 5, timeout=120)
        assert ok, (pub.done.is_set(), node.stats)
        spin_until(ex, lambda: len(probe.persons) >= node.stats.processed, timeout=5)
        assert node.stats.processed >= 1 and len(probe.persons) == node.stats.processed
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
    model, _ = crafted_model(tmp_path)
    node = Pose2DNode(context=ros_context, parameter_overrides=[
        Parameter('model.path', value=model), Parameter('autostart', value=False)])
    try:
        assert not node.active and node.estimator is None
        assert node.trigger_configure() == ok and node.trigger_activate() == ok and node.active
        assert node.trigger_deactivate() == ok and not node.active
        assert inference_thread(node) is None
        assert node.trigger_cleanup() == ok and node.estimator is None
        assert node.trigger_configure() == ok and node.trigger_activate() == ok
        assert inference_thread(node) is not None and node.estimator is not None
    finally:
        node.destroy_node()
    bad = Pose2DNode(context=ros_context, parameter_overrides=[
        Parameter('model.path', value=str(tmp_path / 'none.onnx'))])
    try:
        assert not bad.active and 'model file not found' in bad.error
    finally:
        bad.destroy_node()
