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
The layout's rule: the algorithm and the 2D stage's logic do not depend on ROS.

``core/`` (the algorithm), ``eval/`` and ``sim/`` import nothing of ROS at all; ``pose2d/``
(models, inference, the inference-rate policy) nothing at module level (``fetch`` reads a
rosbag2 bag's images inside one function, for calibration). The nodes are the adapters.
"""

import ast
import os
import subprocess
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PACKAGE = os.path.join(ROOT, 'mv3dpose_ros')
ROS_FREE = {'core': 'anywhere', 'eval': 'anywhere', 'sim': 'anywhere', 'pose2d': 'module level'}


def _is_ros(module: str) -> bool:
    top = module.split('.')[0]
    return (top in ('rclpy', 'rosidl_runtime_py', 'rosbag2_py', 'builtin_interfaces')
            or top.endswith('_msgs') or top.endswith('_srvs')
            or module.startswith(('mv3dpose_ros.ros', 'mv3dpose_ros.nodes')))


def _ros_imports(path: str, module_level_only: bool):
    tree = ast.parse(open(path).read(), path)
    nodes = tree.body if module_level_only else list(ast.walk(tree))
    for node in nodes:
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            names = [node.module]
        else:
            continue
        for name in names:
            if _is_ros(name):
                yield f'{os.path.relpath(path, ROOT)}:{node.lineno} imports {name}'


@pytest.mark.parametrize('package', sorted(ROS_FREE))
def test_the_algorithm_and_the_2d_logic_import_no_ros(package):
    found = []
    for name in sorted(os.listdir(os.path.join(PACKAGE, package))):
        if name.endswith('.py'):
            found += _ros_imports(os.path.join(PACKAGE, package, name),
                                  ROS_FREE[package] == 'module level')
    assert not found, '\n'.join(found)


def test_the_ros_free_packages_load_without_rclpy():
    """Importing every module of them loads no rclpy (nor any message package)."""
    modules = [f'mv3dpose_ros.{package}.{name[:-3]}' for package in sorted(ROS_FREE)
               for name in sorted(os.listdir(os.path.join(PACKAGE, package)))
               if name.endswith('.py')]
    code = ('import importlib, sys\n'
            f'for m in {modules!r}: importlib.import_module(m)\n'
            "print(sorted(m for m in sys.modules if m.split('.')[0] == 'rclpy'"
            " or m.split('.')[0].endswith('_msgs')))\n")
    out = subprocess.run([sys.executable, '-c', code], cwd=ROOT, capture_output=True,
                         text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip() == '[]', out.stdout
