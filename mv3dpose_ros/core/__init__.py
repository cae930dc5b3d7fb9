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
it free of ROS and at the bottom of the import floors. One package per stage, each importing
only the shared modules and the stages below it:

Shared by every stage:

- :mod:`.types`: shared data types (``Track``, ``TrackState``, ``JointState``, ``NS_PER_S``).
- :mod:`.skeleton`: keypoint layouts (joints, bones, left/right) and conversion between them.
- :mod:`.assignment`: the gated Hungarian assignment that association and tracking share.
- :mod:`.files`: bounded loaders of untrusted input files and atomic output files.
- :mod:`.diagnostic_keys`: the ``/diagnostics`` names and keys nodes write and benches read.

The stages, lowest first:

1. :mod:`.geometry`: cameras, calibration files, triangulation, bundle adjustment.
2. :mod:`.tracking`: the tracker, its per-joint filters, offline smoothing and hindsight.
3. :mod:`.fusion`: association across views and ``Fusion.step`` over one synchronised set.
   :mod:`.selfcal` (beside it): a rig's extrinsics from the people in it.
4. :mod:`.live`: the synchroniser, clock offsets, the publication policy and the live loop.
"""

__all__ = ['assignment', 'diagnostic_keys', 'files', 'fusion', 'geometry', 'live', 'selfcal',
           'skeleton', 'tracking', 'types']
