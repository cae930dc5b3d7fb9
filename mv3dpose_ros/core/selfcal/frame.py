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
The world frame and metric scale of an estimated rig, and comparing rigs (step 5).

z up along the floor's normal under the ankles, metres from a stature prior (``world_frame``);
``similarity``, ``align_to`` and ``camera_errors`` compare an estimate with a reference rig
(``extrinsics.adopt_frame`` uses them to keep a given rig's frame).
"""

from typing import Dict, Iterable, List, Mapping, Optional, Sequence, Tuple

from mv3dpose_ros.core.geometry.camera import Camera
from mv3dpose_ros.core.selfcal.points import Points
from mv3dpose_ros.core.selfcal.views import no_empty_slice_warnings, SelfCalError
from mv3dpose_ros.core.skeleton import Layout
import numpy as np


#: Median adult stature [m] (the default ``--person-height``).
ADULT_HEIGHT_M = 1.70


#: Height above the floor of a standing person's joints, as a fraction of stature
#: (Drillis & Contini segment proportions, as tabulated by Winter).
STATURE_FRACTION = {'head_top': 1.0, 'left_eye': 0.936, 'right_eye': 0.936,
                    'left_ear': 0.925, 'right_ear': 0.925, 'nose': 0.915,
                    'left_shoulder': 0.818, 'right_shoulder': 0.818}


ANKLE_FRACTION = 0.039


def similarity(src: Mapping[str, Camera], dst: Mapping[str, Camera],
               names: Optional[Sequence[str]] = None):
    """
    Return ``(s, Rs, ts)`` with ``X_dst = s Rs X_src + ts`` fitting ``src`` onto ``dst``.

    Fits camera centres and orientations together (each camera's axes as points one rig
    radius from its centre), so two cameras suffice; the scale comes from the centres.
    """
    names = list(names or [n for n in src if n in dst])
    cs = np.array([src[n].center for n in names])
    cd = np.array([dst[n].center for n in names])
    ms, md = cs.mean(0), cd.mean(0)
    ss = np.sqrt(((cs - ms) ** 2).sum(1).mean())
    sd = np.sqrt(((cd - md) ** 2).sum(1).mean())
    scale = sd / ss if ss > 1e-12 else 1.0
    ps = [cs - ms]
    pd = [cd - md]
    for k in range(3):
        ps.append(cs - ms + ss * np.array([src[n].R[k] for n in names]))
        pd.append(cd - md + sd * np.array([dst[n].R[k] for n in names]))
    ps, pd = np.concatenate(ps), np.concatenate(pd)
    u, _, vt = np.linalg.svd(pd.T @ ps)
    d = np.sign(np.linalg.det(u @ vt))
    Rs = u @ np.diag([1, 1, d]) @ vt
    return scale, Rs, md - scale * Rs @ ms


def transform_camera(cam: Camera, s: float, Rs: np.ndarray, ts: np.ndarray) -> Camera:
    """Return ``cam`` in the frame ``X' = s Rs X + ts`` (the same image of every point)."""
    R = cam.R @ Rs.T
    return Camera(cam.name, cam.K, cam.dist, R, s * cam.t - R @ ts, cam.width, cam.height)


def camera_errors(est: Mapping[str, Camera], ref: Mapping[str, Camera]
                  ) -> Dict[str, Tuple[float, float]]:
    """Return per camera (rotation error [deg], centre error [m]) of ``est`` vs ``ref``."""
    out = {}
    for n in est:
        if n in ref:
            dR = est[n].R @ ref[n].R.T
            ang = np.degrees(np.arccos(np.clip((np.trace(dR) - 1) / 2, -1, 1)))
            out[n] = (float(ang), float(np.linalg.norm(est[n].center - ref[n].center)))
    return out


def align_to(est: Mapping[str, Camera], ref: Mapping[str, Camera], robust: bool = True
             ) -> Tuple[Dict[str, Camera], List[str]]:
    """
    Express ``est`` in ``ref``'s frame by a similarity; return (cameras, names fitted).

    ``robust`` drops, one by one, the camera that disagrees most (over 3 times the median
    and over 0.3 deg / 2 cm) while three or more remain: bumped cameras must not pull the frame.
    """
    use = [n for n in est if n in ref]
    while True:
        s, Rs, ts = similarity(est, ref, use)
        moved = {n: transform_camera(c, s, Rs, ts) for n, c in est.items()}
        if not robust or len(use) <= 2:
            return moved, use
        err = camera_errors({n: moved[n] for n in use}, ref)
        score = {n: max(e[0] / 0.3, e[1] / 0.02) for n, e in err.items()}
        worst = max(score, key=score.get)
        med = float(np.median(list(score.values())))
        if score[worst] > 1.0 and score[worst] > 3 * med:
            use = [n for n in use if n != worst]
        else:
            return moved, use


def _joint_ids(layout: Layout, names: Iterable[str]) -> List[int]:
    return [layout.index(n) for n in names if layout.has(n)]


def world_frame(R: np.ndarray, t: np.ndarray, X: np.ndarray, pts: Points, layout: Layout,
                names: Sequence[str], person_height: float = ADULT_HEIGHT_M,
                baseline: Optional[Tuple[str, str, float]] = None,
                origin_camera: Optional[str] = None):
    """
    Return ``(R, t, X, world, scale)``: the rig in metres with z up from the floor.

    ``world`` and ``scale`` say in words how the frame and the metres were chosen.
    """
    ankles = _joint_ids(layout, ('left_ankle', 'right_ankle'))
    heads = [(layout.index(n), f) for n, f in STATURE_FRACTION.items() if layout.has(n)]
    ok = np.isfinite(X).all(1)
    people = np.unique(pts.person[ok])
    P = np.full((people.max() + 1 if len(people) else 0, layout.num_joints, 3), np.nan)
    P[pts.person[ok], pts.joint[ok]] = X[ok]
    ank = P[:, ankles].reshape(-1, 3)
    ank = ank[np.isfinite(ank).all(1)]
    with np.errstate(invalid='ignore'), no_empty_slice_warnings():
        foot = np.nanmean(P[:, ankles], axis=1)
        top = np.nanmean(P[:, [j for j, _ in heads]], axis=1)
    v = top - foot
    v = v[np.isfinite(v).all(1)]
    if len(v) < 5 or len(ank) < 10:
        raise SelfCalError('too few people seen whole (ankles and head) to find the floor '
                           f'and the vertical ({len(v)} poses)')
    up = np.median(v / np.linalg.norm(v, axis=1, keepdims=True), axis=0)
    up /= np.linalg.norm(up)
    size = float(np.median(np.linalg.norm(v, axis=1)))
    centre = np.median(ank, axis=0)
    _, sv, vt = np.linalg.svd(ank - centre, full_matrices=False)
    spread = sv / np.sqrt(len(ank))
    normal = vt[2] * np.sign(vt[2] @ up)
    angle = np.degrees(np.arccos(np.clip(normal @ up, -1, 1)))
    if spread[1] > 0.25 * size and angle < 20:
        z = normal
        world = (f'z up: normal of the floor fitted under {len(ank)} ankle positions '
                 f"({angle:.1f} deg from the people's mean vertical)")
    else:
        z = up
        world = ("z up: the people's mean vertical (their ankles span no plane: "
                 f'{spread[1] / size:.2f} person heights across)')
    ref = names.index(origin_camera) if origin_camera else 0
    axis = R[ref][2] - (R[ref][2] @ z) * z
    if np.linalg.norm(axis) < 1e-6:
        axis = R[ref][0] - (R[ref][0] @ z) * z
    x = axis / np.linalg.norm(axis)
    Rw = np.stack([x, np.cross(z, x), z])
    # metres
    rel = []
    for j, frac in heads:
        h = (P[:, j] - foot) @ z
        h = h[np.isfinite(h) & (h > 0)]
        rel.append(h / (frac - ANKLE_FRACTION))
    rel = np.concatenate(rel) if rel else np.zeros(0)
    stature = float(np.median(rel)) if len(rel) else float('nan')
    if baseline is not None:
        ca, cb, metres = baseline
        ia, ib = names.index(ca), names.index(cb)
        d = np.linalg.norm(-R[ia].T @ t[ia] + R[ib].T @ t[ib])
        s = metres / d
        scale = (f'metres from the baseline {ca}-{cb} = {metres:g} m (people then measure '
                 f'{s * stature:.2f} m tall)')
    else:
        s = person_height / stature
        scale = (f'metres from a person height of {person_height:.2f} m (median stature from '
                 f'{len(rel)} joint heights above the ankles)')
    floor = float(np.median(ank @ z)) - ANKLE_FRACTION * stature
    if origin_camera:
        c = -R[ref].T @ t[ref]
        o = c - (c @ z - floor) * z
        world += f'; origin on the floor under camera {origin_camera}'
    else:
        roots = foot[np.isfinite(foot).all(1)]
        m = np.median(roots, axis=0)
        o = m - (m @ z - floor) * z
        world += "; origin on the floor under the people's mean position"
    world += f"; x along camera {names[ref]}'s horizontal viewing direction"
    Rn = R @ Rw.T
    tn = s * (np.einsum('cij,j->ci', R, o) + t)
    Xn = s * (X - o) @ Rw.T
    return Rn, tn, Xn, world, scale
