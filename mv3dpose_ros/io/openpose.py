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
Read (and write) OpenPose JSON detections: one folder per camera, one file per frame.

Each file holds ``{"people": [{"pose_keypoints_2d": [x, y, c, ...]}, ...]}`` in raw image
pixels (OpenPose's own ``--write_json`` output, also what Pose2Sim reads). A joint with
confidence 0 (OpenPose writes ``0, 0, 0``) is missing. Files of different cameras belong to the
same frame when the frame number in their names is equal: the last run of digits of the file
stem, e.g. ``cam01.0042.json`` and ``video_000000000042_keypoints.json`` are both frame 42.

Per camera and frame, a missing file means the camera saw no one (an empty ``[0, J, 3]``
array); a malformed file is reported (file name and reason) and skipped, the camera then
counts as absent for that frame. Nothing here raises on bad file contents. Files are parsed
by ``core.files.load_json`` (size, nesting and number limits; ``NaN``/``Infinity`` are
accepted and make the joint missing, a literal that overflows a double is an error).
"""

from dataclasses import dataclass
import logging
import os
import re
from typing import Dict, Iterator, List, Mapping, Optional, Sequence, Tuple

from mv3dpose_ros.core.files import load_json, LoadError, read_text
import numpy as np

logger = logging.getLogger(__name__)

_KEYS = ('pose_keypoints_2d', 'pose_keypoints')   # the second one: OpenPose < 1.2
#: Largest OpenPose file read [bytes] (100 people x 135 keypoints is ~0.5 MB).
MAX_FILE_BYTES = 16 * 1024 * 1024
#: Largest plausible |x| or |y| [px]; beyond it a file is corrupt.
MAX_COORDINATE = 1e6
#: Confidences up to this are read (and clipped to 1); beyond it a file is corrupt.
MAX_CONFIDENCE = 1.1
_DIGITS = re.compile(r'(\d+)')


class OpenPoseFormatError(ValueError):
    """A file that is not valid OpenPose JSON; the message names the reason."""


@dataclass(frozen=True)
class FileIssue:
    """A file that was skipped, and why."""

    path: str
    reason: str

    def __str__(self) -> str:
        """Return 'path: reason'."""
        return f'{self.path}: {self.reason}'


def frame_number(filename: str) -> Optional[int]:
    """Return the frame number of a file name (last digit run of its stem), or None."""
    stem = os.path.basename(filename)
    if stem.lower().endswith('.json'):
        stem = stem[:-5]
    runs = _DIGITS.findall(stem)
    return int(runs[-1]) if runs else None


def parse_openpose(data: object, num_joints: Optional[int] = None) -> np.ndarray:
    """
    Turn a decoded OpenPose JSON object into ``[P, J, 3]`` (x px, y px, confidence).

    People with an empty keypoint list are dropped (OpenPose writes those); non-finite values
    make the joint missing. Raises :class:`OpenPoseFormatError` naming what is wrong.
    """
    if not isinstance(data, dict):
        raise OpenPoseFormatError(f'top level is {type(data).__name__}, expected an object')
    people = data.get('people')
    if people is None:
        raise OpenPoseFormatError('no "people" list')
    if not isinstance(people, list):
        raise OpenPoseFormatError(f'"people" is {type(people).__name__}, expected a list')
    poses = []
    for k, person in enumerate(people):
        if not isinstance(person, dict):
            raise OpenPoseFormatError(f'people[{k}] is {type(person).__name__}, not an object')
        key = next((key for key in _KEYS if key in person), None)
        if key is None:
            raise OpenPoseFormatError(f'people[{k}] has no "pose_keypoints_2d"')
        values = person[key]
        if not isinstance(values, list):
            raise OpenPoseFormatError(f'people[{k}].{key} is not a list')
        if not values:
            continue
        if len(values) % 3:
            raise OpenPoseFormatError(
                f'people[{k}].{key} has {len(values)} values, not a multiple of 3 (x, y, c)')
        if num_joints is not None and len(values) != 3 * num_joints:
            raise OpenPoseFormatError(
                f'people[{k}].{key} has {len(values) // 3} joints, the layout has {num_joints}')
        if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values):
            raise OpenPoseFormatError(f'people[{k}].{key} holds non-numeric values')
        poses.append(values)
    if not poses:
        return np.zeros((0, num_joints or 0, 3))
    lengths = {len(p) for p in poses}
    if len(lengths) > 1:
        raise OpenPoseFormatError(f'people have different joint counts: '
                                  f'{sorted(n // 3 for n in lengths)}')
    arr = np.asarray(poses, dtype=float).reshape(len(poses), -1, 3)
    finite = np.isfinite(arr).all(-1)
    far = finite & (np.abs(arr[..., :2]) > MAX_COORDINATE).any(-1)
    if far.any():
        k, j = np.argwhere(far)[0]
        raise OpenPoseFormatError(f'people[{k}] keypoint {j} at ({arr[k, j, 0]:.3g}, '
                                  f'{arr[k, j, 1]:.3g}) px, beyond +-{MAX_COORDINATE:g}')
    over = finite & (arr[..., 2] > MAX_CONFIDENCE)
    if over.any():
        k, j = np.argwhere(over)[0]
        raise OpenPoseFormatError(f'people[{k}] keypoint {j} has confidence {arr[k, j, 2]:.3g}, '
                                  f'beyond [0, 1]')
    arr[..., 2] = np.minimum(arr[..., 2], 1.0)    # heatmap peaks may exceed 1 a little
    bad = ~finite | (arr[..., 2] <= 0)
    arr[bad] = 0.0
    return arr


def _read(path: str, num_joints: Optional[int]) -> np.ndarray:
    """Read one file; OpenPoseFormatError carries the reason only."""
    try:
        data = load_json(read_text(path, MAX_FILE_BYTES), allow_nan=True)  # NaN -> missing
    except OSError as e:
        raise OpenPoseFormatError(f'cannot read ({e.strerror or e})') from None
    except LoadError as e:
        raise OpenPoseFormatError(str(e)) from None
    return parse_openpose(data, num_joints)


def read_openpose_file(path: str, num_joints: Optional[int] = None) -> np.ndarray:
    """Read one OpenPose JSON file as ``[P, J, 3]``; OpenPoseFormatError names path and reason."""
    try:
        return _read(path, num_joints)
    except OpenPoseFormatError as e:
        raise OpenPoseFormatError(f'{path}: {e}') from None


def openpose_filename(camera: str, frame: int) -> str:
    """Return OpenPose's file name of a frame: ``<camera>_<frame:012d>_keypoints.json``."""
    return f'{camera}_{int(frame):012d}_keypoints.json'


def write_openpose_file(path: str, poses: np.ndarray, decimals: int = 3) -> None:
    """
    Write ``[P, J, 3]`` poses (x, y, confidence) as one OpenPose JSON file, as OpenPose does.

    Missing joints (confidence 0) are written ``0, 0, 0``; the file is written to a temporary
    name and renamed, so a reader never sees half a file.
    """
    import json
    people = []
    for pose in np.asarray(poses, dtype=np.float64):
        pose = np.where(pose[:, 2:3] > 0, pose, 0.0)
        people.append({'person_id': [-1], 'pose_keypoints_2d': [
            round(float(v), decimals) for v in pose.ravel()]})
    tmp = f'{path}.tmp'
    with open(tmp, 'w', encoding='utf-8') as f:
        json.dump({'version': 1.3, 'people': people}, f, separators=(',', ':'))
    os.replace(tmp, path)


def index_folder(folder: str, issues: Optional[List[FileIssue]] = None) -> Dict[int, str]:
    """
    Map frame number -> file path for the ``*.json`` files of ``folder``.

    Files without a frame number, and the second of two files with the same number, are
    reported in ``issues`` and left out.
    """
    issues = issues if issues is not None else []
    out: Dict[int, str] = {}
    for name in sorted(os.listdir(folder)):
        if not name.lower().endswith('.json'):
            continue
        path = os.path.join(folder, name)
        if not os.path.isfile(path):
            continue
        n = frame_number(name)
        if n is None:
            issues.append(FileIssue(path, 'no frame number in the file name'))
        elif n in out:
            issues.append(FileIssue(path, f'frame {n} already read from '
                                          f'{os.path.basename(out[n])}'))
        else:
            out[n] = path
    return out


class OpenPoseSequence:
    """
    Frames of OpenPose detections from several cameras, matched by frame number.

    ``folders`` maps camera name -> folder. Iterating yields ``(frame, views)`` for every frame
    number found in any folder, in increasing order, where ``views`` maps camera name ->
    ``[P, J, 3]`` (empty for a missing file; malformed files leave the camera out and are
    appended to :attr:`issues` and logged).
    """

    def __init__(self, folders: Mapping[str, str], num_joints: Optional[int] = None):
        """Index the folders (only file names are read here)."""
        self.num_joints = num_joints
        self.issues: List[FileIssue] = []
        self.files: Dict[str, Dict[int, str]] = {}
        for cam, folder in folders.items():
            if not os.path.isdir(folder):
                raise FileNotFoundError(f'camera {cam!r}: folder {folder} does not exist')
            self.files[cam] = index_folder(folder, self.issues)
        for issue in self.issues:
            logger.warning('skipped %s', issue)
        self.frames: List[int] = sorted(set().union(*(f.keys() for f in self.files.values())))

    def __len__(self) -> int:
        """Return the number of frames."""
        return len(self.frames)

    def read(self, frame: int) -> Dict[str, np.ndarray]:
        """Return the views of one frame number."""
        views: Dict[str, np.ndarray] = {}
        for cam, files in self.files.items():
            path = files.get(frame)
            if path is None:
                views[cam] = np.zeros((0, self.num_joints or 0, 3))
                continue
            try:
                views[cam] = _read(path, self.num_joints)
            except OpenPoseFormatError as e:
                issue = FileIssue(path, str(e))
                self.issues.append(issue)
                logger.warning('skipped %s', issue)
        return views

    def __iter__(self) -> Iterator[Tuple[int, Dict[str, np.ndarray]]]:
        """Yield ``(frame, views)`` in frame order."""
        for frame in self.frames:
            yield frame, self.read(frame)


def _normalise(name: str) -> str:
    """Reduce a camera or folder name to a comparable key: 'cam01_json' == 'Cam_1' -> 'cam1'."""
    name = name.lower()
    for suffix in ('_json', '-json', '.json', '_openpose', '_pose'):
        if name.endswith(suffix):
            name = name[:-len(suffix)]
    name = re.sub(r'[^a-z0-9]', '', name)
    return re.sub(r'\d+', lambda m: str(int(m.group())), name)


def _number(name: str) -> Optional[int]:
    """Return the single number in a camera or folder name, or None if it has none or several."""
    numbers = re.findall(r'\d+', _normalise(name))
    return int(numbers[0]) if len(numbers) == 1 else None


def match_camera_names(cameras: Sequence[str], entries: Mapping[str, str], where: str = '',
                       what: str = 'folders') -> Tuple[Dict[str, str], List[str]]:
    """
    Match each camera to the entry (a folder, a video file) named like it.

    ``entries`` maps each entry's label (its file name, shown in messages) to the name compared
    with the cameras (a folder's name, a video's stem). An entry named exactly like the camera
    wins; otherwise names are compared loosely, so Pose2Sim's ``cam01_json`` or ``cam01.mp4``
    is camera ``cam_01``, and last by their one number, so ``Camera0`` is camera ``0`` of a
    VoxelPose calibration. Returns ``(camera -> label, cameras without an entry)``. A camera
    that fits several entries, or an entry that fits several cameras, raises ValueError naming
    them (``what`` names the entries in that message, ``where`` their folder).
    """
    place = f' in {where}' if where else ''
    labels = sorted(entries)
    found: Dict[str, str] = {}
    missing: List[str] = []
    for cam in cameras:
        cands = [e for e in labels if entries[e] == cam]
        if not cands:
            key = _normalise(cam)
            cands = [e for e in labels if _normalise(entries[e]) == key]
        if not cands and _number(cam) is not None:
            # Numbered cameras ('0' in VoxelPose files) and folders like 'Camera0', 'c0_json'.
            cands = [e for e in labels if _number(entries[e]) == _number(cam)]
        if len(cands) > 1:
            raise ValueError(f'camera {cam!r} matches several {what}{place}: '
                             f'{", ".join(cands)}; rename them or pass --cameras')
        if cands:
            found[cam] = cands[0]
        else:
            missing.append(cam)
    users: Dict[str, List[str]] = {}
    for cam, label in found.items():
        users.setdefault(label, []).append(cam)
    clash = {label: cams for label, cams in users.items() if len(cams) > 1}
    if clash:
        raise ValueError(f'one of the {what}{place} matches several cameras: ' + '; '.join(
            f'{label} <- {", ".join(cams)}' for label, cams in clash.items()))
    return found, missing


def match_camera_folders(root: str, cameras: Sequence[str]) -> Tuple[Dict[str, str], List[str]]:
    """
    Find the folder of each camera under ``root`` (names matched by ``match_camera_names``).

    Returns ``(camera -> folder, messages)`` where messages name cameras without a folder;
    ambiguous matches raise ValueError listing the candidates.
    """
    if not os.path.isdir(root):
        raise FileNotFoundError(f'poses root {root} is not a folder')
    subdirs = sorted(d for d in os.listdir(root) if os.path.isdir(os.path.join(root, d)))
    found, missing = match_camera_names(cameras, {d: d for d in subdirs}, root)
    return ({cam: os.path.join(root, d) for cam, d in found.items()},
            [f'camera {cam!r}: no folder in {root} (have: {", ".join(subdirs) or "none"})'
             for cam in missing])
