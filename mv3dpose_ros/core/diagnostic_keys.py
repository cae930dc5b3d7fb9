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
The ``/diagnostics`` names and keys that nodes write and benches, tests and tools read.

One spelling for both sides: a bench that matched a status by its human label broke silently
when the label changed. Status names are suffixes (the node prefixes its own name, e.g.
``fusion_node: synchronizer``); per-camera input statuses are ``<camera> input``.
"""


class FusionStatusNames:
    """fusion_node's status names (after ``<node>: ``)."""

    SYNCHRONIZER = 'synchronizer'
    TRACKING = 'tracking'
    CLOCK = 'clock'
    INPUT_SUFFIX = ' input'          # '<camera> input'


class FusionKeys:
    """fusion_node's values read elsewhere."""

    RECEIVED = 'received'
    DROPPED_BY_SYNC = 'dropped by sync'
    STAMP_OFFSET_MS = 'stamp offset (ms)'
    SETS_EMITTED = 'sets emitted'
    PARTIAL_SETS = 'partial sets'
    LATENCY_MEDIAN_MS = 'latency median (ms)'
    LATENCY_P95_MS = 'latency p95 (ms)'
    PROCESSING_MEDIAN_MS = 'processing median (ms)'
    PROCESSING_P95_MS = 'processing p95 (ms)'


class Pose2DKeys:
    """pose2d_node's values read elsewhere."""

    IMAGES_RECEIVED = 'Images received'
    DROPPED_NEWER = 'Dropped before inference (newer image arrived)'
    STAGE_MEDIAN_MS = 'Stage {} median (ms)'          # .format(stage)
    CAPTURE_TO_PUBLISH_MEDIAN_MS = 'Capture to publish median (ms)'
    CAPTURE_TO_PUBLISH_P95_MS = 'Capture to publish p95 (ms)'
    INPUT_SIZE = 'Input size (HxW)'
    PRECISION = 'Precision'
    THREADS = 'Intra-op threads'
