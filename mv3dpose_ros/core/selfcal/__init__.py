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
Self-calibration: a rig's extrinsics from the people who walk through it.

The steps, in the order ``extrinsics.calibrate`` runs them:

- :mod:`.views`: keypoints normalised, people followed per view, the input checked; ``Settings``.
- :mod:`.pairs`: which person is which between two cameras, and the pair's essential matrix.
- :mod:`.points`: one bundle-adjustment point per joint seen by two cameras or more.
- :mod:`.placement`: cameras placed one by one and adjusted; odd and bumped cameras found.
- :mod:`.frame`: the world frame and metric scale; comparing an estimate with a reference rig.
- :mod:`.extrinsics`: ``calibrate`` (and ``refine``), the conductor over the steps, its report.

Live, on a calibrated rig:

- :mod:`.watch`: each camera's pose checked against the others' people; a turned camera named,
  left out or turned back.
"""

__all__ = ['extrinsics', 'frame', 'pairs', 'placement', 'points', 'views', 'watch']
