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
Calibration readers: every format becomes ``{name: Camera}`` in metres with the world z up.

Formats (``load_calibration(path, fmt='auto')`` picks one by extension and content):

- ``rig``: the project's rig YAML (schema below).
- ``panoptic``: CMU Panoptic JSON (``cameras``: name, type, resolution, K, distCoef, R, t in cm).
  Panoptic's world is in centimetres with y pointing down; it is turned into our z-up metre
  world by ``X_ours = PANOPTIC_TO_WORLD @ X_panoptic / 100`` (a +90 degree rotation about x:
  (x, y, z) -> (x, z, -y)), so its floor (y = 0) becomes z = 0. ``io.datasets`` applies the
  same transform to the Panoptic ground truth. Only HD cameras are read unless
  ``camera_types`` says otherwise.
- ``voxelpose``: Shelf/Campus JSON as used by VoxelPose (per camera ``R``, ``T`` = camera
  centre in mm, ``fx fy cx cy``, ``k`` (3 radial), ``p`` (2 tangential)); its world is already
  z up. The files carry no image size: it is taken from ``image_size``, else from
  ``width``/``height`` fields, else from the dataset named in the file name (campus: 360x288,
  shelf: 1032x776).
- ``pose2sim``: Pose2Sim/anipose TOML (one table per camera: ``size``, ``matrix``,
  ``distortions`` k1 k2 p1 p2, ``rotation`` Rodrigues world->camera, ``translation`` m,
  ``fisheye`` must be false); world z up.
- ``camera_info``: a camera_info_manager YAML (intrinsics only), read as one camera with the
  identity pose (camera frame = world frame); rigs reference such files for their intrinsics.

Rig YAML schema (``save_rig_yaml`` writes it, ``load_calibration`` reads it)::

    format: mv3dpose_rig        # optional marker (auto-detection also accepts 'cameras:')
    version: 1
    world_frame: world          # optional frame id of the world (REP-103: z up, metres)
    cameras:
      cam0:                     # camera name = the name used by topics and pose folders
        image_width: 1920
        image_height: 1080
        K: [fx, fy, cx, cy]     # or a 3x3 nested list, or 9 numbers row-major
        distortion_model: plumb_bob    # only plumb_bob (OpenCV k1 k2 p1 p2 k3) is supported
        distortion: [k1, k2, p1, p2, k3]   # 4 or 5 values; omit for none
        T_world_cam:            # pose of the camera's optical frame (x right, y down,
          translation: [x, y, z]      #   z forward) in the world: camera centre, metres
          rotation: [qx, qy, qz, qw]  #   quaternion xyzw, camera -> world
        intrinsics_file: cam0.yaml    # optional camera_info_manager YAML, relative to the
                                      # rig file; gives K, distortion and image size, and
                                      # fields written inline override it

