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

"""ROS 2 params files read without rclpy: node keys, namespaces, and bounded loading."""

import os

from mv3dpose_ros.io.params_file import (first_section_with, node_parameters,
                                         parameter_sections, ParamsFileError, read_params_file)
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

TWO_NODES = """
/**:
  ros__parameters:
    use_sim_time: false
/**/fusion_node:
  ros__parameters:
    fusion: {tracking_gate_m: 0.3}
robots:
  fusion_node:
    ros__parameters:
      fusion: {tracking_gate_m: 0.5}
"""


def test_sections_are_read_in_file_order_with_their_node_keys(tmp_path):
    path = tmp_path / 'p.yaml'
    path.write_text(TWO_NODES)
    doc = read_params_file(str(path))
    assert [keys for keys, _ in parameter_sections(doc)] == [
        ('/**',), ('/**/fusion_node',), ('robots', 'fusion_node')]
    assert first_section_with(doc, 'fusion') == {'tracking_gate_m': 0.3}     # the first one
    assert first_section_with({'robots': doc['robots']}, 'fusion') == {'tracking_gate_m': 0.5}
    assert first_section_with(doc, 'sync') is None
    assert first_section_with({'tracking_gate_m': 0.3}, 'fusion') is None    # a flat mapping


def test_a_node_gets_every_section_that_names_it_later_ones_winning(tmp_path):
    first = {'/**': {'ros__parameters': {'a': 1, 'b': 1}},
             '/**/fusion_node/': {'ros__parameters': {'b': 2}},
             'pose2d_node': {'ros__parameters': {'a': 9}},
             'robots': {'fusion_node': {'ros__parameters': {'a': 9}}}}    # under a namespace
    second = {'/fusion_node': {'ros__parameters': {'c': 3}}, 'fusion_node': {}}
    assert node_parameters([first, second], 'fusion_node') == {'a': 1, 'b': 2, 'c': 3}
    assert node_parameters([first, None], 'pose2d_node') == {'a': 9, 'b': 1}


def test_the_shipped_fusion_file_has_its_sections_under_every_node():
    doc = read_params_file(os.path.join(ROOT, 'config', 'fusion.yaml'))
    assert first_section_with(doc, 'sync')['max_wait_s'] > 0
    assert first_section_with(doc, 'fusion') is not None


def test_bad_files_are_named(tmp_path):
    path = tmp_path / 'bad.yaml'
    path.write_text('/**:\n  ros__parameters: [\n')
    with pytest.raises(ParamsFileError, match=r'bad\.yaml: invalid YAML'):
        read_params_file(str(path))
    path.write_text('a: ' + 'x' * 100 + '\n')
    with pytest.raises(ParamsFileError, match='larger than 64 bytes'):
        read_params_file(str(path), max_bytes=64)
    path.write_bytes(b'a: \xff\n')
    with pytest.raises(ValueError, match='not UTF-8'):
        read_params_file(str(path))
    with pytest.raises(OSError):
        read_params_file(str(tmp_path / 'missing.yaml'))
