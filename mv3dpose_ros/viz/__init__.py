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
Drawing shared by every picture the package makes, below the commands and the nodes; no ROS.

- :mod:`.palette`: one colour per track id, the same in ``mv3dpose render``, RViz markers, the
  Foxglove scene and the pose2d debug image.
- :mod:`.panels`: metric orthographic views with a metre grid, skeletons and labels drawn on
  them, and which joints of a track are drawn (``valid_joints``).
- :mod:`.pictures`: a picture written as PNG, GIF or video, complete or not at all.
- :mod:`.rig`: a picture of a calibrated rig (cameras, the people it was calibrated from).
- :mod:`.scene`: the Foxglove 3D scene of tracks and cameras (``foxglove.messages``), and a
  picture of a received scene.
"""
