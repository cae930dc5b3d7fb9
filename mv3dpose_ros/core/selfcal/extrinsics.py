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
Extrinsic calibration of a rig from 2D keypoints of the people moving through it.

``calibrate`` runs the steps below; each lives in a module of this package (``views``,
``pairs``, ``points``, ``placement``, ``frame``).

Every joint of one person seen by two cameras at one instant is a correspondence. Steps:

1. Keypoints are undistorted to normalised coordinates with the known intrinsics; joints under
   ``min_confidence`` are dropped; people are followed from frame to frame in each view
   (2D tracklets, ``track_2d``).
2. Per camera pair, which person in one view is which in the other is estimated with the
   geometry: each pair of long tracklets is a hypothesis, whose correspondences give an
   essential matrix (``cv2.findEssentialMat``, RANSAC); a hypothesis scores the number of
   person pairs over all frames it explains (Hungarian matching per frame on the median
   Sampson distance, left/right swapped skeletons tried too); the best is re-estimated from
   every pair that agrees.
3. The pairwise matches of one frame are joined into people seen by several cameras
   (union-find with a left/right parity, most confident matches first, never two people of
   one camera in one person).
4. Cameras are placed incrementally: the best-connected pair from its essential matrix,
   then each next camera by PnP on the triangulated joints, with a bundle adjustment after
   each (``core.geometry.bundle``); a final adjustment over all cameras and joints, observations
   far off dropped, and adjusted again.
5. World frame: z up along the normal of the floor fitted under the ankles (or the people's
   mean vertical where the ankles span no plane), origin on the floor under the people's mean
   position or a named camera, x along the reference camera's horizontal viewing direction;
   metres from a person height prior (anthropometric fractions of stature) or a baseline.

After step 4 every camera is checked against where the others triangulate its people
(``odd_cameras``): one far off (other instants, other people) is reported not placed and the
rig estimated again without it.

