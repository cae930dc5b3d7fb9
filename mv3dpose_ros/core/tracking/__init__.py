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
Stage 2, tracking: 3D poses over time, one track per person, and its filters.

- :mod:`.tracker`: frame-to-frame tracking of 3D poses with a track life cycle.
- :mod:`.smoothing`: per-joint Kalman filters (live) and offline smoothers.
- :mod:`.hindsight`: batch-only settling of tracks with knowledge of the future.
"""

__all__ = ['hindsight', 'smoothing', 'tracker']
