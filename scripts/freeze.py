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

"""Print exact pins of the venv's real distributions (skips egg-info stubs inside ROS wheels)."""

import importlib.metadata as md

HEADER = """# Exact pins for the project venv (make setup). Regenerate with: make freeze
# ROS 2 Jazzy comes from the ros-jazzy-* wheels on PyPI; packages the ROS wheels embed as
# egg-info (rclpy, std_msgs, ...) are not listed because pip cannot install them by name."""


def main() -> None:
    pins = set()
    for dist in md.distributions():
        if str(getattr(dist, '_path', '')).endswith('.egg-info'):
            continue
        name = dist.metadata['Name']
        if name.lower() in ('pip', 'setuptools', 'wheel'):
            continue
        pins.add(f'{name}=={dist.version}')
    print(HEADER)
    print('\n'.join(sorted(pins, key=str.lower)))


if __name__ == '__main__':
    main()
