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
Package metadata against the code: what ``mv3dpose_ros/`` and ``launch/`` import.

- every third-party module imported has its rosdep key in ``package.xml`` and every
  ``exec_depend`` is imported somewhere (no missing, no stale dependency);
- a module the wheels lack (launch, launch_ros, tf2_ros) is imported only where that is allowed:
  launch files, or behind ``except ImportError``;
- every other module comes from a distribution pinned in ``requirements.txt`` (so ``make setup``
  installs it), found with ``importlib.metadata.packages_distributions``;
- each ``-pip`` key is defined in ``rosdep.yaml`` with the same PyPI distribution;
- the console scripts have collision-proof names, and the old names remain as aliases.
"""

import ast
import glob
from importlib.metadata import packages_distributions
import json
import os
import re
import subprocess
import sys
import xml.etree.ElementTree as ET

import pytest
import yaml

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

# import name -> rosdep key. A new third-party import needs a line here and in package.xml.
MODULE_KEYS = {
    'ament_index_python': 'ament_index_python',
    'builtin_interfaces': 'builtin_interfaces',
    'cv2': 'python3-opencv',
    'diagnostic_msgs': 'diagnostic_msgs',
    'foxglove': 'python3-foxglove-sdk-pip',
    'geometry_msgs': 'geometry_msgs',
    'google': 'python3-protobuf',
    'launch': 'launch',
    'launch_ros': 'launch_ros',
    'motmetrics': 'python3-motmetrics-pip',
    'mv3dpose_msgs': 'mv3dpose_msgs',
    'numpy': 'python3-numpy',
    'onnx': 'python3-onnx-pip',          # int8 quantisation in pose2d/fetch.py
    'onnxruntime': 'python3-onnxruntime-pip',
    'rcl_interfaces': 'rcl_interfaces',
    'rclpy': 'rclpy',
    'rosbags': 'python3-rosbags-pip',
    'rosgraph_msgs': 'rosgraph_msgs',
    'scipy': 'python3-scipy',
    'sensor_msgs': 'sensor_msgs',
    'std_msgs': 'std_msgs',
    'std_srvs': 'std_srvs',
    'tf2_ros': 'tf2_ros_py',
    'tqdm': 'python3-tqdm',
    'visualization_msgs': 'visualization_msgs',
    'websockets': 'python3-websockets',
    'yaml': 'python3-yaml',
}
# Not in the ros-jazzy-* wheels: allowed in launch files, elsewhere only behind ImportError.
FULL_INSTALL_ONLY = {'launch', 'launch_ros', 'tf2_ros'}


def _sources():
    for base in ('mv3dpose_ros', 'launch'):
        for folder, _, files in os.walk(os.path.join(ROOT, base)):
            for name in sorted(files):
                if name.endswith('.py'):
                    yield os.path.join(folder, name)


def _guarded_lines(tree):
    """Return the line numbers of imports inside a ``try`` that catches ImportError."""
    lines = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Try) and any(
                isinstance(h.type, ast.Name) and h.type.id in ('ImportError',
                                                               'ModuleNotFoundError')
                for h in node.handlers):
            for stmt in node.body:
                for sub in ast.walk(stmt):
                    if isinstance(sub, (ast.Import, ast.ImportFrom)):
                        lines.add(sub.lineno)
    return lines


def third_party_imports():
    """Return {module: [(path, line, guarded)]} of the top-level third-party imports."""
    found = {}
    for path in _sources():
        tree = ast.parse(open(path, encoding='utf-8').read(), path)
        guarded = _guarded_lines(tree)
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
            else:
                continue
            for name in names:
                top = name.split('.')[0]
                if top in sys.stdlib_module_names or top == 'mv3dpose_ros':
                    continue
                found.setdefault(top, []).append((os.path.relpath(path, ROOT), node.lineno,
                                                  node.lineno in guarded))
    return found


def exec_depends():
    root = ET.parse(os.path.join(ROOT, 'package.xml')).getroot()
    keys = [e.text.strip() for e in root.iter() if e.tag in ('exec_depend', 'depend')]
    assert len(keys) == len(set(keys)), 'duplicate dependencies in package.xml'
    return set(keys)


def pinned():
    out = {}
    for line in open(os.path.join(ROOT, 'requirements.txt')):
        m = re.match(r'^([A-Za-z0-9_.\-]+)==(\S+)', line.strip())
        if m:
            out[re.sub(r'[-_.]+', '-', m.group(1)).lower()] = m.group(2)
    return out


def _norm(dist):
    return re.sub(r'[-_.]+', '-', dist).lower()


IMPORTS = third_party_imports()


def test_every_import_has_its_key_in_package_xml_and_no_key_is_stale():
    unknown = {m: where[:2] for m, where in IMPORTS.items() if m not in MODULE_KEYS}
    assert not unknown, f'imports without a known rosdep key (add to MODULE_KEYS and ' \
        f'package.xml): {unknown}'
    needed = {MODULE_KEYS[m] for m in IMPORTS}
    declared = exec_depends()
    assert not needed - declared, f'missing from package.xml: {sorted(needed - declared)}'
    assert not declared - needed, f'declared but never imported: {sorted(declared - needed)}'


def test_full_install_only_modules_are_optional_outside_launch_files():
    bad = [(m, path, line) for m in FULL_INSTALL_ONLY for path, line, guarded in
           IMPORTS.get(m, []) if not guarded and not path.startswith('launch' + os.sep)]
    assert not bad, f'imported unguarded where the PyPI wheels lack them: {bad}'
    assert any(g for _, _, g in IMPORTS['tf2_ros']), 'tf2_ros must stay optional'


def test_imports_come_from_pinned_distributions():
    dists = packages_distributions()
    pins = pinned()
    missing = {}
    for module in IMPORTS:
        if module in FULL_INSTALL_ONLY or module == 'mv3dpose_msgs':   # built by colcon
            continue
        providers = {_norm(d) for d in dists.get(module, [])}
        if not providers & set(pins):
            missing[module] = sorted(providers) or 'not installed'
    assert not missing, f'imported but not pinned in requirements.txt: {missing}'


def test_pip_keys_are_defined_in_rosdep_yaml_with_the_pinned_distribution():
    rules = yaml.safe_load(open(os.path.join(ROOT, 'rosdep.yaml')))
    pip_keys = {k for k in exec_depends() if k.endswith('-pip')}
    assert pip_keys == set(rules), 'rosdep.yaml must define exactly the -pip keys'
    dists = packages_distributions()
    pins = pinned()
    for module, key in MODULE_KEYS.items():
        if key not in pip_keys:
            continue
        for platform in ('debian', 'ubuntu'):
            [package] = rules[key][platform]['pip']['packages']
            assert _norm(package) in pins, f'{key}: {package} is not pinned'
            assert _norm(package) in {_norm(d) for d in dists.get(module, [])}, \
                f'{key}: {package} does not provide the module {module}'


@pytest.mark.parametrize('new, old', [('mv3dpose_bringup', 'bringup'),
                                      ('mv3dpose_image_publisher', 'image_publisher')])
def test_console_scripts_have_unique_names_and_deprecated_aliases(new, old):
    """The installed scripts run; the old name still works and says which name to use."""
    res = subprocess.run([new, '--help'], capture_output=True, text=True, timeout=60)
    assert res.returncode == 0 and 'usage:' in res.stdout, res.stderr
    res = subprocess.run([old, '--help'], capture_output=True, text=True, timeout=60)
    assert res.returncode == 0 and 'usage:' in res.stdout, res.stderr
    assert f'{old}: this name is deprecated and will be removed in 0.2.0; use {new}' in \
        res.stderr


def test_shipped_viewer_configs_name_the_published_topics_and_are_installed():
    """config/mv3dpose.rviz and config/mv3dpose.foxglove.json show what the nodes publish."""
    from mv3dpose_ros.nodes.foxglove_view import CAMERAS_TOPIC, SCENE_TOPIC
    rviz = yaml.safe_load(open(os.path.join(ROOT, 'config', 'mv3dpose.rviz')))
    manager = rviz['Visualization Manager']
    # the frame of the shipped rigs (fusion_node's world_frame defaults to the rig's)
    rig_frames = {yaml.safe_load(open(p)).get('world_frame') for p in
                  glob.glob(os.path.join(ROOT, 'config', 'rigs', '*.yaml'))} - {None}
    assert rig_frames == {'world'}
    assert manager['Global Options']['Fixed Frame'] == 'world'
    topics = {d['Class'].split('/')[-1]: d['Topic']['Value']
              for d in manager['Displays'] if 'Topic' in d}
    assert topics == {'MarkerArray': '/fusion_node/markers', 'PoseArray': '/fusion_node/poses'}
    layout = json.load(open(os.path.join(ROOT, 'config', 'mv3dpose.foxglove.json')))
    panels = layout['configById']
    three_d = next(v for k, v in panels.items() if k.startswith('3D!'))
    # no frame named: Foxglove's display frame is then the scene's own (the rig's world_frame,
    # 'world' in the shipped rigs, 'map' where a rig names none), and the grid lies in it
    assert 'followTf' not in three_d and 'frameId' not in three_d['layers']['grid']
    visible = {t for t, c in three_d['topics'].items() if c['visible']}
    assert {SCENE_TOPIC, CAMERAS_TOPIC} <= visible
    paths = [p['value'] for k, v in panels.items() if k.startswith('Plot!') for p in v['paths']]
    paths += [v['topicPath'] for k, v in panels.items() if k.startswith('RawMessages!')]
    assert paths and all(p.startswith('/fusion_node/tracks.skeletons') for p in paths)

    def leaves(node):
        return [node] if isinstance(node, str) else leaves(node['first']) + \
            leaves(node['second'])
    assert sorted(leaves(layout['layout'])) == sorted(panels)
    share = os.path.join(ROOT, 'install', 'mv3dpose_ros', 'share', 'mv3dpose_ros', 'config')
    if not os.path.isdir(share):
        pytest.skip('package not built (make setup)')
    for name in ('mv3dpose.rviz', 'mv3dpose.foxglove.json'):
        assert os.path.isfile(os.path.join(share, name)), f'{name} not installed'
