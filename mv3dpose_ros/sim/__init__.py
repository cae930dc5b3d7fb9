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
Synthetic multi-camera scenes with ground truth, for tests, benchmarks and demos.

- :mod:`.rig`: cameras on an ellipse around an area (``RigConfig``, ``make_rig``);
- :mod:`.people`: walking people with varied bodies (``WalkConfig``, ``BodyConfig``,
  ``simulate_people``);
- :mod:`.detector`: realistic 2D detector errors (``DetectorNoise``, ``detect``);
- :mod:`.scene`: all of it together (``Scene``, ``make_scene``);
- :mod:`.export`: a scene written as the files the offline tools read (rig, poses, ground truth).
"""

from mv3dpose_ros.sim.detector import detect, DetectorNoise
from mv3dpose_ros.sim.people import BodyConfig, simulate_people, WalkConfig
from mv3dpose_ros.sim.rig import make_rig, RigConfig
from mv3dpose_ros.sim.scene import make_scene, Scene

__all__ = ['BodyConfig', 'DetectorNoise', 'RigConfig', 'Scene', 'WalkConfig', 'detect',
           'make_rig', 'make_scene', 'simulate_people']
