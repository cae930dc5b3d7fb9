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

"""ament_python package: installs console scripts to lib/mv3dpose_ros for `ros2 run`."""

from glob import glob

from setuptools import find_packages, setup

package_name = 'mv3dpose_ros'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config',
         glob('config/*.yaml') + glob('config/*.rviz') + glob('config/*.json')
         + glob('config/*.xml')),
        ('share/' + package_name + '/config/rigs', glob('config/rigs/*.yaml')),
        ('share/' + package_name + '/launch', glob('launch/*.launch.py')),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='mv3dpose_ros maintainers',
    maintainer_email='maintainers@mv3dpose.dev',
    description='Multi-person 3D human pose tracking from calibrated multi-camera rigs.',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'mv3dpose = mv3dpose_ros.cli:main',
            'pose2d_node = mv3dpose_ros.nodes.pose2d.node:main',
            'fusion_node = mv3dpose_ros.nodes.fusion.node:main',
            'mv3dpose_bringup = mv3dpose_ros.nodes.bringup:main',
            'mv3dpose_image_publisher = mv3dpose_ros.nodes.image_publisher:main',
            'mv3dpose_foxglove_view = mv3dpose_ros.nodes.foxglove_view:main',
            # Deprecated aliases, kept for one release (0.1.x): generic names that can collide
            # with other packages' scripts on a PATH. Removed in 0.2.0.
            'bringup = mv3dpose_ros.nodes.aliases:bringup',
            'image_publisher = mv3dpose_ros.nodes.aliases:image_publisher',
            'roundtrip_probe = mv3dpose_ros.nodes.roundtrip_probe:main',
        ],
    },
)
