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
The configuration of a live stream, checked and completed in one place.

The synchroniser's and the fusion's settings depend on each other and on the clock the stamps
are judged on; every caller that builds a ``LiveFusion`` (fusion_node, ``mv3dpose track``)
passes its configs through ``complete_live_config`` so the rules hold the same everywhere.
"""

import dataclasses
from typing import List, Tuple

from mv3dpose_ros.core.fusion.pipeline import FusionConfig
from mv3dpose_ros.core.live.sync import SyncConfig


def complete_live_config(sync: SyncConfig, fusion: FusionConfig, sim_time: bool
                         ) -> Tuple[SyncConfig, FusionConfig, List[str]]:
    """
    Return the configs a live stream runs with, and what was changed and why.

    Raises ``ValueError`` (or ``TypeError``) naming the field when a value cannot work. The
    arguments are left as they are: the results are new instances. ``sim_time``: stamps
    follow a replayed clock, not the arrival clock, so the checks that judge stamps on the
    arrival clock are off.
    """
    sync.validate()
    fusion.validate()
    warnings = []
    changes = {}
    if sim_time:
        # A replay's stamps follow /clock, not the arrival clock: judge them there.
        changes['stream_ahead_check'] = False
        changes['offset_warn_fraction'] = 0.0      # arrival delays of a replay say nothing
    if sync.min_views < 2 and not fusion.view_updates:
        # A set of one camera only updates tracks through single-view updates.
        warnings.append('sync.min_views 1 needs fusion.view_updates: using 2')
        changes['min_views'] = 2
    return dataclasses.replace(sync, **changes), dataclasses.replace(fusion), warnings
