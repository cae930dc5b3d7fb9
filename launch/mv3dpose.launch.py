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
Launch one pose2d_node per camera plus fusion_node (full ROS 2 installs only).

Usage::

    ros2 launch mv3dpose_ros mv3dpose.launch.py rig:=/path/rig.yaml cameras:=cam0,cam1
    ros2 launch mv3dpose_ros mv3dpose.launch.py rig:=rig.yaml image_topic:=/{camera}/image_raw

The same processes and arguments as the ``bringup`` console script (which is what the tests
run, since ``launch``/``launch_ros`` are not in the PyPI wheels). ``cameras`` empty means every
camera of the rig. Never imported by the tests.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def _nodes(context, *args, **kwargs):
    share = get_package_share_directory('mv3dpose_ros')
    rig = LaunchConfiguration('rig').perform(context)
    if not rig:
        raise RuntimeError('set rig:=<rig calibration file>')
    rig = os.path.abspath(rig)
    cameras = [c for c in LaunchConfiguration('cameras').perform(context).split(',') if c]
    if not cameras:
        from mv3dpose_ros.core.geometry.calibration import load_calibration
        cameras = list(load_calibration(rig))
    image_topic = LaunchConfiguration('image_topic').perform(context)
    sim_time = LaunchConfiguration('use_sim_time').perform(context).lower() == 'true'
    pose2d_params = LaunchConfiguration('pose2d_params').perform(context) or \
        os.path.join(share, 'config', 'pose2d.yaml')
    fusion_params = LaunchConfiguration('fusion_params').perform(context) or \
        os.path.join(share, 'config', 'fusion.yaml')
    nodes = []
    from mv3dpose_ros.ros.names import camera_namespace, camera_topic
    for cam in cameras:   # {camera} and namespaces: the camera's ROS name (00_03 -> cam00_03)
        remaps = [('image', camera_topic(image_topic or '/{camera}/image_raw', cam))]
        nodes.append(Node(
            package='mv3dpose_ros', executable='pose2d_node', name='pose2d_node',
            namespace=camera_namespace(cam), output='screen', remappings=remaps,
            parameters=[pose2d_params, {'camera_id': cam, 'use_sim_time': sim_time}]))
    nodes.append(Node(
        package='mv3dpose_ros', executable='fusion_node', name='fusion_node', output='screen',
        parameters=[fusion_params, {'rig_config': rig, 'camera_ids': cameras,
                                    'input_topic': '/{camera}/persons_2d',
                                    'use_sim_time': sim_time}]))
    port = int(LaunchConfiguration('foxglove_port').perform(context) or 0)
    if port > 0:          # the live web view (docs/foxglove.md)
        nodes.append(Node(
            package='mv3dpose_ros', executable='mv3dpose_foxglove_view', name='foxglove_view',
            output='screen', parameters=[{'rig_config': rig, 'camera_ids': cameras,
                                          'port': port, 'use_sim_time': sim_time}]))
    return nodes


def generate_launch_description():
    """Declare the arguments and the nodes."""
    return LaunchDescription([
        DeclareLaunchArgument('rig', default_value='', description='rig calibration file'),
        DeclareLaunchArgument('cameras', default_value='',
                              description='comma-separated camera ids (empty: all of the rig)'),
        DeclareLaunchArgument('image_topic', default_value='/{camera}/image_raw',
                              description='image topic per camera ({camera}: the camera ROS '
                                          'name, as mv3dpose_bringup --image-topic)'),
        DeclareLaunchArgument('pose2d_params', default_value='',
                              description='pose2d_node params file (default: the shipped one)'),
        DeclareLaunchArgument('fusion_params', default_value='',
                              description='fusion_node params file (default: the shipped one)'),
        DeclareLaunchArgument('use_sim_time', default_value='false',
                              description='use /clock (bag replay)'),
        DeclareLaunchArgument('foxglove_port', default_value='0',
                              description='also serve the live web view on this WebSocket '
                                          'port (0: off)'),
        OpaqueFunction(function=_nodes),
    ])
