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
Gated one-to-one assignment: the Hungarian solve that association and tracking share.

Cross-view association matches poses to candidates and tracking matches 3D poses to tracks;
both need the same rule, that a pair over its gate never blocks a valid alternative.
"""

from typing import Tuple

import numpy as np
from scipy.optimize import linear_sum_assignment

__all__ = ['gated_assignment']

#: Cost written for infeasible pairs before the Hungarian solve (never accepted).
_INFEASIBLE = 1e6


def gated_assignment(cost: np.ndarray, threshold) -> Tuple[np.ndarray, np.ndarray]:
    """
    Match rows to columns by the Hungarian algorithm over the pairs with ``cost < threshold``.

    Pairs at or over the threshold (scalar or broadcastable array; NaN costs never pass) are
    removed before the solve, not vetoed after it, so an invalid pair never blocks a valid
    alternative: the solve maximises the number of valid matches, then minimises their cost.
    Returns ``(rows, cols)`` of the accepted pairs.
    """
    feasible = cost < threshold                      # NaN compares False
    rows, cols = np.nonzero(feasible)
    r, c = rows.tolist(), cols.tolist()
    if len(set(r)) == len(r) == len(set(c)):
        # The feasible pairs are disjoint, so they are the whole solution (the usual case of
        # well separated people): no solve needed.
        return rows, cols
    rows, cols = linear_sum_assignment(np.where(feasible, cost, _INFEASIBLE))
    keep = feasible[rows, cols]
    return rows[keep], cols[keep]
