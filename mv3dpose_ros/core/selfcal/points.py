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
The bundle adjustment's points: one per joint of a person seen by two cameras or more.

Built from the grouped people (``build_points``), thinned evenly where there are too many,
and screened for implausible bodies (``plausible_people``: bone lengths a person can have).
"""

from dataclasses import dataclass

from mv3dpose_ros.core.geometry import bundle
from mv3dpose_ros.core.selfcal.views import no_empty_slice_warnings, SelfCalError, Views
from mv3dpose_ros.core.skeleton import Layout
import numpy as np


@dataclass
class Points:
    """3D points (one per frame, person and joint) with their observations."""

    prob: bundle.Problem
    frame: np.ndarray      # [M] frame index
    joint: np.ndarray      # [M] joint index
    person: np.ndarray     # [M] person number (unique over frames)


def build_points(views: Views, groups, layout: Layout, max_points: int = 0,
                 seed: int = 0) -> Points:
    """Turn grouped people into the bundle adjustment's points and observations."""
    flip = layout.flip_permutation
    cam_index = {c: k for k, c in enumerate(views.cameras)}
    cam, pt, xy, w, frame, joint, person = [], [], [], [], [], [], []
    n_pt, n_person = 0, 0
    for f, people in enumerate(groups):
        for g in people:
            J = layout.num_joints
            seen = np.zeros(J, int)
            obs = []
            for c, (p, fl) in g.items():
                q = views.people[c][f][p]
                if fl:
                    q = q[flip]
                ok = q[:, 2] > 0
                seen += ok
                obs.append((cam_index[c], q, ok))
            keep = np.flatnonzero(seen >= 2)
            if not len(keep):
                continue
            ids = np.full(J, -1)
            ids[keep] = n_pt + np.arange(len(keep))
            for ci, q, ok in obs:
                sel = ok & (ids >= 0)
                cam.append(np.full(sel.sum(), ci))
                pt.append(ids[sel])
                xy.append(q[sel, :2])
                w.append(q[sel, 2])
            frame.append(np.full(len(keep), f))
            joint.append(keep)
            person.append(np.full(len(keep), n_person))
            n_pt += len(keep)
            n_person += 1
    if not n_pt:
        raise SelfCalError('no person was matched across two cameras in any frame')
    prob = bundle.Problem(np.concatenate(cam), np.concatenate(pt), np.concatenate(xy),
                          np.concatenate(w),
                          np.array([views.focal[c] for c in views.cameras]))
    pts = Points(prob, np.concatenate(frame), np.concatenate(joint), np.concatenate(person))
    if max_points and n_pt > max_points:
        pts = subset_points(pts, even_sample(n_pt, max_points, pts.person))
    return pts


def even_sample(n: int, keep: int, person: np.ndarray) -> np.ndarray:
    """Pick about ``keep`` of ``n`` points, whole people evenly spread over the sequence."""
    people = np.unique(person)
    step = max(1, int(np.ceil(n / keep)))
    chosen = set(people[::step].tolist())
    return np.array([p in chosen for p in person])


def subset_points(pts: Points, mask: np.ndarray) -> Points:
    """Return the points under ``mask`` with their observations, renumbered."""
    new = np.full(len(mask), -1)
    new[mask] = np.arange(mask.sum())
    o = mask[pts.prob.point]
    prob = bundle.Problem(pts.prob.camera[o], new[pts.prob.point[o]], pts.prob.xy[o],
                          pts.prob.weight[o], pts.prob.focal)
    return Points(prob, pts.frame[mask], pts.joint[mask], pts.person[mask])


def drop_observations(pts: Points, keep: np.ndarray) -> Points:
    """Drop observations; points left with fewer than two are dropped too."""
    p = pts.prob
    prob = bundle.Problem(p.camera[keep], p.point[keep], p.xy[keep], p.weight[keep], p.focal)
    count = np.bincount(prob.point, minlength=len(pts.frame))
    return subset_points(Points(prob, pts.frame, pts.joint, pts.person), count >= 2)


def plausible_people(X: np.ndarray, pts: Points, layout: Layout,
                     tolerance: float = 1.3) -> np.ndarray:
    """
    Return the ``[M]`` mask of points whose person has the bone lengths of the others.

    People joined from wrong matches triangulate into skeletons of the wrong size or shape
    (two views always agree with some point): a person whose median bone length ratio to
    the median over everyone is off by more than ``tolerance`` is dropped (False).
    """
    n = int(pts.person.max()) + 1 if len(pts.person) else 0
    P = np.full((n, layout.num_joints, 3), np.nan)
    P[pts.person, pts.joint] = X
    bones = np.array(layout.bones)
    length = np.linalg.norm(P[:, bones[:, 0]] - P[:, bones[:, 1]], axis=2)     # [n, B]
    with no_empty_slice_warnings():
        typical = np.nanmedian(length, axis=0)
        ratio = np.abs(np.log(length / typical))
        off = np.nanmedian(ratio, axis=1)
    good = ~(off > np.log(tolerance))          # NaN (too few bones) stays
    return good[pts.person]
