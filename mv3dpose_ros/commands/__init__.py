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
Subcommands of the ``mv3dpose`` command line tool, one module each.

Each exposes ``add_arguments(parser)`` and ``run(args) -> int``; ``mv3dpose_ros.cli`` lists
them and imports a module only when its subcommand runs. Commands hold the command line and
its orchestration; what other code needs lives below them (``io``, ``ros``, ``viz``), and no
command imports another except ``demo``, which runs the others.

- :mod:`.detect`: 2D poses of per-camera image folders or videos as OpenPose JSON (offline).
- :mod:`.track`: 3D tracks from per-camera OpenPose JSON folders (offline).
- :mod:`.calibrate`: a rig's extrinsics from the 2D keypoints of the people in it.
- :mod:`.eval`: score a tracks file against ground truth (PCP, MPJPE, MOTA).
- :mod:`.model`: fetch, list, locate and inspect the 2D pose models.
- :mod:`.bag`: record, play and inspect rosbag2 files without ``ros2 bag``.
- :mod:`.convert`: images, OpenPose JSON and tracks to and from bags.
- :mod:`.render`: tracks as PNG, GIF or video pictures.
- :mod:`.demo`: the live pipeline end to end over DDS, with a summary and a picture.
"""
