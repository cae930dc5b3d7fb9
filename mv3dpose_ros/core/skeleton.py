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
Skeleton layouts (joint order, bones, left/right pairs) and conversion between them.

Every layout names its joints from one vocabulary (``'left_hip'``, ``'neck'``, ...), so
``convert_poses`` maps joints by name. Layouts:

- ``coco17``: COCO keypoints (what ONNX top-down/bottom-up pose models output).
- ``coco18``: OpenPose COCO (18 joints: the COCO-17 joints in OpenPose order plus ``neck``).
- ``body25``: OpenPose BODY_25 (``neck`` = the COCO-style mid-shoulder neck, ``mid_hip``).
- ``body25b``: OpenPose experimental BODY_25B as used by Pose2Sim: the 17 COCO joints, then
  17 ``upper_neck`` (OpenPose "UpperNeck", Pose2Sim "Neck"), 18 ``head_top`` (Pose2Sim "Head"),
  then the six foot joints in BODY_25 order.
- ``shelf14``: Shelf/Campus ground truth; joint 12 "bottom head" is ``upper_neck`` (the bottom of
  the head, MPII's "upper neck"), 13 is ``head_top``.
- ``panoptic19``: CMU Panoptic coco19; joint 2 "body centre" is ``mid_hip``.

Derived joints. When the target layout has a joint the source lacks, ``convert_poses`` computes
it from other joints where a sensible definition exists (first recipe whose inputs are all
present wins; confidence = the minimum of the inputs'). Each is an affine combination of joints,
so it works alike for 2D pixels and 3D metres:

- ``neck``       = (left_shoulder + right_shoulder) / 2
- ``mid_hip``    = (left_hip + right_hip) / 2
- ``upper_neck`` = (nose + neck) / 2 with neck as above (VoxelPose's "head bottom")
- ``head_top``   = mid_ears + 0.8 (mid_ears - mid_shoulders); else (no ears)
                   mid_shoulders + 1.7 (nose - mid_shoulders), which leans forward by ~0.1 m

The factors follow adult proportions (height H: shoulders 0.82 H, chin 0.87 H, ears and nose
0.92 H, head top H) and reproduce the Campus ground truth's bottom-head and top-head heights
above the shoulders (0.10 m and 0.35 m median) for an upright person.

Anything else the source lacks comes out missing: NaN coordinates and confidence 0.
"""

from dataclasses import dataclass
import functools
from typing import Dict, Optional, Sequence, Tuple, Union

import numpy as np


@dataclass(frozen=True)
class Layout:
    """A joint order with its bones and left/right pairs (all as joint indices)."""

    name: str
    joint_names: Tuple[str, ...]
    bones: Tuple[Tuple[int, int], ...]
    flip_pairs: Tuple[Tuple[int, int], ...]

    @property
    def num_joints(self) -> int:
        """Return the number of joints."""
        return len(self.joint_names)

    def index(self, name: str) -> int:
        """Return the index of joint ``name`` (ValueError naming the layout if absent)."""
        try:
            return self.joint_names.index(name)
        except ValueError:
            raise ValueError(f'layout {self.name!r} has no joint {name!r}') from None

    def has(self, name: str) -> bool:
        """Tell whether the layout has joint ``name``."""
        return name in self.joint_names

    @property
    def root_joints(self) -> Tuple[int, int]:
        """Return the indices of (left_hip, right_hip), whose midpoint is the root."""
        return self.index('left_hip'), self.index('right_hip')

    @property
    def flip_permutation(self) -> np.ndarray:
        """Return the permutation swapping left and right (``poses[..., perm, :]`` mirrors)."""
        perm = np.arange(self.num_joints)
        for a, b in self.flip_pairs:
            perm[a], perm[b] = b, a
        return perm


_COCO17 = (
    'nose', 'left_eye', 'right_eye', 'left_ear', 'right_ear',
    'left_shoulder', 'right_shoulder', 'left_elbow', 'right_elbow', 'left_wrist', 'right_wrist',
    'left_hip', 'right_hip', 'left_knee', 'right_knee', 'left_ankle', 'right_ankle')

_FEET = ('left_big_toe', 'left_small_toe', 'left_heel',
         'right_big_toe', 'right_small_toe', 'right_heel')

_JOINTS = {
    'coco17': _COCO17,
    'body25': (
        'nose', 'neck', 'right_shoulder', 'right_elbow', 'right_wrist',
        'left_shoulder', 'left_elbow', 'left_wrist', 'mid_hip',
        'right_hip', 'right_knee', 'right_ankle', 'left_hip', 'left_knee', 'left_ankle',
        'right_eye', 'left_eye', 'right_ear', 'left_ear') + _FEET,
    'coco18': (
        'nose', 'neck', 'right_shoulder', 'right_elbow', 'right_wrist',
        'left_shoulder', 'left_elbow', 'left_wrist',
        'right_hip', 'right_knee', 'right_ankle', 'left_hip', 'left_knee', 'left_ankle',
        'right_eye', 'left_eye', 'right_ear', 'left_ear'),
    'body25b': _COCO17 + ('upper_neck', 'head_top') + _FEET,
    'shelf14': (
        'right_ankle', 'right_knee', 'right_hip', 'left_hip', 'left_knee', 'left_ankle',
        'right_wrist', 'right_elbow', 'right_shoulder', 'left_shoulder', 'left_elbow',
        'left_wrist', 'upper_neck', 'head_top'),
    'panoptic19': (
        'neck', 'nose', 'mid_hip', 'left_shoulder', 'left_elbow', 'left_wrist',
        'left_hip', 'left_knee', 'left_ankle', 'right_shoulder', 'right_elbow', 'right_wrist',
        'right_hip', 'right_knee', 'right_ankle', 'left_eye', 'left_ear', 'right_eye',
        'right_ear'),
}

_LIMBS = (('left_shoulder', 'left_elbow'), ('left_elbow', 'left_wrist'),
          ('right_shoulder', 'right_elbow'), ('right_elbow', 'right_wrist'),
          ('left_hip', 'left_knee'), ('left_knee', 'left_ankle'),
          ('right_hip', 'right_knee'), ('right_knee', 'right_ankle'))
_FACE = (('nose', 'left_eye'), ('nose', 'right_eye'),
         ('left_eye', 'left_ear'), ('right_eye', 'right_ear'))
_FOOT_BONES = (('left_ankle', 'left_heel'), ('left_ankle', 'left_big_toe'),
               ('left_big_toe', 'left_small_toe'),
               ('right_ankle', 'right_heel'), ('right_ankle', 'right_big_toe'),
               ('right_big_toe', 'right_small_toe'))

_BONES = {
    'coco17': _LIMBS + _FACE + (
        ('left_shoulder', 'right_shoulder'), ('left_hip', 'right_hip'),
        ('left_shoulder', 'left_hip'), ('right_shoulder', 'right_hip'),
        ('left_ear', 'left_shoulder'), ('right_ear', 'right_shoulder')),
    'body25': _LIMBS + _FACE + _FOOT_BONES + (
        ('neck', 'nose'), ('neck', 'left_shoulder'), ('neck', 'right_shoulder'),
        ('neck', 'mid_hip'), ('mid_hip', 'left_hip'), ('mid_hip', 'right_hip')),
    'coco18': _LIMBS + _FACE + (
        ('neck', 'nose'), ('neck', 'left_shoulder'), ('neck', 'right_shoulder'),
        ('left_shoulder', 'left_hip'), ('right_shoulder', 'right_hip'), ('left_hip', 'right_hip')),
    'body25b': _LIMBS + _FACE + _FOOT_BONES + (
        ('upper_neck', 'head_top'), ('upper_neck', 'nose'),
        ('upper_neck', 'left_shoulder'), ('upper_neck', 'right_shoulder'),
        ('left_shoulder', 'left_hip'), ('right_shoulder', 'right_hip'),
        ('left_hip', 'right_hip')),
    'shelf14': _LIMBS + (
        ('upper_neck', 'head_top'), ('upper_neck', 'left_shoulder'),
        ('upper_neck', 'right_shoulder'), ('left_shoulder', 'left_hip'),
        ('right_shoulder', 'right_hip'), ('left_hip', 'right_hip')),
    'panoptic19': _LIMBS + (
        ('neck', 'nose'), ('nose', 'left_eye'), ('left_eye', 'left_ear'),
        ('nose', 'right_eye'), ('right_eye', 'right_ear'),
        ('neck', 'left_shoulder'), ('neck', 'right_shoulder'), ('neck', 'mid_hip'),
        ('mid_hip', 'left_hip'), ('mid_hip', 'right_hip')),
}

# Derived joints: recipes tried in order, each {source joint: weight} with weights summing to 1.
_DERIVED: Dict[str, Tuple[Dict[str, float], ...]] = {
    'neck': ({'left_shoulder': 0.5, 'right_shoulder': 0.5},),
    'mid_hip': ({'left_hip': 0.5, 'right_hip': 0.5},),
    'upper_neck': ({'nose': 0.5, 'left_shoulder': 0.25, 'right_shoulder': 0.25},),
    'head_top': ({'left_ear': 0.9, 'right_ear': 0.9, 'left_shoulder': -0.4,
                  'right_shoulder': -0.4},
                 {'nose': 1.7, 'left_shoulder': -0.35, 'right_shoulder': -0.35}),
}

LAYOUT_NAMES: Tuple[str, ...] = tuple(_JOINTS)


def _flip_pairs(names: Sequence[str]) -> Tuple[Tuple[int, int], ...]:
    pairs = []
    for i, name in enumerate(names):
        if name.startswith('left_'):
            other = 'right_' + name[len('left_'):]
            if other not in names:
                raise ValueError(f'joint {name!r} has no right counterpart')
            pairs.append((i, names.index(other)))
    return tuple(pairs)


def _build(name: str) -> Layout:
    names = _JOINTS[name]
    if len(set(names)) != len(names):
        raise ValueError(f'layout {name!r} repeats a joint name')
    bones = tuple((names.index(a), names.index(b)) for a, b in _BONES[name])
    return Layout(name=name, joint_names=names, bones=bones, flip_pairs=_flip_pairs(names))


_LAYOUTS: Dict[str, Layout] = {name: _build(name) for name in LAYOUT_NAMES}


def get_layout(name: Union[str, Layout]) -> Layout:
    """Return the layout called ``name`` (a ``Layout`` passes through)."""
    if isinstance(name, Layout):
        return name
    try:
        return _LAYOUTS[name]
    except (KeyError, TypeError):
        raise ValueError(
            f'unknown skeleton layout {name!r}; known: {", ".join(LAYOUT_NAMES)}') from None


@functools.lru_cache(maxsize=None)
def _plan(src: Layout, dst: Layout):
    """Precompute the direct index map and the derived-joint recipes from ``src`` to ``dst``."""
    dst_idx, src_idx, derived = [], [], []
    for j, name in enumerate(dst.joint_names):
        if src.has(name):
            dst_idx.append(j)
            src_idx.append(src.index(name))
            continue
        recipes = []
        for recipe in _DERIVED.get(name, ()):
            if all(src.has(n) for n in recipe):
                recipes.append((np.array([src.index(n) for n in recipe]),
                                np.array(list(recipe.values()), dtype=float)))
        if recipes:
            derived.append((j, tuple(recipes)))
    return np.array(dst_idx, dtype=int), np.array(src_idx, dtype=int), tuple(derived)


def convert_poses(poses: np.ndarray, src: Union[str, Layout], dst: Union[str, Layout],
                  has_confidence: Optional[bool] = None) -> np.ndarray:
    """
    Map poses ``[..., J_src, C]`` from layout ``src`` to ``[..., J_dst, C]`` in ``dst``.

    Joints are matched by name; joints only ``dst`` has are derived (see the module docstring)
    or set missing (NaN coordinates, confidence 0). ``has_confidence`` says whether the last
    column is a confidence; by default it is for C = 3 (x, y, c) and C = 4 (x, y, z, c), so pass
    ``False`` for plain ``[..., 3]`` xyz. A source joint counts as present when its coordinates
    are finite and (with confidence) its confidence is > 0.
    """
    src_l, dst_l = get_layout(src), get_layout(dst)
    poses = np.asarray(poses, dtype=float)
    if poses.ndim < 2 or poses.shape[-2] != src_l.num_joints:
        raise ValueError(f'poses of shape {poses.shape} do not match layout {src_l.name!r} '
                         f'({src_l.num_joints} joints): expected [..., {src_l.num_joints}, C]')
    channels = poses.shape[-1]
    if has_confidence is None:
        has_confidence = channels in (3, 4)
    dims = channels - 1 if has_confidence else channels
    if dims < 1:
        raise ValueError(f'poses of shape {poses.shape} have no coordinates')
    out = np.full(poses.shape[:-2] + (dst_l.num_joints, channels), np.nan)
    if has_confidence:
        out[..., -1] = 0.0
    dst_idx, src_idx, derived = _plan(src_l, dst_l)
    out[..., dst_idx, :] = poses[..., src_idx, :]
    if not derived:
        return out
    present = np.isfinite(poses[..., :dims]).all(axis=-1)
    if has_confidence:
        present &= poses[..., -1] > 0
    for j, recipes in derived:
        todo = np.ones(poses.shape[:-2], dtype=bool)
        for idx, weights in recipes:
            ok = todo & present[..., idx].all(axis=-1)
            if not ok.any():
                continue
            coords = np.einsum('...jd,j->...d', poses[..., idx, :dims], weights)
            out[..., j, :dims] = np.where(ok[..., None], coords, out[..., j, :dims])
            if has_confidence:
                conf = poses[..., idx, -1].min(axis=-1)
                out[..., j, -1] = np.where(ok, conf, out[..., j, -1])
            todo &= ~ok
    return out
