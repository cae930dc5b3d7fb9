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

"""Percentiles and medians of measured figures: NaN when there is nothing to summarise."""

import math
from typing import Dict, Iterable, Sequence

import numpy as np


def percentile(values: Iterable[float], q: float, method: str = 'linear') -> float:
    """
    Return the ``q``-th percentile of ``values`` (NaN when empty), as ``np.percentile``.

    ``method='nearest'`` picks a measured value (index ``round(q / 100 * (n - 1))``) instead
    of interpolating between two.
    """
    values = np.asarray(list(values), dtype=float)
    return float(np.percentile(values, q, method=method)) if values.size else math.nan


def median(values: Iterable[float]) -> float:
    """Return the median of the values that are not NaN (NaN when none is)."""
    return percentile([v for v in values if v == v], 50)


def summary(values: Sequence[float], qs: Sequence[float] = (50, 95)) -> Dict[str, float]:
    """Return ``{'p50': ..., 'p95': ...}`` (the ``qs``) of ``values``."""
    return {f'p{q:g}': percentile(values, q) for q in qs}
