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
QoS profiles of the package and incompatible-QoS reporting.

A QoS mismatch is the most common "nothing is published" report for ROS perception packages:
DDS silently never matches the endpoints. Every subscription and publisher of our nodes
registers the event callbacks built here, which log an ERROR naming the topic, the policy and
both sides' profiles.
"""

from typing import Any, Callable, Iterable, Optional

from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.qos import (qos_policy_name_from_kind, QoSDurabilityPolicy, QoSHistoryPolicy,
                       QoSProfile, QoSReliabilityPolicy)

RELIABILITY = {'best_effort': QoSReliabilityPolicy.BEST_EFFORT,
               'reliable': QoSReliabilityPolicy.RELIABLE,
               'system_default': QoSReliabilityPolicy.SYSTEM_DEFAULT}


def parse_reliability(name: str) -> QoSReliabilityPolicy:
    """Return the reliability policy for a parameter value ('best_effort', 'reliable', ...)."""
    key = str(name).strip().lower()
    if key not in RELIABILITY:
        raise ValueError(f'unknown QoS reliability {name!r}; use one of {", ".join(RELIABILITY)}')
    return RELIABILITY[key]


def sensor_qos(reliability: str = 'best_effort', depth: int = 5) -> QoSProfile:
    """Return the SensorDataQoS profile (REP-2003) with overridable reliability and depth."""
    if depth < 1:
        raise ValueError(f'QoS depth must be >= 1, got {depth}')
    return QoSProfile(history=QoSHistoryPolicy.KEEP_LAST, depth=int(depth),
                      reliability=parse_reliability(reliability),
                      durability=QoSDurabilityPolicy.VOLATILE)


def reliable_qos(depth: int = 10) -> QoSProfile:
    """Return RELIABLE, KEEP_LAST(depth), VOLATILE: poses, tracks and markers."""
    if depth < 1:
        raise ValueError(f'QoS depth must be >= 1, got {depth}')
    return QoSProfile(history=QoSHistoryPolicy.KEEP_LAST, depth=int(depth),
                      reliability=QoSReliabilityPolicy.RELIABLE,
                      durability=QoSDurabilityPolicy.VOLATILE)


def latched_qos() -> QoSProfile:
    """Return RELIABLE + TRANSIENT_LOCAL, depth 1: late joiners get the last message."""
    return QoSProfile(history=QoSHistoryPolicy.KEEP_LAST, depth=1,
                      reliability=QoSReliabilityPolicy.RELIABLE,
                      durability=QoSDurabilityPolicy.TRANSIENT_LOCAL)


def describe(profile: QoSProfile) -> str:
    """Return a short human-readable profile, e.g. ``RELIABLE VOLATILE KEEP_LAST(10)``."""
    parts = [profile.reliability.name, profile.durability.name]
    if profile.history == QoSHistoryPolicy.KEEP_LAST:
        parts.append(f'KEEP_LAST({profile.depth})')
    elif profile.history == QoSHistoryPolicy.KEEP_ALL:
        parts.append('KEEP_ALL')
    # Remote endpoints' history is not sent by discovery (UNKNOWN): leave it out.
    return ' '.join(parts)


def _describe_endpoints(infos: Iterable[Any]) -> str:
    parts = [f'{i.node_namespace.rstrip("/")}/{i.node_name} [{describe(i.qos_profile)}]'
             for i in infos]
    return '; '.join(parts) if parts else 'none visible'


def _policy_name(kind: Any) -> str:
    try:
        return qos_policy_name_from_kind(kind)
    except Exception:  # noqa: B902 - any unknown kind: report it raw rather than fail
        return str(kind)


def subscription_events(
        node: Any, topic: str, profile: QoSProfile,
        on_error: Optional[Callable[[str], None]] = None) -> SubscriptionEventCallbacks:
    """Build callbacks that log an ERROR when a publisher on ``topic`` has incompatible QoS."""
    resolved = node.resolve_topic_name(topic)

    def incompatible(event: Any) -> None:
        text = (f'incompatible QoS on {resolved}: policy {_policy_name(event.last_policy_kind)}'
                f' ({event.total_count} total). This subscription: [{describe(profile)}];'
                f' publishers: {_describe_endpoints(node.get_publishers_info_by_topic(resolved))}.'
                f' No messages will arrive from them: make the publisher RELIABLE or set this'
                " node's input reliability parameter to best_effort.")
        node.get_logger().error(text)
        if on_error is not None:
            on_error(text)

    return SubscriptionEventCallbacks(incompatible_qos=incompatible)


def publisher_events(
        node: Any, topic: str, profile: QoSProfile,
        on_error: Optional[Callable[[str], None]] = None) -> PublisherEventCallbacks:
    """Build callbacks that log an ERROR when a subscriber on ``topic`` has incompatible QoS."""
    resolved = node.resolve_topic_name(topic)

    def incompatible(event: Any) -> None:
        infos = node.get_subscriptions_info_by_topic(resolved)
        text = (f'incompatible QoS on {resolved}: policy {_policy_name(event.last_policy_kind)}'
                f' ({event.total_count} total). This publisher: [{describe(profile)}];'
                f' subscribers: {_describe_endpoints(infos)}.'
                f' They will receive nothing from this node.')
        node.get_logger().error(text)
        if on_error is not None:
            on_error(text)

    return PublisherEventCallbacks(incompatible_qos=incompatible)
