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
Read and write rosbag2 files (MCAP or sqlite3) without rosbag2, on the ``rosbags`` library.

Why this package exists: ``ros2 bag`` is not part of the ROS 2 wheels, yet users replay and
record rigs. Everything here is rclpy-free so offline tools and tests can use it; the bags it
writes are standard rosbag2 v9 directories that ``ros2 bag play``, RViz and Foxglove open on a
full install. Import from here (``from mv3dpose_ros.io.bag import BagReader``); the modules:

- :mod:`.files`: what a bag is on disk (directory, ``metadata.yaml``, storage files), ``BagError``,
  the storage names, ``is_bag`` / ``bag_path_type`` for dispatch and overwrite checks.
- :mod:`.typestore`: the one typestore (``Stores.ROS2_JAZZY`` plus every ``.msg`` of
  ``mv3dpose_msgs``), ``serialize`` / ``deserialize`` of rosbags objects, ``make_qos``.
- :mod:`.crc`: integrity: MCAP chunk and summary CRCs, the sqlite3 key table, ``verify_bag``.
- :mod:`.reader`: ``BagReader`` (every library failure a ``BagError`` naming the file, CRCs
  checked while reading), ``check_bag``.
- :mod:`.writer`: ``BagWriter`` (atomic: a hidden partial directory renamed into place on success;
  ``checkpoint`` survives SIGKILL), ``partial_dirs`` and ``writer_alive`` (a lock tells
  running writers from dead ones).
- :mod:`.salvage`: a killed recording's partial directory turned into a complete bag
  (``mv3dpose bag recover``).
"""

from mv3dpose_ros.io.bag.crc import CRC_TABLE, verify_bag, verify_mcap_chunks
from mv3dpose_ros.io.bag.files import bag_path_type, BagError, DEFAULT_STORAGE, is_bag
from mv3dpose_ros.io.bag.files import MCAP_MAGIC, PathLike, STORAGES, temp_path_beside
from mv3dpose_ros.io.bag.reader import BagMessage, BagReader, check_bag, TopicSummary
from mv3dpose_ros.io.bag.salvage import salvage, SalvageReport
from mv3dpose_ros.io.bag.typestore import deserialize, get_typestore, make_qos, MSG_PACKAGE
from mv3dpose_ros.io.bag.typestore import msg_dir, normalise_type, serialize
from mv3dpose_ros.io.bag.writer import BagWriter, partial_dirs, writer_alive

__all__ = ['bag_path_type', 'BagError', 'BagMessage', 'BagReader', 'BagWriter', 'check_bag',
           'CRC_TABLE', 'DEFAULT_STORAGE', 'deserialize', 'get_typestore', 'is_bag',
           'make_qos', 'MCAP_MAGIC', 'msg_dir', 'MSG_PACKAGE', 'normalise_type',
           'partial_dirs', 'PathLike', 'salvage', 'SalvageReport', 'serialize', 'STORAGES',
           'temp_path_beside', 'TopicSummary', 'verify_bag', 'verify_mcap_chunks',
           'writer_alive']
