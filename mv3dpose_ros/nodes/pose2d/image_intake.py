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
A raw image subscription that a worker thread takes from when it is free, not an executor.

Taking a 6 MB image out of DDS costs 13-25 ms of CPU; one never taken (skipped by the grid, or
superseded while the model was busy) costs almost nothing: it stays in DDS's shared memory. So
the subscription lives on a helper node ``<name>_intake`` that no executor spins, and the
worker spins it once (``take``) when it wants the newest image. raw=True: the callback gets
the CDR bytes, whose pixels are read in place (``ros.images.decode_image_bytes``).
"""

from typing import Any, Callable

from mv3dpose_ros.ros.qos import subscription_events
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import QoSProfile


class ImageIntake:
    """The helper node, its raw subscription to ``topic`` of ``node`` and its own executor."""

    def __init__(self, node: Any, topic: str, msg_type: Any, qos: QoSProfile,
                 callback: Callable[[bytes, Any], None]) -> None:
        self.node = rclpy.create_node(
            f'{node.get_name()}_intake', namespace=node.get_namespace(), context=node.context,
            use_global_arguments=False, enable_rosout=False, start_parameter_services=False)
        self.subscription = self.node.create_subscription(
            msg_type, node.resolve_topic_name(topic), callback, qos,
            event_callbacks=subscription_events(node, topic, qos), raw=True)
        self.executor = SingleThreadedExecutor(context=node.context)
        self.executor.add_node(self.node)

    def take(self, timeout_s: float) -> bool:
        """Wait up to ``timeout_s`` for an image and hand it to the callback (the newest)."""
        self.executor.spin_once(timeout_sec=timeout_s)
        return True

    def close(self) -> None:
        """Stop taking and remove the helper node."""
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()
