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
Multi-person 3D human pose tracking from calibrated multi-camera rigs (Tanke & Gall 2019).

Packages, in import floors (a package imports only its own floor's permitted neighbours and
the floors below; ``test/test_layout.py`` checks it):

1. :mod:`.core`: the algorithm, numpy only, no ROS.
2. :mod:`.viz` (drawing), :mod:`.io` (files, bags, camera inputs; no ROS), :mod:`.ros`
   (message codecs, names, QoS, parameters, diagnostics).
3. :mod:`.pose2d` (2D pose estimation), :mod:`.sim` (synthetic rigs with ground truth),
   :mod:`.eval` (metrics).
4. :mod:`.nodes` (the ROS 2 nodes), :mod:`.commands` (the ``mv3dpose`` subcommands, run by
   :mod:`.cli`), :mod:`.testing` (the test and benchmark harness).
"""

__version__ = '0.1.0'
