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
fusion_node parameters through real rcl argument parsing: files, overrides, launch, bringup.

Each case builds the node from a command line the way a user, ``bringup`` or launch_ros
would pass it (``rclpy.init(args=...)`` parses it with rcl), so the precedence tested is rcl's
own: ``-p``, a second params file, ``bringup --fusion-param`` and launch arguments (written under
``/**``) all override config/fusion.yaml.
"""

import os

from mv3dpose_ros.core.geometry.calibration import save_rig_yaml
from mv3dpose_ros.sim import make_scene
import pytest
import rclpy
import yaml

pytestmark = [pytest.mark.ros]

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
FUSION_YAML = os.path.join(ROOT, 'config', 'fusion.yaml')


@pytest.fixture(scope='module')
def rig(tmp_path_factory):
    scene = make_scene(num_cameras=3, num_people=1, num_frames=2, fps=30.0, seed=1)
    path = str(tmp_path_factory.mktemp('rig') / 'rig.yaml')
    save_rig_yaml(scene.cameras, path, world_frame='rig_world')
    return path


def node_from(args):
    """Build a FusionNode from ``--ros-args ...`` parsed by rcl; return its read-back state."""
    from mv3dpose_ros.nodes.fusion.node import FusionNode
    ctx = rclpy.Context()
    rclpy.init(args=['fusion_node', '--ros-args'] + list(args), context=ctx)
    try:
        node = FusionNode(context=ctx)
        try:
            return {'rig': node.rig_path, 'max_wait': node.sync_config.max_wait_s,
                    'slop': node.sync_config.slop_s, 'frame': node.world_frame,
                    'persons': node.params.limits.max_persons,
                    'coast': node.fusion_config.max_coast_s,
                    'warnings': list(node.config_warnings)}
        finally:
            node.destroy_node()
    finally:
        rclpy.shutdown(context=ctx)


def write(tmp_path, name, doc):
    path = tmp_path / name
    path.write_text(yaml.safe_dump(doc))
    return str(path)


def test_shipped_file_alone_gives_its_values(rig):
    got = node_from(['--params-file', FUSION_YAML, '-p', f'rig_config:={rig}'])
    assert got['rig'] == rig and got['max_wait'] == 0.1 and got['persons'] == 50
    assert got['warnings'] == []


def test_dash_p_overrides_the_shipped_file(rig):
    got = node_from(['--params-file', FUSION_YAML, '-p', f'rig_config:={rig}',
                     '-p', 'sync.max_wait_s:=0.25', '-p', 'fusion.max_coast_s:=2.5',
                     '-p', 'limits.max_persons:=7'])
    assert (got['rig'], got['max_wait'], got['coast'], got['persons']) == (rig, 0.25, 2.5, 7)


@pytest.mark.parametrize('section', ['/**', '/**/fusion_node', 'fusion_node'])
def test_second_params_file_overrides(rig, tmp_path, section):
    over = write(tmp_path, 'over.yaml', {section: {'ros__parameters': {
        'rig_config': rig, 'sync': {'max_wait_s': 0.3}}}})
    got = node_from(['--params-file', FUSION_YAML, '--params-file', over])
    assert got['rig'] == rig and got['max_wait'] == 0.3


def test_launch_arguments_override(rig, tmp_path):
    """launch_ros writes a Node's dict parameters to a temporary file under '/**'."""
    launch_params = write(tmp_path, 'launch_params.yaml', {'/**': {'ros__parameters': {
        'rig_config': rig, 'camera_ids': ['cam_01', 'cam_02'], 'use_sim_time': False}}})
    got = node_from(['--params-file', FUSION_YAML, '--params-file', launch_params])
    assert got['rig'] == rig


def test_bringup_fusion_param_overrides(rig, tmp_path):
    from mv3dpose_ros.nodes.bringup import build_parser, Plan
    args = build_parser().parse_args(['--rig', rig, '--no-pose2d',
                                      '--fusion-param', 'sync.max_wait_s:=0.35',
                                      '--fusion-param', 'sync.slop_s:=0.004'])
    plan = Plan(args)
    override = write(tmp_path, 'bringup_override.yaml', plan.overrides)
    argv = plan.commands(override)['fusion_node']
    got = node_from(argv[argv.index('--ros-args') + 1:])
    assert (got['rig'], got['max_wait'], got['slop']) == (rig, 0.35, 0.004)


def test_unknown_parameter_named_with_the_closest_valid_name(rig):
    got = node_from(['--params-file', FUSION_YAML, '-p', f'rig_config:={rig}',
                     '-p', 'sync.max_wiat_s:=0.2', '-p', 'totally_unrelated_xyz:=1'])
    assert got['max_wait'] == 0.1
    text = '\n'.join(got['warnings'])
    assert "'sync.max_wiat_s'" in text and "did you mean 'sync.max_wait_s'" in text
    assert "'totally_unrelated_xyz' is not a parameter" in text


def test_world_frame_from_the_rig_unless_the_parameter_is_given(rig):
    assert node_from(['--params-file', FUSION_YAML, '-p', f'rig_config:={rig}'])['frame'] == \
        'rig_world'
    assert node_from(['--params-file', FUSION_YAML, '-p', f'rig_config:={rig}',
                      '-p', 'world_frame:=odom'])['frame'] == 'odom'


def test_unknown_rig_key_named_with_the_closest_valid_key(rig, tmp_path):
    doc = yaml.safe_load(open(rig))
    doc['world_fame'] = doc.pop('world_frame')
    cam = next(iter(doc['cameras']))
    doc['cameras'][cam]['distortions'] = doc['cameras'][cam].pop('distortion', [0.0] * 5)
    path = write(tmp_path, 'typo_rig.yaml', doc)
    got = node_from(['--params-file', FUSION_YAML, '-p', f'rig_config:={path}'])
    text = '\n'.join(got['warnings'])
    assert "unknown key 'world_fame' in the rig; did you mean 'world_frame'?" in text
    assert f"unknown key 'distortions' in camera '{cam}'; did you mean 'distortion'?" in text
    assert got['frame'] == 'map'            # the misspelt key was not read


def test_error_message_recommends_an_override_that_works(rig, tmp_path):
    from mv3dpose_ros.nodes.fusion.node import ConfigError
    empty = write(tmp_path, 'empty_rig.yaml', {'/**': {'ros__parameters': {'rig_config': ''}}})
    with pytest.raises(ConfigError, match=r'-p rig_config:=') as info:
        node_from(['--params-file', FUSION_YAML, '--params-file', empty])
    recommended = str(info.value).split('--ros-args ')[1].split(')')[0].split()
    recommended[1] = recommended[1].split(':=')[0] + ':=' + rig
    assert node_from(['--params-file', FUSION_YAML, '--params-file', empty] +
                     recommended)['rig'] == rig
