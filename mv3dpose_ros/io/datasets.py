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
Ground-truth loaders for the public multi-view datasets (metres, the calibration's z-up world).

- Campus ``actorsGT.mat``: 3 actors, 2000 frames, ``shelf14`` joints, already in metres and in
  the world of ``calibration_campus.json``; ``actor2D`` holds the GT projected to each camera
  (integer pixels). Unannotated actors are NaN.
- Panoptic ``hdPose3d_stage1_coco19``: one JSON per frame (``body3DScene_<frame>.json``) with
  bodies (``id``, ``joints19`` = x, y, z, c in centimetres, y down); ``panoptic19`` joints.
  Converted with ``core.geometry.calibration.PANOPTIC_TO_WORLD`` and ``PANOPTIC_SCALE`` exactly
  like the Panoptic calibration. Joints with negative confidence are missing (NaN, confidence 0).
"""

from dataclasses import dataclass, field
import glob
import os
import re
from typing import List, Tuple

from mv3dpose_ros.core.files import load_json, LoadError, read_text
from mv3dpose_ros.core.geometry.calibration import PANOPTIC_SCALE, PANOPTIC_TO_WORLD
import numpy as np

#: The Campus evaluation frames used by Belagiannis et al., VoxelPose and others (inclusive).
CAMPUS_TEST_FRAMES = np.r_[350:471, 650:751]


class DatasetError(ValueError):
    """A ground-truth file that cannot be used; the message names the file and the reason."""


@dataclass
class CampusGroundTruth:
    """Campus ground truth as dense arrays (``layout`` = 'shelf14')."""

    poses: np.ndarray         # [F, A, 14, 3] metres, NaN where the actor is not annotated
    projections: np.ndarray   # [F, A, C, 14, 2] pixels of the dataset's own 2D GT, NaN likewise
    frames: np.ndarray        # [F] frame indices (0-based)
    layout: str = 'shelf14'

    @property
    def annotated(self) -> np.ndarray:
        """Return the mask ``[F, A]`` of annotated actors."""
        return np.isfinite(self.poses).all(axis=(-1, -2))

    def frame(self, index: int) -> np.ndarray:
        """Return the ``[A, 14, 3]`` poses of frame ``index`` (NaN rows = not annotated)."""
        return self.poses[int(np.searchsorted(self.frames, index))]


def _campus_cell(cell) -> np.ndarray:
    """Unwrap one MATLAB cell (an object array around the actual matrix)."""
    arr = cell
    while isinstance(arr, np.ndarray) and arr.dtype == object and arr.size == 1:
        arr = arr.flat[0]
    return arr


def _campus_views(cell) -> list:
    """Return the per-camera 2D arrays of one ``actor2D`` cell (empty list if none)."""
    arr = np.asarray(cell)
    while arr.dtype == object and arr.size == 1 and isinstance(arr.flat[0], np.ndarray) \
            and arr.flat[0].dtype == object:
        arr = arr.flat[0]
    return list(arr.ravel()) if arr.dtype == object else []


def load_campus_gt(path: str) -> CampusGroundTruth:
    """Read Campus ``actorsGT.mat`` into dense arrays (NaN for unannotated actors)."""
    import scipy.io

    try:
        mat = scipy.io.loadmat(path)
    except Exception as e:   # scipy raises MatReadError, ValueError, OSError, ...
        raise DatasetError(f'{path}: cannot read MATLAB file: {e}') from None
    for key in ('actor3D', 'actor2D'):
        if key not in mat:
            raise DatasetError(f'{path}: variable {key!r} missing (not a Campus/Shelf actorsGT)')
    a3, a2 = mat['actor3D'].ravel(), mat['actor2D'].ravel()
    actors, frames = len(a3), len(a3[0])
    annotated = [(p, f) for p in range(actors) for f in range(len(a3[p]))
                 if np.asarray(_campus_cell(a3[p][f])).size]
    n_cams = len(_campus_views(a2[annotated[0][0]][annotated[0][1]])) if annotated else 0
    poses = np.full((frames, actors, 14, 3), np.nan)
    proj = np.full((frames, actors, n_cams, 14, 2), np.nan)
    for p in range(actors):
        if len(a3[p]) != frames or len(a2[p]) != frames:
            raise DatasetError(f'{path}: actor {p} has {len(a3[p])} 3D and {len(a2[p])} 2D '
                               f'frames, expected {frames}')
        for f in range(frames):
            x = np.asarray(_campus_cell(a3[p][f]), dtype=float)
            if x.size == 0:
                continue
            if x.shape != (14, 3):
                raise DatasetError(f'{path}: actor {p} frame {f}: 3D pose of shape {x.shape}, '
                                   f'expected (14, 3)')
            poses[f, p] = x
            views = _campus_views(a2[p][f])
            for c in range(min(n_cams, len(views))):
                uv = np.asarray(views[c], dtype=float)
                if uv.shape == (14, 2):
                    proj[f, p, c] = uv
    return CampusGroundTruth(poses=poses, projections=proj, frames=np.arange(frames))


@dataclass
class PanopticGroundTruth:
    """Panoptic 3D ground truth per frame (``layout`` = 'panoptic19')."""

    frames: np.ndarray                                    # [F] frame numbers from file names
    bodies: List[List[Tuple[int, np.ndarray]]]            # per frame: (body id, [19, 4]) m
    univ_time: np.ndarray                                 # [F] Panoptic universal time (ms)
    skipped: List[Tuple[str, str]] = field(default_factory=list)   # (file, reason)
    layout: str = 'panoptic19'

    @property
    def ids(self) -> np.ndarray:
        """Return the sorted body ids seen in any frame."""
        return np.array(sorted({i for frame in self.bodies for i, _ in frame}), dtype=int)

    def as_array(self) -> Tuple[np.ndarray, np.ndarray]:
        """Return ``(ids [N], poses [F, N, 19, 4])`` with NaN / confidence 0 where absent."""
        ids = self.ids
        col = {int(i): k for k, i in enumerate(ids)}
        out = np.full((len(self.frames), len(ids), 19, 4), np.nan)
        out[..., 3] = 0.0
        for f, frame in enumerate(self.bodies):
            for body_id, joints in frame:
                out[f, col[body_id]] = joints
        return ids, out


def panoptic_to_world(points_cm: np.ndarray) -> np.ndarray:
    """Map Panoptic points ``[..., 3]`` (cm, y down) into our world (m, z up)."""
    return np.asarray(points_cm, dtype=float) @ PANOPTIC_TO_WORLD.T * PANOPTIC_SCALE


def _panoptic_body(body, path: str) -> Tuple[int, np.ndarray]:
    if not isinstance(body, dict) or 'id' not in body or 'joints19' not in body:
        raise DatasetError(f'{path}: body without id or joints19')
    try:
        joints = np.array(body['joints19'], dtype=float).reshape(19, 4)
    except (TypeError, ValueError, OverflowError):
        raise DatasetError(f'{path}: body {body.get("id")}: joints19 must be 76 numbers '
                           f'(19 x, y, z, c)') from None
    out = np.empty((19, 4))
    out[:, :3] = panoptic_to_world(joints[:, :3])
    out[:, 3] = joints[:, 3]
    missing = ~(np.isfinite(joints).all(axis=1) & (joints[:, 3] >= 0))
    out[missing, :3] = np.nan
    out[missing, 3] = 0.0
    if np.abs(out[~missing, :3]).max(initial=0.0) > 1e6:
        raise DatasetError(f'{path}: body {body.get("id")!r}: joints19 beyond 1e6 m')
    bid = body['id']
    if isinstance(bid, bool) or not isinstance(bid, int) or not 0 <= bid < 2 ** 63:
        raise DatasetError(f'{path}: body id {repr(bid)[:40]} is not a non-negative integer')
    return bid, out


def load_panoptic_gt(folder: str, pattern: str = '*.json') -> PanopticGroundTruth:
    """
    Read a Panoptic ``hdPose3d_stage1_coco19`` folder, frames sorted by number.

    Unreadable files are skipped and listed in ``skipped`` with the reason; a folder without
    any usable file raises ``DatasetError``.
    """
    paths = glob.glob(os.path.join(folder, pattern))
    numbered = []
    for p in paths:
        m = re.search(r'(\d+)\.json$', os.path.basename(p))
        if m:
            numbered.append((int(m.group(1)), p))
    numbered.sort()
    frames, bodies, times, skipped = [], [], [], []
    for number, path in numbered:
        try:
            data = load_json(read_text(path, 64 * 1024 * 1024))
            if not isinstance(data, dict) or not isinstance(data.get('bodies'), list):
                raise DatasetError(f'{path}: no "bodies" list')
            frame = [_panoptic_body(b, path) for b in data['bodies']]
            univ = data.get('univTime', np.nan)
            if isinstance(univ, bool) or not isinstance(univ, (int, float)):
                raise DatasetError(f'{path}: univTime {repr(univ)[:40]} is not a number')
        except LoadError as e:
            skipped.append((path, f'{path}: {e}'))
            continue
        except (OSError, ValueError) as e:   # DatasetError included
            skipped.append((path, str(e)))
            continue
        frames.append(number)
        bodies.append(frame)
        times.append(float(univ))
    if not frames:
        reasons = '; '.join(r for _, r in skipped[:3])
        raise DatasetError(f'{folder}: no usable Panoptic ground-truth JSON files '
                           f'({len(numbered)} found{": " + reasons if reasons else ""})')
    return PanopticGroundTruth(frames=np.array(frames, dtype=int), bodies=bodies,
                               univ_time=np.array(times), skipped=skipped)
