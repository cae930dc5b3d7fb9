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

The processes are the list ``mv3dpose_ros.nodes.processes.rig_processes`` returns, the one the
``mv3dpose_bringup`` console script starts (which is what most tests run, since
``launch``/``launch_ros`` are not in the PyPI wheels); ``test/test_bringup.py`` checks this
file against that list where ``launch_ros`` is installed. ``cameras`` empty means fusion_node's
``camera_ids``, else every camera of the rig; ``rig`` empty means its ``rig_config``.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from mv3dpose_ros.nodes.processes import PlanError, rig_processes

#: The launch arguments as the messages of ``rig_processes`` name them.
LABELS = {'rig': 'rig:=', 'namespace': 'the namespace', 'image_topic': 'image_topic:='}


def _nodes(context, *args, **kwargs):
    def arg(name):
        return LaunchConfiguration(name).perform(context)

    share = get_package_share_directory('mv3dpose_ros')
    files = [arg('pose2d_params') or os.path.join(share, 'config', 'pose2d.yaml'),
             arg('fusion_params') or os.path.join(share, 'config', 'fusion.yaml')]
    port = int(arg('foxglove_port') or 0)
    try:
        rig = rig_processes(files, arg('rig') or None,
                            [c for c in arg('cameras').split(',') if c] or None,
                            image_topic=arg('image_topic') or '/{camera}/image_raw',
                            foxglove_port=port if port > 0 else None,
                            use_sim_time=arg('use_sim_time').lower() == 'true', labels=LABELS)
    except PlanError as exc:
        raise RuntimeError(f'mv3dpose.launch.py: {exc}') from exc
    return [Node(**p.launch_kwargs(rig.params_files, rig.common)) for p in rig.processes]


def generate_launch_description():
    """Declare the arguments and the nodes."""
    return LaunchDescription([
        DeclareLaunchArgument('rig', default_value='',
                              description='rig calibration file (empty: fusion_node '
                                          'rig_config of the params files)'),
        DeclareLaunchArgument('cameras', default_value='',
                              description='comma-separated camera ids (empty: fusion_node '
                                          'camera_ids, else all of the rig)'),
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
