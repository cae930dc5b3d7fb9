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
2D multi-person pose estimation with onnxruntime on the CPU (no rclpy here).

- :mod:`.models`: registry of fetchable models (pinned PyPI sources, sha256, licences) and cache.
- :mod:`.fetch`: builds a registered model's ONNX once (``mv3dpose model fetch``).
- :mod:`.estimator`: ``open_estimator(path)`` -> ``PoseEstimator.infer(image) -> Detections``
  (``keypoints [P, 17, 3]`` x, y, confidence in original pixels, ``boxes [P, 4]``,
  ``scores [P]``) for the YOLO-pose and MoveNet MultiPose families.
- :mod:`.ops`: letterbox and its inverse, numpy NMS. :mod:`.draw`: debug drawing.
- :mod:`.config`: ``pose2d_node``'s parameters as dataclasses (``Pose2DConfig``, ``ModelConfig``).
- :mod:`.intake`: ``ImageMailbox`` (the newest image, what became of the others) and the
  ``InferenceThread`` that takes from it.
- :mod:`.scheduling`: the grid arithmetic of ``inference_rate_hz`` (windows, frame period, doze,
  size ladder); :mod:`.auto_rate`: auto mode's choice (``AutoInferenceRate``), the rig's rates
  (``RigRate``) and the rate in use (``GridRate``).
- :mod:`.sizing`: ``EstimatorCache``, the input size in use and the others, each opened once.
"""
