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
The parameters of ``pose2d_node``, one dataclass per section (no ROS here).

Each field is one parameter (``model.name``, ``image_qos.reliability``, ...): its default is the
parameter's default and its trailing comment the parameter's description
(``ros.params.declare_config``). Fields made with ``dynamic`` may change at run time (ROS
parameters tagged ``[DYNAMIC]``); the others are read-only. ``parameter_error`` checks a
dynamic value before the node takes it.
"""

from dataclasses import dataclass, field
from typing import Any

from mv3dpose_ros.pose2d.scheduling import parse_inference_rate


def dynamic(default: Any, any_type: bool = False) -> Any:
    """Return a field whose parameter may change at run time (``any_type``: 1, 1.0 or auto)."""
    return field(default=default, metadata={'dynamic': True, 'dynamic_typing': any_type})


@dataclass
class ModelConfig:
    """The pose model of one camera (``model.*``)."""

    name: str = 'yolo11n-pose'          # registered model used when model.path is empty (see
    #                                   `mv3dpose model list`)
    path: str = ''                      # explicit ONNX file of a supported family (overrides
    #                                   model.name)
    family: str = 'auto'                # auto | yolo-pose | movenet-multipose (auto reads the
    #                                   ONNX)
    input_size: str = 'auto'            # auto: of the fetched sizes of the registered model, the
    #                                   one that fits the first image's aspect (384x640 for 16:9,
    #                                   640x384 for portrait); with inference_rate_hz auto, smaller
    #                                   fetched sizes down to model.min_input_side are used while
    #                                   the camera outpaces inference. N or HxW: that size, fixed;
    #                                   empty: the model's default. For models with dynamic input
    #                                   it sets the size
    min_input_side: int = 320           # smallest long side of the input that model.input_size
    #                                   auto steps down to under load (320: 192x320 for 16:9
    #                                   images, which still finds every person on the Panoptic
    #                                   frames with 4 cameras, its keypoints about 18 px off those
    #                                   of 640x640; 512 stops at 288x512, 10 px); a value above the
    #                                   chosen size keeps it fixed
    cache_dir: str = ''                 # model cache (empty = $MV3DPOSE_MODEL_DIR or
    #                                   ~/.cache/mv3dpose/models)
    threads: int = 0                    # onnxruntime intra-op threads (0 = one per core; bringup
    #                                   gives each of N cameras cores / N)
    precision: str = 'auto'             # auto | fp32 | int8: variant of the registered model; auto
    #                                   = int8 on the CPU where fetched (make setup builds it;
    #                                   15-20 % less time, accuracy in docs/models.md), else
    #                                   fp32
    providers: str = 'auto'             # onnxruntime execution providers: auto (TensorRT where its
    #                                   libraries load, CUDA, OpenVINO, CPU: the first available)
    #                                   or a comma-separated list of tensorrt, cuda, openvino, cpu;
    #                                   CPU is the fallback


@dataclass
class ImageQosConfig:
    """The QoS of the image subscription (``image_qos.*``; history depth 1)."""

    reliability: str = 'best_effort'    # input QoS reliability: best_effort (REP-2003 sensor data)
    #                                   | reliable | system_default


@dataclass
class OutputQosConfig:
    """The QoS of ``persons_2d`` (``output_qos.*``; RELIABLE)."""

    depth: int = 10                     # persons_2d QoS history depth (RELIABLE)


@dataclass
class Pose2DConfig:
    """Every parameter of ``pose2d_node``, in the order they are declared."""

    camera_id: str = ''                 # rig camera name written into every Person2DArray; empty =
    #                                   the last component of the node namespace (e.g. cam0 under
    #                                   /cam0)
    model: ModelConfig = field(default_factory=ModelConfig)
    score_threshold: float = dynamic(-1.0)  # minimum person score; < 0 = family default (YOLO
    #                                   0.25, MoveNet 0.2)
    keypoint_threshold: float = dynamic(0.0)  # keypoint confidences below this are published as 0
    nms_iou: float = dynamic(0.7)       # IoU above which overlapping person boxes are merged
    #                                   (YOLO)
    max_people: int = dynamic(100)      # most people published per image
    image_qos: ImageQosConfig = field(default_factory=ImageQosConfig)
    image_transport: str = 'raw'        # raw: sensor_msgs/Image on image | compressed:
    #                                   sensor_msgs/CompressedImage (JPEG/PNG) on image/compressed,
    #                                   as image_transport's compressed plugin publishes it
    output_qos: OutputQosConfig = field(default_factory=OutputQosConfig)
    debug_image: bool = True            # offer ~/debug_image (drawn only while subscribed)
    debug_min_confidence: float = dynamic(0.3)  # keypoints drawn in the debug image from this
    #                                   confidence
    diagnostics_period_s: float = 1.0   # /diagnostics publish period [s]
    min_rate_hz: float = dynamic(0.0)   # output rate below which diagnostics WARN (0 = off)
    no_input_timeout_s: float = dynamic(5.0)  # WARN when no image arrived for this long [s]
    inference_rate_hz: float = dynamic(-1.0, any_type=True)  # -1 or auto: every image while the
    #                                   node keeps up; when images come faster than it infers, a
    #                                   smaller input, then (once over a quarter of the images go
    #                                   uninferred) a grid rate it can sustain (measured; the
    #                                   slowest camera's for the whole rig, see rig_rate_topic), so
    #                                   the cameras of a rig infer common instants; 0: infer the
    #                                   newest image whenever the model is free; > 0: infer only
    #                                   the first image of each 1/rate window of the header stamps
    #                                   (every camera of a synchronised rig infers the same
    #                                   instants)
    rig_rate_topic: str = '/mv3dpose/pose2d_auto_rate'  # auto mode: the topic on which the cameras
    #                                   of a rig announce their grid rates (std_msgs/Float64); each
    #                                   follows the slowest, so all infer the same instants, on a
    #                                   grid of 1.33-1.5x steps (one topic per rig; empty: each
    #                                   camera alone)
    inference_nice: int = 5             # nice value of the inference thread (0 = unchanged): on a
    #                                   shared CPU the light, latency-critical work (image receipt,
    #                                   publishing, fusion) runs before inference instead of
    #                                   queueing behind it
    autostart: bool = True              # configure and activate at start-up (false: wait for
    #                                   lifecycle transitions)


def parameter_error(name: str, value: Any) -> str:
    """Return why a new value of dynamic parameter ``name`` is refused ('' when it is not)."""
    if name in ('nms_iou', 'keypoint_threshold', 'debug_min_confidence') and not (
            0.0 <= float(value) <= 1.0):
        return f'{name} must be in [0, 1]'
    if name == 'max_people' and int(value) < 1:
        return 'max_people must be >= 1'
    if name == 'inference_rate_hz':
        try:
            parse_inference_rate(value)
        except ValueError as exc:
            return str(exc)
    return ''
