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


"""OpenPose JSON folders: parsing, frame matching across cameras, malformed files, folder names."""

import json
import os

from mv3dpose_ros.io.openpose import (frame_number, match_camera_folders, OpenPoseFormatError,
                                      OpenPoseSequence, read_openpose_file)
import numpy as np
import pytest


def write(path, obj):
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, 'w') as f:
        f.write(obj if isinstance(obj, str) else json.dumps(obj))


def person(x: float, j: int = 3):
    kp = []
    for k in range(j):
        kp += [x + k, 10.0 * k, 0.9]
    return {'person_id': [-1], 'pose_keypoints_2d': kp}


def test_frame_number_from_common_names():
    assert frame_number('cam01.0042.json') == 42
    assert frame_number('video_000000000042_keypoints.json') == 42
    assert frame_number('/a/b/c3_7.json') == 7
    assert frame_number('keypoints.json') is None


def test_read_file_shapes_and_missing_joints(tmp_path):
    p = str(tmp_path / 'a_0001.json')
    data = {'version': 1.3, 'people': [person(1.0), person(50.0), {'pose_keypoints_2d': []}]}
    data['people'][1]['pose_keypoints_2d'][3:6] = [0, 0, 0]
    write(p, data)
    poses = read_openpose_file(p, num_joints=3)
    assert poses.shape == (2, 3, 3)                 # the empty person is dropped
    np.testing.assert_allclose(poses[0, 1], [2.0, 10.0, 0.9])
    assert poses[1, 1, 2] == 0.0                    # confidence 0 = missing
    write(p, '{"people": [{"pose_keypoints_2d": [1, 2, NaN, 3, 4, 0.5, 5, 6, 0.5]}]}')
    assert read_openpose_file(p)[0, 0, 2] == 0.0    # NaN makes the joint missing
    write(p, {'people': []})
    assert read_openpose_file(p, num_joints=25).shape == (0, 25, 3)


@pytest.mark.parametrize('content,reason', [
    ('{"people": [', 'invalid JSON'),
    ('[1, 2]', 'top level is list'),
    ('{"version": 1}', 'no "people"'),
    ('{"people": {}}', '"people" is dict'),
    ('{"people": [{"face_keypoints_2d": []}]}', 'no "pose_keypoints_2d"'),
    ('{"people": [{"pose_keypoints_2d": [1, 2]}]}', 'not a multiple of 3'),
    ('{"people": [{"pose_keypoints_2d": [1, 2, 1]}]}', 'the layout has 3'),
    ('{"people": [{"pose_keypoints_2d": [1, "a", 1, 1, 1, 1, 1, 1, 1]}]}', 'non-numeric'),
    (b'\xff\xfe\x00', 'not UTF-8'),
    # huge numbers and deep nesting: named, never an OverflowError / RecursionError traceback
    ('{"people": [{"pose_keypoints_2d": [' + '9' * 400 + ', 1, 1, 1, 1, 1, 1, 1, 1]}]}',
     'integer with 400 digits'),
    ('{"people": [{"pose_keypoints_2d": ' + '[' * 3000 + ']' * 3000 + '}]}', 'nesting'),
    ('{"people": [{"pose_keypoints_2d": [1e400, 1, 1, 1, 1, 1, 1, 1, 1]}]}', 'out of range'),
    ('{"people": [{"pose_keypoints_2d": [1e300, 1, 1, 1, 1, 1, 1, 1, 1]}]}', 'beyond'),
])
def test_malformed_files_name_file_and_reason(tmp_path, content, reason):
    p = tmp_path / 'c_0003.json'
    if isinstance(content, bytes):
        p.write_bytes(content)
    else:
        p.write_text(content)
    with pytest.raises(OpenPoseFormatError) as e:
        read_openpose_file(str(p), num_joints=3)
    assert str(p) in str(e.value) and reason in str(e.value)


def test_sequence_matches_frames_and_skips_bad_files(tmp_path):
    root = str(tmp_path)
    write(f'{root}/a/a.0000.json', {'people': [person(1)]})
    write(f'{root}/a/a.0001.json', {'people': [person(1), person(9)]})
    write(f'{root}/a/a.0002.json', '{"people": [')                 # malformed
    write(f'{root}/a/notes.txt', 'ignored')
    write(f'{root}/b/b_000000000001_keypoints.json', {'people': [person(2)]})
    write(f'{root}/b/b_000000000002_keypoints.json', {'people': [person(3)]})
    write(f'{root}/b/b_0000000002.json', {'people': []})            # duplicate frame 2
    write(f'{root}/b/nonumber.json', {'people': []})
    seq = OpenPoseSequence({'A': f'{root}/a', 'B': f'{root}/b'}, num_joints=3)
    assert seq.frames == [0, 1, 2] and len(seq) == 3
    assert len(seq.issues) == 2                                      # duplicate + no number
    frames = dict(iter(seq))
    assert frames[0]['A'].shape == (1, 3, 3)
    assert frames[0]['B'].shape == (0, 3, 3)                         # missing file: empty
    assert frames[1]['A'].shape == (2, 3, 3) and frames[1]['B'].shape == (1, 3, 3)
    assert 'A' not in frames[2]                                      # malformed: camera absent
    assert frames[2]['B'][0, 0, 0] == 3.0
    bad = [i for i in seq.issues if i.path.endswith('a.0002.json')]
    assert len(bad) == 1 and 'invalid JSON' in bad[0].reason
    with pytest.raises(FileNotFoundError):
        OpenPoseSequence({'C': f'{root}/nope'})


def test_camera_folder_matching(tmp_path):
    for d in ('cam01_json', 'cam02_json', 'cam_03', 'other'):
        os.makedirs(tmp_path / d)
    found, missing = match_camera_folders(str(tmp_path), ['cam_01', 'cam_02', 'cam_03', 'cam_9'])
    assert {k: os.path.basename(v) for k, v in found.items()} == {
        'cam_01': 'cam01_json', 'cam_02': 'cam02_json', 'cam_03': 'cam_03'}
    assert len(missing) == 1 and 'cam_9' in missing[0]
    os.makedirs(tmp_path / 'cam1')                     # now cam01_json and cam1 both fit cam_01
    with pytest.raises(ValueError, match='several folders'):
        match_camera_folders(str(tmp_path), ['cam_01'])


def test_real_pose2sim_detections(shared_data):
    root = os.path.join(shared_data, 'pose2sim_multiperson', 'pose')
    found, missing = match_camera_folders(root, ['cam_01', 'cam_02', 'cam_03', 'cam_04'])
    assert not missing
    seq = OpenPoseSequence(found, num_joints=25)
    assert len(seq) == 100 and not seq.issues
    _, views = next(iter(seq))
    assert set(views) == set(found)
    assert all(v.shape[1:] == (25, 3) for v in views.values())
    assert not seq.issues


def test_numbered_cameras_match_folders_by_their_number(tmp_path):
    for name in ('Camera0', 'Camera1', 'Camera2', 'notes'):
        (tmp_path / name).mkdir()
    found, missing = match_camera_folders(str(tmp_path), ['0', '1', '2', '3'])
    assert {cam: os.path.basename(f) for cam, f in found.items()} == {
        '0': 'Camera0', '1': 'Camera1', '2': 'Camera2'}
    assert len(missing) == 1 and "camera '3'" in missing[0]
