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
Stage 3, fusion: one synchronised set of 2D views in, the rig's tracks out.

- :mod:`.pipeline`: ``Fusion``, whose ``step`` runs the stages below over one set's record.
- :mod:`.config`: ``FusionConfig``, its checks, and the tracker's parameters drawn from it.
- :mod:`.rig`: the rig's geometry, computed once per ``Fusion``.
- :mod:`.record`: ``SetRecord``, what one step knows about its set, filled stage by stage.
- :mod:`.association`: cross-view association of 2D poses (Tanke & Gall, Algorithm 1).
- :mod:`.reconstruction`: a set's candidate 3D poses: normalise, associate, triangulate, clean.
- :mod:`.noise`: the detector's 2D noise on this rig and the joints' measurement variance.
- :mod:`.views`: single-view and late-view ray updates of the tracks.
- :mod:`.duplicates`: fragments start no track; two tracks of one person merge.
- :mod:`.assembly`: the ``Track`` outputs and tombstones of a step.
"""

__all__ = ['assembly', 'association', 'config', 'duplicates', 'noise', 'pipeline',
           'reconstruction', 'record', 'rig', 'views']
