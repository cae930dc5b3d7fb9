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
Stage 1, geometry: cameras, calibration files, triangulation, bundle adjustment.

What every later stage measures with: a camera model that maps metres to pixels and back,
every calibration format read into ``{name: Camera}``, and the two ways of turning 2D
observations into 3D (triangulating points; adjusting cameras and points together).

- :mod:`.camera`: pinhole cameras with OpenCV distortion, epipolar geometry, image-size fits.
- :mod:`.calibration`: every calibration format read into ``{name: Camera}``; rig YAML out.
- :mod:`.triangulation`: robust multi-view triangulation of person candidates.
- :mod:`.bundle`: bundle adjustment of camera extrinsics and 3D points.
"""

__all__ = ['bundle', 'calibration', 'camera', 'triangulation']
