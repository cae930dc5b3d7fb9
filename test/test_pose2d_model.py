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
Which model pose2d_node runs: precision, the input size fitted to the camera, the GPU warm-up.

On crafted model caches (``pose2d_models``): no download. The estimator cache's own rules
(fetched sizes, ladders, auto mode's steps) are ``test_pose2d_parts``'s.
"""

from mv3dpose_ros.pose2d import models
from mv3dpose_ros.ros.images import numpy_to_image
from mv3dpose_ros.ros.messages import ns_to_stamp
import numpy as np
from pose2d_models import crafted_model, fake_cache
import pytest
from rclpy.parameter import Parameter
from std_msgs.msg import Header

pytestmark = [pytest.mark.ros]

NS = 1_000_000_000


def test_precision_auto_runs_int8_on_the_cpu_and_fp32_on_a_gpu(ros_context, tmp_path,
                                                               monkeypatch):
    """model.precision auto (default): a size's int8 twin where fetched, on the CPU only."""
    from mv3dpose_ros.nodes.pose2d import node as pose2d_node
    from mv3dpose_ros.pose2d.estimator import CPU
    cache = fake_cache(tmp_path, [(384, 640), (192, 320)], int8=[(288, 512), (192, 320)])

    def start():
        return pose2d_node.Pose2DNode(context=ros_context, namespace='/camprec',
                                      parameter_overrides=[
                                          Parameter('model.cache_dir', value=cache),
                                          Parameter('model.threads', value=1),
                                          Parameter('model.input_size', value='192x320')])
    node = start()
    try:
        assert node.active, node.error
        assert node.get_parameter('model.precision').value == 'auto'
        assert node.estimator.path == models.model_file('yolo11n-pose', (192, 320), cache,
                                                        'int8')
        assert node.estimator.precision == 'int8'
    finally:
        node.destroy_node()
    monkeypatch.setattr(pose2d_node, 'resolve_providers',
                        lambda request: (['CUDAExecutionProvider', CPU], []))
    node = start()
    try:
        assert node.active, node.error
        assert node.estimator.path == models.model_file(      # fp32 only on a GPU
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
    cache = fake_cache(tmp_path, sizes)
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


def test_a_gpu_model_is_warmed_up_before_the_first_image(ros_context, tmp_path, monkeypatch):
    """A provider other than the CPU runs once on a blank input when opened (faked here)."""
    from mv3dpose_ros.nodes.pose2d import node as pose2d_node
    from mv3dpose_ros.pose2d.estimator import PoseEstimator
    real_open, real_run, runs = pose2d_node.open_estimator, PoseEstimator.run, []

    def run(self, tensor):
        runs.append((self.provider, tensor.shape))
        return real_run(self, tensor)

    monkeypatch.setattr(PoseEstimator, 'run', run)
    model, _ = crafted_model(tmp_path)
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
