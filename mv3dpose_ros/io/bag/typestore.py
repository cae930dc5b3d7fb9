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
The one typestore and QoS profiles of the bags, on ``rosbags`` (no rclpy).

``Stores.ROS2_JAZZY`` (pinned; ``Stores.LATEST`` is Kilted) plus every ``.msg`` of
``mv3dpose_msgs``, read from the installed share directory or the source tree, so the ``.msg``
files stay the single source of truth.
"""

import functools
from pathlib import Path
from typing import Any, Dict

from mv3dpose_ros.io.bag.files import BagError
from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability
from rosbags.interfaces import QosTime
from rosbags.typesys import get_types_from_msg, Stores
from rosbags.typesys import get_typestore as _rosbags_typestore

MSG_PACKAGE = 'mv3dpose_msgs'


def msg_dir() -> Path:
    """
    Return the folder holding the ``mv3dpose_msgs`` ``.msg`` files.

    The installed share directory (ament index) wins; the source tree beside this package is the
    fallback so that a plain checkout works before ``colcon build``.
    """
    try:
        from ament_index_python.packages import get_package_share_directory
        share = Path(get_package_share_directory(MSG_PACKAGE)) / 'msg'
        if any(share.glob('*.msg')):
            return share
    except Exception:  # noqa: B902 - ament index absent or package not installed
        pass
    source = Path(__file__).resolve().parents[3] / MSG_PACKAGE / 'msg'
    if any(source.glob('*.msg')):
        return source
    raise BagError(f'cannot find the {MSG_PACKAGE} .msg files: not installed (ament index) '
                   f'and not in the source tree at {source}')


@functools.lru_cache(maxsize=1)
def get_typestore():
    """Return the ROS 2 Jazzy typestore with every ``mv3dpose_msgs`` message registered."""
    store = _rosbags_typestore(Stores.ROS2_JAZZY)
    types: Dict[str, Any] = {}
    for path in sorted(msg_dir().glob('*.msg')):
        types.update(get_types_from_msg(path.read_text(), f'{MSG_PACKAGE}/msg/{path.stem}'))
    store.register(types)
    return store


def normalise_type(msgtype: str) -> str:
    """Turn ``pkg/Type`` or ``pkg/msg/Type`` into the ``pkg/msg/Type`` form bags use."""
    parts = msgtype.split('/')
    if len(parts) == 2:
        return f'{parts[0]}/msg/{parts[1]}'
    if len(parts) == 3:
        return msgtype
    raise ValueError(f'message type {msgtype!r} is not of the form pkg/msg/Type')


def serialize(msg: Any, msgtype: str) -> bytes:
    """Serialise a rosbags message object to CDR bytes."""
    return bytes(get_typestore().serialize_cdr(msg, normalise_type(msgtype)))


def deserialize(data: bytes, msgtype: str) -> Any:
    """Deserialise CDR bytes into a rosbags message object (a dataclass)."""
    return get_typestore().deserialize_cdr(data, normalise_type(msgtype))


def make_qos(reliable: bool = True, depth: int = 10, transient_local: bool = False) -> Qos:
    """Build a rosbags QoS profile for ``offered_qos_profiles`` (no rclpy needed)."""
    default = QosTime(0, 0)  # rmw: 0 = the default, i.e. no deadline / lifespan / lease
    return Qos(
        history=QosHistory.KEEP_LAST, depth=int(depth),
        reliability=QosReliability.RELIABLE if reliable else QosReliability.BEST_EFFORT,
        durability=QosDurability.TRANSIENT_LOCAL if transient_local else QosDurability.VOLATILE,
        deadline=default, lifespan=default, liveliness=QosLiveliness.AUTOMATIC,
        liveliness_lease_duration=default, avoid_ros_namespace_conventions=False)
