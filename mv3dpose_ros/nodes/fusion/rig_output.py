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
The rig fusion_node uses, out: ``~/rig``, the ``save_rig`` file and the cameras' static TF.

The calibration watch (``core.selfcal.watch``) may correct a camera while the node runs; every
such change, and the rig at start, is published on the latched ``~/rig`` (``std_msgs/String``:
the rig YAML every command reads, so ``ros2 topic echo --once`` gives a file to save), written
to ``save_rig`` when set (``mv3dpose_bringup --save-rig``), and broadcast again as the cameras'
static transforms.
"""

from typing import Any, Mapping, Sequence

from mv3dpose_ros.core.geometry.calibration import rig_yaml_text, save_rig_yaml
from mv3dpose_ros.ros.qos import latched_qos
from std_msgs.msg import String


class RigOutput:
    """Publish, save and broadcast the rig in use."""

    def __init__(self, node: Any, tf: Any, world_frame: str, camera_ids: Sequence[str],
                 path: str) -> None:
        self.node, self.tf, self.world_frame = node, tf, world_frame
        self.camera_ids, self.path = tuple(camera_ids), path
        self.publisher = node.create_publisher(String, '~/rig', latched_qos())
        self.changes = 0             # rigs published since start (the first is the start's)

    def publish(self, cameras: Mapping[str, Any], why: str) -> None:
        """Send ``cameras`` (every camera of the rig in use) everywhere it goes."""
        rig = {c: cameras[c] for c in self.camera_ids}
        self.publisher.publish(String(data=rig_yaml_text(rig, self.world_frame, why)))
        self.changes += 1
        if self.changes > 1:
            self.tf.republish_cameras(rig, self.camera_ids, self.node.get_clock().now().to_msg())
        if self.path:
            try:
                save_rig_yaml(rig, self.path, self.world_frame, comment=why)
            except OSError as exc:
                self.node.get_logger().error(f'save_rig: cannot write {self.path}: {exc}')
                return
            self.node.get_logger().info(f'rig in use written to {self.path} ({why})')
