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
Camera names -> ROS names: the one mapping every node, command and launch file uses.

A camera id comes from the calibration (``cam0``, Panoptic's ``00_03``, ``Camera 1``) and is
kept verbatim in messages (``Person2DArray.camera_id``) and files. Topics and namespaces use
its *ROS name*:

- a camera id that is a valid ROS name token (a letter first, then letters, digits and single
  underscores) is its own ROS name: ``cam0`` -> ``cam0``;
- otherwise every character other than a letter, digit or underscore becomes ``_``, runs of
  underscores collapse to one, and ``cam`` is put in front when the result does not start with
  a letter: ``00_03`` -> ``cam00_03``, ``Camera 1`` -> ``Camera_1``, ``1-left`` -> ``cam1_left``.

In every topic or namespace pattern (``/{camera}/image_raw``, ``input_topic``, bringup's
``--namespace`` and ``--image-topic``) ``{camera}`` stands for this ROS name.

Pure Python (no rclpy), so offline commands use it too.
"""

import re
from typing import Iterable

#: The per-camera topics of a rig (``camera_topic`` patterns), as the nodes and bags name them.
IMAGE_TOPIC = '/{camera}/image_raw'
INFO_TOPIC = '/{camera}/camera_info'
PERSONS_TOPIC = '/{camera}/persons_2d'

_TOKEN = re.compile(r'^[A-Za-z][A-Za-z0-9_]*$')
_NAME_TOKEN = re.compile(r'^[A-Za-z_][A-Za-z0-9_]*$')


class RosNameError(ValueError):
    """A topic or namespace that is no valid ROS name; the text says which and why."""


def camera_namespace(camera: str) -> str:
    """Return the ROS name (namespace token) of camera id ``camera`` (see the module doc)."""
    camera = str(camera)
    if not camera:
        raise RosNameError('empty camera id')
    if _TOKEN.match(camera) and '__' not in camera:
        return camera
    token = re.sub(r'_+', '_', re.sub(r'[^A-Za-z0-9_]', '_', camera))
    return token if token[:1].isalpha() else 'cam' + token


def camera_topic(pattern: str, camera: str) -> str:
    """Return ``pattern`` with ``{camera}`` replaced by the ROS name of ``camera``."""
    return pattern.replace('{camera}', camera_namespace(camera))


def image_topic(camera: str) -> str:
    """Return the image topic of ``camera`` (``sensor_msgs/Image``)."""
    return camera_topic(IMAGE_TOPIC, camera)


def info_topic(camera: str) -> str:
    """Return the ``CameraInfo`` topic of ``camera``."""
    return camera_topic(INFO_TOPIC, camera)


def persons_topic(camera: str) -> str:
    """Return the ``Person2DArray`` topic of ``camera`` (what its pose2d_node publishes)."""
    return camera_topic(PERSONS_TOPIC, camera)


def topic_problem(name: str) -> str:
    """
    Return why ``name`` is not a valid ROS 2 topic or namespace name, or '' if it is valid.

    The rules of rcl's topic name validation (a leading ``~`` for private names is accepted):
    tokens separated by ``/`` are letters, digits and underscores, do not start with a digit,
    contain no ``__``; no empty token (``//``), no trailing ``/``.
    """
    if not name:
        return 'it is empty'
    body = name[1:] if name.startswith('~') else name
    if body.startswith('~'):
        return "'~' may only be the first character"
    if len(body) > 1 and body.endswith('/'):
        return 'it ends with /'
    tokens = body.strip('/').split('/') if body not in ('', '/') else []
    if body.startswith('/') and not tokens and name != '/':
        return 'it has no name after /'
    for token in tokens:
        if not token:
            return "it contains an empty token ('//')"
        if token[0].isdigit():
            return f'token {token!r} starts with a digit'
        if not _NAME_TOKEN.match(token):
            bad = sorted({c for c in token if not (c.isalnum() or c == '_') or not c.isascii()})
            return f'token {token!r} contains {"".join(bad)!r} (only letters, digits and _)'
        if '__' in token:
            return f"token {token!r} contains '__'"
    return ''


def check_pattern(pattern: str, cameras: Iterable[str], what: str) -> None:
    """
    Raise ``RosNameError`` unless ``pattern`` gives a valid, distinct name for every camera.

    ``what`` names the option or parameter in the message (``--image-topic``).
    """
    cameras = list(cameras)
    names = {}
    for cam in cameras:
        topic = camera_topic(pattern, cam)
        problem = topic_problem(topic)
        if problem:
            raise RosNameError(f'{what} {pattern!r} gives {topic!r} for camera {cam!r}, '
                               f'which is no valid ROS name: {problem}')
        names.setdefault(topic, []).append(cam)
    if len(cameras) > 1 and '{camera}' not in pattern:
        raise RosNameError(
            f'{what} {pattern!r} has no {{camera}}: all {len(cameras)} cameras would share '
            'one name (e.g. /{camera}/image_raw)')
    dup = {t: c for t, c in names.items() if len(c) > 1}
    if dup:
        raise RosNameError(f'{what} {pattern!r}: cameras map to the same name: {dup}')
