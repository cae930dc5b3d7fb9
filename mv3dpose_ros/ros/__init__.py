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
What any node uses: messages, CDR codecs, names, QoS, parameters, diagnostics, TF, spinning.

The parts of one node live with it (``nodes.fusion``, ``nodes.pose2d``).

- :mod:`.names`: camera names -> ROS names, and the per-camera topics (``image_topic``,
  ``persons_topic``, ...) every node, command and launch file uses.
- :mod:`.cdr`: CDR read and written by hand, shared by the fast message codecs.
- :mod:`.messages`: core arrays and ``Track`` <-> ``mv3dpose_msgs`` (``Person2DArray``,
  ``TrackedSkeletonArray``, ``SkeletonInfo``).
- :mod:`.images`: ``Image``, ``CompressedImage`` and ``CameraInfo`` <-> numpy, without cv_bridge.
- :mod:`.markers`: RViz ``MarkerArray`` of tracked skeletons.
- :mod:`.frames`: coordinate frames of the rig and the people as ``geometry_msgs``.
- :mod:`.tf`: TF broadcasting and lookup for fusion_node where ``tf2_ros`` exists.
- :mod:`.bag_convert`: files to bags and back (images, OpenPose JSON, tracks), the library of
  ``mv3dpose convert``.
- :mod:`.qos`: the package's QoS profiles and incompatible-QoS reporting.
- :mod:`.subscribers`: waiting for subscribers before publishing: which topics, and saying so.
- :mod:`.params`: parameter declaration with descriptors, from core config dataclasses.
- :mod:`.diagnostics`: a small ``/diagnostics`` publisher with diagnostic_updater's keys.
- :mod:`.spin`: spinning a node's executor until the process is asked to stop; every node's
  ``main`` (``run_node``).
- :mod:`.system`: OS and Fast DDS helpers of the image-moving processes: huge pages for the
  image buffers, stale shared-memory files.
"""
