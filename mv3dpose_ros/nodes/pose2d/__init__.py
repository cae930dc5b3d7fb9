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
pose2d_node and its parts: one camera's images in, ``Person2DArray`` out (the 2D stage).

The logic is ROS-free in ``mv3dpose_ros.pose2d``; here is what only this node needs of ROS.

- :mod:`.node`: the lifecycle node, its data path and its ``main`` (console script
  ``pose2d_node``).
- :mod:`.image_intake`: a raw image subscription the inference thread takes from when it is
  free.
- :mod:`.rig_rate`: the rig-rate handshake of the auto mode, on ``rig_rate_topic``.
- :mod:`.diagnostics`: the node's ``/diagnostics`` status, one per camera.
"""
