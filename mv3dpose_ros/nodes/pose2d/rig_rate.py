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
The rig-rate handshake of pose2d_node's auto mode, on ``rig_rate_topic`` (std_msgs/Float64).

Each auto-mode camera announces the grid rate it can sustain alone, once a period and at each
change, and hears the other cameras' (``pose2d.auto_rate.GridRate``, which the node passes in,
keeps them and uses the slowest); so the cameras of a rig infer the same instants. The timer
runs on the steady clock: announcements and their expiry go on while a bag is paused (sim
time).
"""

import time
from typing import Any, Callable

from mv3dpose_ros.ros.qos import reliable_qos
from rclpy.clock import Clock, ClockType
from std_msgs.msg import Float64


class RigRateLink:
    """
    One camera's publisher, subscription and timer on the rig's rate topic.

    ``rate`` is the camera's ``GridRate``; ``share()`` applies the rig's slowest rate (called
    after each announcement heard and each period, as announcements expire); ``complain(text)``
    hears of a malformed announcement.
    """

    def __init__(self, node: Any, topic: str, rate: Any, period_s: float,
                 share: Callable[[], None], complain: Callable[[str], None]) -> None:
        self.node, self.topic, self.rate = node, topic, rate
        self._share, self._complain = share, complain
        qos = reliable_qos(10)
        self.publisher = node.create_publisher(Float64, topic, qos)
        self.subscription = node.create_subscription(Float64, topic, self._heard, qos)
        self.timer = node.create_timer(period_s, self._tick,
                                       clock=Clock(clock_type=ClockType.STEADY_TIME))

    def announce(self) -> None:
        """Auto mode: tell the rig's other cameras the grid rate this one can sustain."""
        auto = self.rate.auto
        if auto is not None:
            self.publisher.publish(Float64(data=float(auto.rate_hz)))

    def _heard(self, msg: Float64) -> None:
        if not self.rate.hear(float(msg.data), time.monotonic()):
            self._complain(f'ignored a rate of {msg.data!r} Hz on {self.topic} (0 or a finite '
                           'rate > 0 expected)')
            return
        self._share()

    def _tick(self) -> None:
        self.announce()
        self._share()                       # announcements expire

    def destroy(self) -> None:
        """Remove the publisher, the subscription and the timer."""
        self.node.destroy_publisher(self.publisher)
        self.node.destroy_subscription(self.subscription)
        self.node.destroy_timer(self.timer)
