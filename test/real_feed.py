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
Real detections for ROS tests: the Pose2Sim session (4 cameras, 2 people, OpenPose BODY_25B).

Read in place from ``../shared/data/pose2sim_multiperson`` (never copied); the rig is the
project's conversion ``config/rigs/pose2sim_multiperson.yaml`` of its calibration. Stamps are
``t0 + frame / 60 s`` with ``t0`` in the recent past of the wall clock, as a live rig's are
(data time advances by the frame period however slowly a loaded host delivers the frames).
"""

import os
import time
from typing import Dict, Iterator, List, Optional, Tuple

from mv3dpose_msgs.msg import Person2DArray
from mv3dpose_ros.core.geometry.calibration import load_calibration
from mv3dpose_ros.io.openpose import match_camera_folders, OpenPoseSequence
from mv3dpose_ros.ros.messages import ns_to_stamp, numpy_to_person2d_array
import numpy as np
from std_msgs.msg import Header

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RIG = os.path.join(ROOT, 'config', 'rigs', 'pose2sim_multiperson.yaml')
LAYOUT = 'body25b'
FPS = 60.0
NS = 1_000_000_000


class Pose2Sim:
    """The Pose2Sim frames and rig, and the ``Person2DArray`` messages of each frame."""

    def __init__(self, shared_data: str, frames: int = 100) -> None:
        root = os.path.join(shared_data, 'pose2sim_multiperson')
        self.rig_path = RIG
        self.cameras = load_calibration(RIG)
        folders, missing = match_camera_folders(os.path.join(root, 'pose'), list(self.cameras))
        assert not missing, missing
        seq = OpenPoseSequence(folders, num_joints=25)
        self.frames: List[Tuple[int, Dict[str, np.ndarray]]] = list(seq)[:frames]
        self.t0_ns = time.time_ns() - int((len(self.frames) / FPS + 1.0) * NS)

    def stamp_ns(self, index: int) -> int:
        """Return the stamp of the ``index``-th frame."""
        return self.t0_ns + int(round(index * NS / FPS))

    def messages(self, index: int, stamp_ns: Optional[int] = None
                 ) -> Iterator[Tuple[str, Person2DArray]]:
        """Yield ``(camera, Person2DArray)`` of the ``index``-th frame (stamp: ``stamp_ns``)."""
        _, views = self.frames[index]
        stamp = ns_to_stamp(self.stamp_ns(index) if stamp_ns is None else stamp_ns)
        for cam, poses in views.items():
            c = self.cameras[cam]
            header = Header(stamp=stamp, frame_id=f'{cam}_optical_frame')
            yield cam, numpy_to_person2d_array(poses, header, cam, c.width, c.height, LAYOUT)
