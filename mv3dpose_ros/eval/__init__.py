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
Evaluation metrics: PCP3D (10-part and 8-limb), MPJPE, CLEAR MOT / IDF1, identity figures.

Modules: :mod:`.pcp`, :mod:`.mpjpe`, :mod:`.mot` (per-frame building blocks; with ground
truth: MOTA, IDF1/IDP/IDR, ID switches per minute, fragmentations, duplicates), :mod:`.identity`
(without ground truth, for live runs: ``duplicate_rate``, ``identity_summary``) and
:mod:`.sequence` (a whole tracks file against Campus/Shelf, Panoptic or JSON Lines ground
truth, as ``mv3dpose eval`` prints it). All distances are metres; missing joints are NaN.
"""
