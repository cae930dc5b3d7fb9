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
Files: bags, datasets, detections, tracks, images and videos; no ROS (rosbags, not rclpy).

- :mod:`.bag`: rosbag2 read and write (MCAP, sqlite3) on ``rosbags``: type store, reader, writer,
  checks and salvage.
- :mod:`.media`: image and video files: the accepted extensions, folder listing by frame
  number, the one video reader (``VideoReader``: frames, rate, seeking), a folder or video
  played by index (``FrameSource``, the image publisher's) (``SourceError``).
- :mod:`.params_file`: ROS 2 params files read as plain data without rclpy (``mv3dpose track
  --params``, the process list of a rig, scripts): their ``ros__parameters`` by node key.
- :mod:`.cameras`: a rig's inputs: the calibration, one image folder or video per camera matched
  to its cameras, and the time points that align their frames.
- :mod:`.openpose`: OpenPose JSON detections, one folder per camera, one file per frame.
- :mod:`.pose_inputs`: the inputs of the commands that read per-camera OpenPose JSON folders
  with a calibration (``mv3dpose track``, ``mv3dpose calibrate``).
- :mod:`.tracks_jsonl`: tracks as JSON Lines, the output of ``mv3dpose track``.
- :mod:`.datasets`: ground truth of the public multi-view datasets (Campus, Shelf, Panoptic).
- :mod:`.foxglove_ws`: a minimal Foxglove WebSocket client that decodes by advertised schema.
"""