``refine`` starts from a given rig instead of step 4. A bumped camera (its image moves far
more than the others' when fitted to their triangulations) is placed again and adjusted
alone, the others fixed; without one, all are adjusted and the result is mapped back onto
the given rig by a similarity fitted to the cameras that moved least.
"""

from dataclasses import dataclass, field
from typing import Dict, List, Mapping, Optional, Tuple

from mv3dpose_ros.core.geometry import bundle
from mv3dpose_ros.core.geometry.camera import Camera
from mv3dpose_ros.core.selfcal.frame import (ADULT_HEIGHT_M, align_to, camera_errors, similarity,
                                             world_frame)
from mv3dpose_ros.core.selfcal.pairs import estimate_pair, group_people, PairResult
from mv3dpose_ros.core.selfcal.placement import (final_adjustment, initial_rig, odd_cameras,
                                                 refine_start)
from mv3dpose_ros.core.selfcal.points import build_points, drop_observations
from mv3dpose_ros.core.selfcal.views import check_views, SelfCalError, Settings, track_2d, Views
from mv3dpose_ros.core.skeleton import get_layout
import numpy as np


@dataclass
class CameraReport:
    """Per camera figures of the result."""

    name: str
    placed: bool
    observations: int = 0
    median_px: float = float('nan')
    p95_px: float = float('nan')
    moved_deg: float = float('nan')    # refine: rotation change
    moved_m: float = float('nan')      # refine: centre change
    why: str = ''


@dataclass
class Result:
    """The calibrated rig and what it rests on."""

    cameras: Dict[str, Camera]
    reports: Dict[str, CameraReport]
    pairs: List[PairResult]
    points: np.ndarray               # [M, 3] joints in the world frame (NaN: dropped)
    point_joint: np.ndarray          # [M] joint index of each point
    point_frame: np.ndarray          # [M] frame index of each point
    point_person: np.ndarray         # [M] person (one per frame and person) of each point
    world: str                       # how the world frame was chosen
    scale: str                       # where metres come from
    unplaced: Dict[str, str] = field(default_factory=dict)


def calibrate(views: Views, intrinsics: Mapping[str, Camera], layout: str,
              settings: Optional[Settings] = None, initial: Optional[Mapping[str, Camera]] = None,
              person_height: float = ADULT_HEIGHT_M,
              baseline: Optional[Tuple[str, str, float]] = None,
              origin_camera: Optional[str] = None, log=None) -> Result:
    """
    Estimate the extrinsics of ``intrinsics``' cameras from the people in ``views``.

    With ``initial`` (refine) the given extrinsics start the adjustment and the result is
    mapped back onto them (the cameras that moved least hold the frame). Cameras that cannot
    be placed are left out of ``Result.cameras`` and named with the reason in ``unplaced``.
    """
    s = settings or Settings()
    lay = get_layout(layout)
    log = log or (lambda text: None)
    check_views(views, s)
    views.tracks = {c: track_2d(views.people[c], s.track_gate) for c in views.cameras}
    names = views.cameras
    pairs, best_pair = [], {}
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            pr = estimate_pair(views, a, b, lay, s)
            log(f'pair {a}-{b}: {pr.person_frames} person matches, '
                f'{pr.inliers}/{pr.correspondences} joints fit one essential matrix'
                + (f' ({pr.note})' if pr.note else ''))
            pairs.append(pr)
            for c, o in ((a, b), (b, a)):
                if pr.person_frames > best_pair.get(c, (-1, ''))[0]:
                    best_pair[c] = (pr.person_frames, o)
    usable = [p for p in pairs if p.E is not None and p.person_frames >= s.min_pair_frames]
    unplaced = {}
    for c in names:
        if not any(c in (p.a, p.b) for p in usable):
            n, o = best_pair.get(c, (0, ''))
            unplaced[c] = (f'never shares a person with another camera: at most {n} person '
                           f'matches (with {o or "none"}), need {s.min_pair_frames}')
    if not usable:
        raise SelfCalError('no camera pair shares enough people: '
                           + '; '.join(f'{c} {w}' for c, w in unplaced.items()))
    idx = {c: k for k, c in enumerate(names)}
    while True:
        groups = group_people(views, usable)
        pts = build_points(views, groups, lay, s.max_points, s.seed)
        if initial is None:
            R, t, placed, why, ref = initial_rig(views, pts, usable, s)
            unplaced.update({c: w for c, w in why.items() if c not in unplaced})
        else:
            R = np.array([initial[c].R for c in names])
            t = np.array([initial[c].t for c in names])
            placed = [idx[c] for c in names if c not in unplaced]
            ref = placed[0]
        placed = [c for c in placed if names[c] not in unplaced]
        for c in names:
            if idx[c] not in placed and c not in unplaced:
                unplaced[c] = 'not reached from the placed cameras'
        pts = drop_observations(pts, np.isin(pts.prob.camera, placed))
        fixed = ref
        if initial is not None:
            fixed = refine_start(R, t, pts, placed, s, names, log)
        R, t, X, kept = final_adjustment(R, t, pts, placed, fixed, s, lay)
        # checked on every observation: those far off were just dropped from the adjustment
        odd, px = odd_cameras(R, t, pts, placed, s.odd_ratio, s.odd_px)
        log("median px against the other cameras' triangulations: "
            + ', '.join(f'{names[c]} {v:.1f}' for c, v in px.items()))
        pts = kept
        if not odd:
            break
        for c in odd:
            rest = float(np.nanmedian([v for k, v in px.items() if k not in odd]))
            unplaced[names[c]] = (
                f'never shares a person with the others consistently: its people are '
                f'{px[c]:.0f} px (median) from where the other cameras triangulate them '
                f'(the others: {rest:.1f} px); does it see other instants, or other people?')
            log(f'{names[c]}: {unplaced[names[c]]}; calibrating without it')
        usable = [p for p in usable if p.a not in unplaced and p.b not in unplaced]
        if not usable:
            raise SelfCalError('no camera pair shares people consistently: '
                               + '; '.join(f'{c} {w}' for c, w in unplaced.items()))
    res = bundle.residuals_px(R, t, X, pts.prob)
    good = [names[c] for c in placed]

    def cams(RR, tt):
        return {n: Camera(n, intrinsics[n].K, intrinsics[n].dist, RR[idx[n]], tt[idx[n]],
                          intrinsics[n].width, intrinsics[n].height) for n in good}

    if initial is None:
        R, t, X, world, scale = world_frame(R, t, X, pts, lay, names, person_height, baseline,
                                            origin_camera)
        out = cams(R, t)
    else:
        out, held = align_to(cams(R, t), initial)
        s_, Rs, ts = similarity(cams(R, t), initial, held)
        X = s_ * X @ Rs.T + ts
        world = f'the given rig\'s frame, held by cameras {", ".join(held)}'
        scale = "the given rig's metres"
    reports = {}
    moved = camera_errors(out, initial) if initial is not None else {}
    for n in names:
        if n in out:
            r = res[pts.prob.camera == idx[n]]
            r = r[np.isfinite(r)]
            rep = CameraReport(n, True, len(r), float(np.median(r)) if len(r) else np.nan,
                               float(np.percentile(r, 95)) if len(r) else np.nan)
            if n in moved:
                rep.moved_deg, rep.moved_m = moved[n]
        else:
            rep = CameraReport(n, False, why=unplaced.get(n, ''))
        reports[n] = rep
    return Result(out, reports, pairs, X, pts.joint, pts.frame, pts.person, world, scale,
                  unplaced)


def adopt_frame(result: Result, reference: Mapping[str, Camera],
                max_deg: float = 5.0, max_ratio: float = 0.15) -> str:
    """
    Express ``result`` in ``reference``'s world frame (a robust similarity); '' or why not.

    A rig recalibrated from its people keeps the frame its users know (a robot's ``map``, a
    benchmark's ground truth) when the old extrinsics are credible: their cameras spread out
    and, after the similarity, within ``max_deg`` and ``max_ratio`` of the rig's size of the
    new ones (median over the cameras). Only the 7 degrees of freedom of the frame are taken
    from them; the cameras' relative poses stay the people's.
    """
    names = [n for n in result.cameras if n in reference]
    if len(names) < 2:
        return 'fewer than two of its cameras were placed'
    centres = np.array([reference[n].center for n in names])
    spread = float(np.sqrt(((centres - centres.mean(0)) ** 2).sum(1).mean()))
    if not np.isfinite(spread) or spread < 0.05:
        return 'it has no extrinsics (its camera centres coincide)'
    moved, used = align_to(result.cameras, reference, robust=True)
    err = camera_errors({n: moved[n] for n in used}, reference)
    deg = float(np.median([e[0] for e in err.values()]))
    dist = float(np.median([e[1] for e in err.values()]))
    if deg > max_deg or dist > max_ratio * spread:
        return (f'its extrinsics disagree with the people (median {deg:.1f} deg, '
                f'{100 * dist:.0f} cm after a similarity)')
    s, Rs, ts = similarity(result.cameras, reference, used)
    result.cameras = moved
    result.points = s * result.points @ Rs.T + ts
    result.world = (f"the given calibration's (a similarity fitted on {', '.join(used)}; the "
                    f'cameras are a median {deg:.2f} deg / {100 * dist:.1f} cm from its own)')
    result.scale = "the given calibration's (the same similarity)"
    return ''
