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

"""The one camera-name -> ROS-name mapping (ros/names.py) and topic pattern checks."""

from mv3dpose_ros.ros.names import camera_namespace, camera_topic, check_pattern, image_topic
from mv3dpose_ros.ros.names import persons_topic, RosNameError, topic_problem
import pytest
from rclpy.validate_full_topic_name import validate_full_topic_name


@pytest.mark.parametrize('camera, expected', [
    ('cam0', 'cam0'), ('cam_01', 'cam_01'), ('00_03', 'cam00_03'), ('0', 'cam0'),
    ('Camera 1', 'Camera_1'), ('1-left', 'cam1_left'), ('a__b', 'a_b'), ('_x', 'cam_x')])
def test_camera_namespace_is_a_valid_ros_token(camera, expected):
    assert camera_namespace(camera) == expected
    validate_full_topic_name(f'/{camera_namespace(camera)}/image_raw')   # raises if invalid


def test_patterns_and_converters_share_the_mapping():
    assert camera_topic('/{camera}/image_raw', '00_03') == '/cam00_03/image_raw'
    assert image_topic('00_03') == camera_topic('/{camera}/image_raw', '00_03')
    assert persons_topic('cam0') == '/cam0/persons_2d'


@pytest.mark.parametrize('name, why', [
    ('/a/0b', 'starts with a digit'), ('/a//b', 'empty token'), ('/a/', 'ends with /'),
    ('/a-b', "contains '-'"), ('/a__b', "'__'"), ('', 'empty')])
def test_topic_problem_names_the_reason(name, why):
    assert why in topic_problem(name)


def test_check_pattern():
    check_pattern('/{camera}/image_raw', ['00_03', 'cam1'], '--image-topic')
    with pytest.raises(RosNameError, match='has no {camera}: all 2 cameras'):
        check_pattern('/image_raw', ['a', 'b'], '--image-topic')
    with pytest.raises(RosNameError, match="--image-topic '/{camera}/im-age'.*contains '-'"):
        check_pattern('/{camera}/im-age', ['a'], '--image-topic')
    with pytest.raises(RosNameError, match='same name'):
        check_pattern('/{camera}/image', ['a b', 'a-b'], '--namespace')