Every error is a ``CalibrationError`` naming the file, the camera and the field. Files are
parsed by ``core.files`` (size, nesting, number and YAML alias limits) and every value is
range-checked by ``Camera``.
"""

import difflib
import os
import re
from typing import Any, Dict, Iterable, List, Mapping, Optional, Sequence, Tuple

import cv2
from mv3dpose_ros.core.files import atomic_path, load_json, load_toml, load_yaml, LoadError
from mv3dpose_ros.core.files import read_text
from mv3dpose_ros.core.geometry.camera import CalibrationError, Camera
import numpy as np
import yaml

#: Rotation taking Panoptic's y-down world to our z-up world: (x, y, z) -> (x, z, -y).
PANOPTIC_TO_WORLD = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
#: Panoptic lengths are centimetres.
PANOPTIC_SCALE = 0.01

FORMATS = ('rig', 'panoptic', 'voxelpose', 'pose2sim', 'camera_info')

#: Image sizes of the VoxelPose datasets, whose calibration files do not carry them.
VOXELPOSE_IMAGE_SIZES = {'campus': (360, 288), 'shelf': (1032, 776)}


# ---------------------------------------------------------------------------- quaternions
def quaternion_to_matrix(q: Sequence[float]) -> np.ndarray:
    """Return the rotation matrix of a unit quaternion (x, y, z, w)."""
    x, y, z, w = np.asarray(q, dtype=float) / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def matrix_to_quaternion(R: np.ndarray) -> np.ndarray:  # noqa: N803
    """Return the unit quaternion (x, y, z, w), w >= 0, of a rotation matrix."""
    R = np.asarray(R, dtype=float)
    # Shepperd's method: pivot on the largest of w, x, y, z for numerical stability.
    diag = np.array([np.trace(R), R[0, 0], R[1, 1], R[2, 2]])
    i = int(np.argmax(diag))
    if i == 0:
        w = 0.5 * np.sqrt(1 + diag[0])
        q = [(R[2, 1] - R[1, 2]) / (4 * w), (R[0, 2] - R[2, 0]) / (4 * w),
             (R[1, 0] - R[0, 1]) / (4 * w), w]
    elif i == 1:
        x = 0.5 * np.sqrt(1 + R[0, 0] - R[1, 1] - R[2, 2])
        q = [x, (R[0, 1] + R[1, 0]) / (4 * x), (R[0, 2] + R[2, 0]) / (4 * x),
             (R[2, 1] - R[1, 2]) / (4 * x)]
    elif i == 2:
        y = 0.5 * np.sqrt(1 - R[0, 0] + R[1, 1] - R[2, 2])
        q = [(R[0, 1] + R[1, 0]) / (4 * y), y, (R[1, 2] + R[2, 1]) / (4 * y),
             (R[0, 2] - R[2, 0]) / (4 * y)]
    else:
        z = 0.5 * np.sqrt(1 - R[0, 0] - R[1, 1] + R[2, 2])
        q = [(R[0, 2] + R[2, 0]) / (4 * z), (R[1, 2] + R[2, 1]) / (4 * z), z,
             (R[1, 0] - R[0, 1]) / (4 * z)]
    q = np.array(q)
    q /= np.linalg.norm(q)
    return -q if q[3] < 0 else q


# ---------------------------------------------------------------------------- helpers
#: Largest calibration file read [bytes] (a 500-camera rig is well below 1 MB).
MAX_CALIBRATION_BYTES = 16 * 1024 * 1024


def _parse(path: str, kind: str) -> Any:
    try:
        text = read_text(path, MAX_CALIBRATION_BYTES)
    except OSError as e:
        raise CalibrationError(f'cannot read calibration file: {e.strerror or e}',
                               source=path) from None
    except LoadError as e:
        raise CalibrationError(f'cannot read calibration file: {e}', source=path) from None
    try:
        return {'json': load_json, 'toml': load_toml}.get(kind, load_yaml)(text)
    except LoadError as e:
        raise CalibrationError(f'not valid {kind.upper()}: {e}', source=path) from None


def _field(entry: Any, key: str, camera: Optional[str], source: str) -> Any:
    if not isinstance(entry, Mapping):
        raise CalibrationError(f'expected a mapping, got {type(entry).__name__}',
                               source=source, camera=camera)
    if key not in entry or entry[key] is None:
        raise CalibrationError('missing', source=source, camera=camera, field=key)
    return entry[key]


def _numbers(value: Any, count: Optional[int], key: str, camera: Optional[str],
             source: str) -> np.ndarray:
    try:
        arr = np.array(value, dtype=float).ravel()
    except (TypeError, ValueError, OverflowError):
        raise CalibrationError(f'not numeric: {repr(value)[:80]}', source=source,
                               camera=camera, field=key) from None
    if count is not None and arr.size != count:
        raise CalibrationError(f'has {arr.size} values, expected {count}', source=source,
                               camera=camera, field=key)
    if not np.isfinite(arr).all():
        raise CalibrationError('contains NaN or infinite values', source=source,
                               camera=camera, field=key)
    return arr


def _camera(source: str, **kwargs) -> Camera:
    try:
        return Camera(**kwargs)
    except CalibrationError as e:
        raise e.with_source(source) from None


def _camera_from_pose(source: str, name: str, K, dist, R_world_cam, position, width,
                      height) -> Camera:  # noqa: N803
    try:
        return Camera.from_pose(name, K, dist, R_world_cam, position, width, height)
    except CalibrationError as e:
        raise e.with_source(source) from None


def _intrinsics_matrix(value: Any, camera: str, source: str, key: str = 'K') -> np.ndarray:
    arr = _numbers(value, None, key, camera, source)
    if arr.size == 4:
        fx, fy, cx, cy = arr
        return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
    if arr.size == 9:
        return arr.reshape(3, 3)
    raise CalibrationError(f'has {arr.size} values, expected 4 (fx fy cx cy) or 9 (3x3)',
                           source=source, camera=camera, field=key)


def _select(cameras: Dict[str, Camera], names: Optional[Iterable[str]],
            source: str) -> Dict[str, Camera]:
    if names is None:
        return cameras
    names = list(names)
    missing = [n for n in names if n not in cameras]
    if missing:
        raise CalibrationError(f'cameras {missing} not found; available: {list(cameras)}',
                               source=source, field='cameras')
    return {n: cameras[n] for n in names}


# ---------------------------------------------------------------------------- camera_info
def _camera_info(data: Any, source: str, camera: Optional[str] = None) -> Dict[str, Any]:
    """Parse a camera_info_manager mapping into name, K, dist, width, height."""
    name = camera
    if name is None and isinstance(data, Mapping):
        name = data.get('camera_name')
    name = str(name) if name else os.path.splitext(os.path.basename(source))[0]
    width = _field(data, 'image_width', name, source)
    height = _field(data, 'image_height', name, source)
    cm = _field(data, 'camera_matrix', name, source)
    K = _numbers(_field(cm, 'data', name, source), 9, 'camera_matrix', name, source)
    model = str(data.get('distortion_model', 'plumb_bob') or 'plumb_bob')
    dc = data.get('distortion_coefficients')
    d = np.zeros(0) if dc is None else _numbers(
        _field(dc, 'data', name, source), None, 'distortion_coefficients', name, source)
    if model in ('rational_polynomial', 'plumb_bob') and d.size > 5 and not d[5:].any():
        d = d[:5]
    if model not in ('plumb_bob', 'rational_polynomial') or d.size > 5:
        raise CalibrationError(f'distortion model {model!r} with {d.size} coefficients is not '
                               f'supported (plumb_bob k1 k2 p1 p2 k3 only)', source=source,
                               camera=name, field='distortion_model')
    return {'name': name, 'K': K.reshape(3, 3), 'dist': d, 'width': width, 'height': height}


def load_camera_info_yaml(path: str) -> Dict[str, Any]:
    """
    Read a camera_info_manager YAML; return dict name, K (3, 3), dist (5,), width, height.

    The values are validated as a ``Camera`` would validate them (with identity pose).
    """
    info = _camera_info(_parse(path, 'yaml'), path)
    cam = _camera(path, R=np.eye(3), t=np.zeros(3), **info)
    return {'name': cam.name, 'K': cam.K.copy(), 'dist': cam.dist.copy(), 'width': cam.width,
            'height': cam.height}


def _load_camera_info(path: str, data: Any) -> Dict[str, Camera]:
    info = _camera_info(data, path)
    return {info['name']: _camera(path, R=np.eye(3), t=np.zeros(3), **info)}


# ---------------------------------------------------------------------------- rig YAML
def _load_rig(path: str, data: Any) -> Dict[str, Camera]:
    cams_data = _field(data, 'cameras', None, path)
    if isinstance(cams_data, list):   # also accept a list of entries with 'name'
        cams_data = {str(_field(c, 'name', None, path)): c for c in cams_data}
    if not isinstance(cams_data, Mapping) or not cams_data:
        raise CalibrationError('must map camera names to camera entries', source=path,
                               field='cameras')
    cameras = {}
    base = os.path.dirname(os.path.abspath(path))
    for name, entry in cams_data.items():
        name = str(name)
        if not isinstance(entry, Mapping):
            raise CalibrationError('expected a mapping', source=path, camera=name)
        fields: Dict[str, Any] = {}
        if entry.get('intrinsics_file'):
            ipath = os.path.join(base, os.path.expanduser(str(entry['intrinsics_file'])))
            info = _camera_info(_parse(ipath, 'yaml'), ipath, camera=name)
            _camera(ipath, R=np.eye(3), t=np.zeros(3), **info)   # its errors name ipath
            fields.update(K=info['K'], dist=info['dist'], width=info['width'],
                          height=info['height'])
        if 'K' in entry:
            fields['K'] = _intrinsics_matrix(entry['K'], name, path)
        model = entry.get('distortion_model', 'plumb_bob')
        if model != 'plumb_bob':
            raise CalibrationError(f'{model!r} is not supported (plumb_bob only)', source=path,
                                   camera=name, field='distortion_model')
        if 'distortion' in entry:
            d = entry['distortion']
            fields['dist'] = None if d is None else _numbers(d, None, 'distortion', name, path)
        for key, src in (('width', 'image_width'), ('height', 'image_height')):
            if src in entry:
                fields[key] = entry[src]
        for key, src in (('K', 'K'), ('width', 'image_width'), ('height', 'image_height')):
            if key not in fields:
                raise CalibrationError('missing (and no intrinsics_file)', source=path,
                                       camera=name, field=src)
        pose = _field(entry, 'T_world_cam', name, path)
        q = _numbers(_field(pose, 'rotation', name, path), 4, 'T_world_cam.rotation', name,
                     path)
        norm = np.linalg.norm(q)
        if abs(norm - 1) > 1e-3:
            raise CalibrationError(f'quaternion (x, y, z, w) must have unit norm, got {norm:.6g}',
                                   source=path, camera=name, field='T_world_cam.rotation')
        position = _numbers(_field(pose, 'translation', name, path), 3,
                            'T_world_cam.translation', name, path)
        cameras[name] = _camera_from_pose(path, name, fields['K'], fields.get('dist'),
                                          quaternion_to_matrix(q), position, fields['width'],
                                          fields['height'])
    return cameras


def rig_yaml_dict(cameras: Mapping[str, Camera], world_frame: str = 'world') -> Dict[str, Any]:
    """Return the rig YAML document (plain lists and floats) describing ``cameras``."""
    out: Dict[str, Any] = {'format': 'mv3dpose_rig', 'version': 1, 'world_frame': world_frame,
                           'cameras': {}}
    for name, cam in cameras.items():
        K = cam.K
        entry: Dict[str, Any] = {'image_width': int(cam.width), 'image_height': int(cam.height)}
        if K[0, 1] == 0:
            entry['K'] = [float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2])]
        else:
            entry['K'] = [[float(v) for v in row] for row in K]
        entry['distortion_model'] = 'plumb_bob'
        entry['distortion'] = [float(v) for v in cam.dist]
        entry['T_world_cam'] = {
            'translation': [float(v) for v in cam.center],
            'rotation': [float(v) for v in matrix_to_quaternion(cam.R_world_cam)]}
        out['cameras'][str(name)] = entry
    return out


def rig_yaml_text(cameras: Mapping[str, Camera], world_frame: str = 'world',
                  comment: Optional[str] = None) -> str:
    """Return the rig YAML of ``cameras`` as text, ``comment`` lines first (``# ...``)."""
    header = ''
    if comment:
        header = ''.join(f'# {line}\n' for line in comment.splitlines())
    return header + yaml.safe_dump(rig_yaml_dict(cameras, world_frame), sort_keys=False,
                                   default_flow_style=None, width=100)


def save_rig_yaml(cameras: Mapping[str, Camera], path: str, world_frame: str = 'world',
                  comment: Optional[str] = None) -> None:
    """Write ``cameras`` as a rig YAML that ``load_calibration`` reads back (round trip)."""
    text = rig_yaml_text(cameras, world_frame, comment)
    with atomic_path(path) as tmp:
        with open(tmp, 'w', encoding='utf-8') as f:
            f.write(text)


# ---------------------------------------------------------------------------- Panoptic
def _load_panoptic(path: str, data: Any, camera_types: Optional[Iterable[str]]
                   ) -> Dict[str, Camera]:
    entries = _field(data, 'cameras', None, path)
    if not isinstance(entries, list):
        raise CalibrationError('must be a list', source=path, field='cameras')
    types = None if camera_types is None else {str(t) for t in camera_types}
    cameras = {}
    C = PANOPTIC_TO_WORLD
    for i, entry in enumerate(entries):
        name = str(entry.get('name', f'#{i}')) if isinstance(entry, Mapping) else f'#{i}'
        kind = entry.get('type') if isinstance(entry, Mapping) else None
        if types is not None and kind not in types:
            continue
        res = _numbers(_field(entry, 'resolution', name, path), 2, 'resolution', name, path)
        K = _numbers(_field(entry, 'K', name, path), 9, 'K', name, path).reshape(3, 3)
        d = _numbers(_field(entry, 'distCoef', name, path), None, 'distCoef', name, path)
        R = _numbers(_field(entry, 'R', name, path), 9, 'R', name, path).reshape(3, 3)
        t = _numbers(_field(entry, 't', name, path), 3, 't', name, path)
        # x_cam[m] = R X_p[cm] / 100 + t / 100 with X_p = C^T X_ours * 100.
        cameras[name] = _camera(path, name=name, K=K, dist=d, R=R @ C.T, t=t * PANOPTIC_SCALE,
                                width=res[0], height=res[1])
    if not cameras:
        raise CalibrationError(f'no camera of type {sorted(types or [])}', source=path,
                               field='cameras')
    return cameras


# ---------------------------------------------------------------------------- VoxelPose
def _load_voxelpose(path: str, data: Any, image_size: Optional[Tuple[int, int]]
                    ) -> Dict[str, Camera]:
    if not isinstance(data, Mapping) or not data:
        raise CalibrationError('expected a mapping of camera ids to cameras', source=path)
    default_size = image_size
    if default_size is None:
        base = os.path.basename(path).lower()
        for key, size in VOXELPOSE_IMAGE_SIZES.items():
            if re.search(key, base):
                default_size = size
    cameras = {}
    for name, entry in data.items():
        name = str(name)
        R = _numbers(_field(entry, 'R', name, path), 9, 'R', name, path).reshape(3, 3)
        T = _numbers(_field(entry, 'T', name, path), 3, 'T', name, path)
        f = [_numbers(_field(entry, k, name, path), 1, k, name, path)[0]
             for k in ('fx', 'fy', 'cx', 'cy')]
        k = _numbers(entry.get('k', [0, 0, 0]), 3, 'k', name, path)
        p = _numbers(entry.get('p', [0, 0]), 2, 'p', name, path)
        if image_size is not None or 'width' not in entry:
            if default_size is None:
                raise CalibrationError('no image size in the file: give one (--image-size WxH '
                                       'on the command line, image_size=(w, h) in Python)',
                                       source=path, camera=name, field='width')
            width, height = default_size
        else:
            width, height = entry['width'], _field(entry, 'height', name, path)
        # x_cam = R (X_mm - T) = R X_m + (-R T / 1000).
        cameras[name] = _camera(path, name=name, K=[[f[0], 0, f[2]], [0, f[1], f[3]], [0, 0, 1]],
                                dist=[k[0], k[1], p[0], p[1], k[2]], R=R, t=-R @ T / 1000.0,
                                width=width, height=height)
    return cameras


# ---------------------------------------------------------------------------- Pose2Sim
def _load_pose2sim(path: str, data: Any) -> Dict[str, Camera]:
    cameras = {}
    for key, entry in data.items():
        if not isinstance(entry, Mapping) or key == 'metadata':
            continue
        name = str(entry.get('name', key))
        if entry.get('fisheye', False):
            raise CalibrationError('fisheye cameras are not supported', source=path,
                                   camera=name, field='fisheye')
        size = _numbers(_field(entry, 'size', name, path), 2, 'size', name, path)
        K = _numbers(_field(entry, 'matrix', name, path), 9, 'matrix', name, path)
        d = _numbers(_field(entry, 'distortions', name, path), None, 'distortions', name, path)
        rvec = _numbers(_field(entry, 'rotation', name, path), 3, 'rotation', name, path)
        t = _numbers(_field(entry, 'translation', name, path), 3, 'translation', name, path)
        cameras[name] = _camera(path, name=name, K=K.reshape(3, 3), dist=d,
                                R=cv2.Rodrigues(rvec)[0], t=t, width=size[0], height=size[1])
    if not cameras:
        raise CalibrationError('no camera tables (with size, matrix, ...) found', source=path)
    return cameras


# ---------------------------------------------------------------------------- dispatch
def detect_format(path: str) -> str:
    """Return the calibration format of ``path`` from its extension and content."""
    ext = os.path.splitext(path)[1].lower()
    if ext == '.toml':
        return 'pose2sim'
    if ext == '.json':
        data = _parse(path, 'json')
        if isinstance(data, Mapping) and isinstance(data.get('cameras'), list):
            return 'panoptic'
        if isinstance(data, Mapping) and data and all(
                isinstance(v, Mapping) and 'T' in v and 'fx' in v for v in data.values()):
            return 'voxelpose'
        raise CalibrationError('JSON is neither Panoptic (cameras: [...]) nor VoxelPose '
                               '({id: {R, T, fx, ...}})', source=path)
    if ext in ('.yaml', '.yml'):
        data = _parse(path, 'yaml')
        if isinstance(data, Mapping) and 'cameras' in data:
            return 'rig'
        if isinstance(data, Mapping) and 'camera_matrix' in data:
            return 'camera_info'
        raise CalibrationError('YAML is neither a rig (cameras:) nor a camera_info_manager '
                               'file (camera_matrix:)', source=path)
    raise CalibrationError(f'unknown calibration file extension {ext!r}: expected .yaml, '
                           f'.json or .toml, or pass fmt (one of {", ".join(FORMATS)})',
                           source=path)


def load_calibration(path: str, fmt: str = 'auto', cameras: Optional[Iterable[str]] = None,
                     camera_types: Optional[Iterable[str]] = ('hd',),
                     image_size: Optional[Tuple[int, int]] = None) -> Dict[str, Camera]:
    """
    Read a calibration file into ``{name: Camera}`` (metres, world z up).

    ``cameras`` keeps only (and orders by) the given names; ``camera_types`` filters Panoptic
    cameras by type (None = all); ``image_size`` (w, h) is for VoxelPose files without sizes.
    """
    path = os.fspath(path)
    if fmt == 'auto':
        fmt = detect_format(path)
    if fmt not in FORMATS:
        raise CalibrationError(f'unknown calibration format {fmt!r}; known: '
                               f'{", ".join(FORMATS)}', source=path)
    if fmt == 'pose2sim':
        result = _load_pose2sim(path, _parse(path, 'toml'))
    elif fmt == 'panoptic':
        result = _load_panoptic(path, _parse(path, 'json'), camera_types)
    elif fmt == 'voxelpose':
        result = _load_voxelpose(path, _parse(path, 'json'), image_size)
    elif fmt == 'rig':
        result = _load_rig(path, _parse(path, 'yaml'))
    else:
        result = _load_camera_info(path, _parse(path, 'yaml'))
    return _select(result, cameras, path)


#: Keys of the rig YAML schema (module docstring), per level.
RIG_KEYS = ('format', 'version', 'world_frame', 'cameras')
RIG_CAMERA_KEYS = ('name', 'image_width', 'image_height', 'K', 'distortion_model', 'distortion',
                   'T_world_cam', 'intrinsics_file')
RIG_POSE_KEYS = ('translation', 'rotation')


def rig_metadata(path: str) -> Tuple[Optional[str], List[str]]:
    """
    Return a rig YAML's ``world_frame`` (None if absent or not a rig file) and its unknown keys.

    Each unknown key comes as a sentence naming it, where it is and the closest valid key, so
    a typo ('world_fame', 'T_world_camera') is reported instead of silently ignored.
    """
    path = os.fspath(path)
    try:
        if detect_format(path) != 'rig':
            return None, []
    except CalibrationError:
        return None, []
    data = _parse(path, 'yaml')
    if not isinstance(data, Mapping):
        return None, []
    problems: List[str] = []

    def check(entry: Any, valid: Sequence[str], where: str) -> None:
        if not isinstance(entry, Mapping):
            return
        for key in entry:
            if str(key) not in valid:
                close = difflib.get_close_matches(str(key), valid, n=1)
                hint = f'; did you mean {close[0]!r}?' if close else \
                    f' (valid: {", ".join(valid)})'
                problems.append(f'{path}: unknown key {key!r} in {where}{hint}')

    check(data, RIG_KEYS, 'the rig')
    cams = data.get('cameras')
    entries = cams.items() if isinstance(cams, Mapping) else \
        ((c.get('name', i) if isinstance(c, Mapping) else i, c)
         for i, c in enumerate(cams if isinstance(cams, list) else []))
    for name, entry in entries:
        check(entry, RIG_CAMERA_KEYS, f'camera {name!r}')
        if isinstance(entry, Mapping):
            check(entry.get('T_world_cam'), RIG_POSE_KEYS, f'camera {name!r} T_world_cam')
    frame = data.get('world_frame')
    return (str(frame) if frame else None), problems
