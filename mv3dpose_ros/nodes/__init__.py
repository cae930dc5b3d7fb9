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
The ROS 2 nodes: thin adapters that wire ``core`` and ``pose2d`` to topics and parameters.

- :mod:`.pose2d`: pose2d_node and its parts (image intake, rig rate, diagnostics): one
  camera's images in, ``Person2DArray`` out (the 2D stage).
- :mod:`.fusion`: fusion_node and its parts (parameters, input checks, diagnostics): N cameras'
  ``Person2DArray`` in, tracked 3D skeletons out (the live core).
- :mod:`.bringup`: one pose2d_node per camera plus fusion_node from one rig and one parameter set.
- :mod:`.calibration_phase`: ``bringup --calibrate``: record the people, calibrate, then track.
- :mod:`.processes`: the processes of a rig, the one list bringup and the launch file start.
- :mod:`.image_publisher`: a folder of images or a video file as a free-running camera.
- :mod:`.foxglove_view`: a live web view of the pipeline over the Foxglove WebSocket protocol.
- :mod:`.roundtrip_probe`: a publish/echo probe for mv3dpose_msgs over real DDS, for tests.
- :mod:`.aliases`: deprecated console-script names, kept for one release.
"""
