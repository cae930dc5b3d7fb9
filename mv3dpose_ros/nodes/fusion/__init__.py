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
fusion_node and its parts: N cameras' ``Person2DArray`` in, tracked 3D skeletons out.

The algorithm is ROS-free in ``mv3dpose_ros.core`` (``core.live.loop.LiveFusion`` is what this
node wires to topics); here is what only this node needs around it.

- :mod:`.node`: the node, its topics, timers and services, and its ``main`` (console script
  ``fusion_node``).
- :mod:`.config`: the node's parameters as config dataclasses (``FusionNodeParams``), and
  ``check_setup``, which turns them into the rig, cameras and configs it runs with.
- :mod:`.inputs`: per-camera input statistics and the checks of each ``Person2DArray``.
- :mod:`.diagnostics`: the node's ``/diagnostics`` statuses.
- :mod:`.log_bridge`: the core's Python ``logging`` forwarded to the node's ROS logger.
- :mod:`.rig_output`: the rig in use (corrected by the calibration watch) on ``~/rig``, in the
  ``save_rig`` file and the cameras' static TF.
"""
