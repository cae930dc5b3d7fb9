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
The algorithm: calibrated multi-view 2D poses in, tracked 3D skeletons out; numpy, no ROS.

The nodes and the offline commands run the same code from here; ``test/test_layout.py`` keeps
it free of ROS and at the bottom of the import floors.

- :mod:`.types`: shared data types (``Track``, ``TrackState``, ``JointState``, ``NS_PER_S``).
- :mod:`.camera`: pinhole cameras with OpenCV distortion, epipolar geometry, image-size fits.
- :mod:`.calibration`: every calibration format read into ``{name: Camera}``; rig YAML out.
- :mod:`.skeleton`: keypoint layouts (joints, bones, left/right) and conversion between them.
- :mod:`.files`: bounded loaders of untrusted input files and atomic output files.
- :mod:`.sync`: the N-stream synchroniser grouping per-camera messages by capture stamp.
- :mod:`.association`: cross-view association of 2D poses (Tanke & Gall, Algorithm 1).
- :mod:`.triangulation`: multi-view triangulation of the associated person candidates.
- :mod:`.tracking`: frame-to-frame tracking of 3D poses with a track life cycle.
- :mod:`.smoothing`: temporal smoothing of joint trajectories, live and offline.
- :mod:`.fusion`: ``Fusion.step``, the pipeline of the above for one synchronised set.
- :mod:`.output`: what a live consumer sees of ``Fusion.step`` (publication rules, public ids).
- :mod:`.live`: the live fusion loop (synchroniser, fusion, publication, idle steps, coasting).
- :mod:`.hindsight`: batch-only settling of tracks with knowledge of the future.
- :mod:`.clock_offsets`: each camera's stamp offset against the rig, from arrival delays.
- :mod:`.diagnostic_keys`: the ``/diagnostics`` names and keys nodes write and benches read.
- :mod:`.selfcal`: extrinsic calibration of a rig from the keypoints of people walking in it.
- :mod:`.bundle`: bundle adjustment of camera extrinsics and 3D points.
"""
