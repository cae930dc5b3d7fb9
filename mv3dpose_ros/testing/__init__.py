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
The harness the tests and the benchmarks share: node processes, probes, spinning, figures.

The top floor of the import order (like ``nodes/``): it may import rclpy, and nothing in the
package imports it.

- :mod:`.processes`: a node or console script as a process with its log in a file
  (``NodeProcess``), stopped as Ctrl-C would (``interrupt``, ``stop_group``, ``stop_all``);
- :mod:`.spin`: ``spin_until`` (fails fast with the log when a watched process died),
  ``spin_for``;
- :mod:`.probe`: an in-process node that records messages with their arrival times and
  publishes per camera (``Probe``, ``Received``), and the latest ``/diagnostics`` values;
- :mod:`.rig`: the probe of a live rig (persons_2d, tracks, diagnostics) and its analysis
  (``RigProbe``, ``time_points``, ``analyse``, ``drop_table``, ``publisher_command``);
- :mod:`.stats`: percentiles and medians of measured figures (NaN when there are none);
- :mod:`.netns`: hosts as Linux network namespaces on one bridge (links, caps, counters);
- :mod:`.remote_probe`: a probe process on another host writing what it receives as JSON
  lines.
"""
