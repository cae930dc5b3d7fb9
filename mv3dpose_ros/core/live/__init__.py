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
Stage 4, live: streams that arrive when they arrive, fused and published.

- :mod:`.sync`: the N-stream synchroniser grouping per-camera messages by capture stamp.
- :mod:`.sync_window`: the synchroniser's adaptive slop (stamp time) and wait (arrival time).
- :mod:`.sync_outliers`: the stream time, outlier stamps held aside, sustained jumps.
- :mod:`.sync_stats`: the synchroniser's counters, per camera and over the rig.
- :mod:`.clock_offsets`: each camera's stamp offset against the rig, from arrival delays,
  and the live loop's check that names a camera whose host clock is off.
- :mod:`.output`: what a live consumer sees of ``Fusion.step`` (publication rules, public ids).
- :mod:`.loop`: the live fusion loop (synchroniser, fusion, publication, idle steps, coasting).
- :mod:`.config`: the live configs checked and completed in one place (sim time, min views).
"""

__all__ = ['clock_offsets', 'config', 'loop', 'output', 'sync', 'sync_outliers', 'sync_stats',
           'sync_window']
