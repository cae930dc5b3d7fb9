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
from typing import Dict, Iterable, List, Mapping, Optional, Sequence, Tuple

import cv2
from mv3dpose_ros.core.geometry import bundle
from mv3dpose_ros.core.geometry.camera import Camera
from mv3dpose_ros.core.skeleton import get_layout, Layout
import numpy as np
from scipy.optimize import linear_sum_assignment

#: Median adult stature [m] (the default ``--person-height``).
ADULT_HEIGHT_M = 1.70
#: Height above the floor of a standing person's joints, as a fraction of stature
#: (Drillis & Contini segment proportions, as tabulated by Winter).
STATURE_FRACTION = {'head_top': 1.0, 'left_eye': 0.936, 'right_eye': 0.936,
                    'left_ear': 0.925, 'right_ear': 0.925, 'nose': 0.915,
                    'left_shoulder': 0.818, 'right_shoulder': 0.818}
ANKLE_FRACTION = 0.039


class SelfCalError(ValueError):
    """Input the rig cannot be calibrated from; the message says what and why."""


@dataclass
class Settings:
    """Knobs of the estimation (defaults fit 25-60 fps detections of OpenPose-like models)."""

    min_confidence: float = 0.3     # joints below are not used
    min_joints: int = 6             # people with fewer confident joints are not used
    track_gate: float = 0.35        # 2D tracklets: median joint step / person height
    match_gate: float = 0.05        # person match: median Sampson distance / person height
    match_gate_min_px: float = 4.0  # ... but never stricter than this
    hypotheses: int = 8             # longest tracklets per view tried as pair hypotheses
    probe_frames: int = 40          # frames a hypothesis is scored on before the best's all
    min_pair_frames: int = 10       # person matches a camera pair needs to be used
    min_frames: int = 10            # frames with people in at least two cameras
    loss_px: float = 3.0            # robust loss scale of the bundle adjustment
    outlier_px: float = 25.0        # observations dropped before the last adjustment
    max_points: int = 20000         # joints kept for the adjustment (evenly over frames)
    init_points: int = 3000         # ... and while cameras are being placed
    odd_ratio: float = 4.0          # a camera this many times further off the others'
    odd_px: float = 25.0            # ... triangulations than the rest and this far: unplaced
    bumped_ratio: float = 4.0       # refine: a camera whose image moves this many times more
    bumped_px: float = 8.0          # ... than the others' and this far, fitted to the others'
    #                                 triangulations, is re-placed and adjusted alone
    seed: int = 0


@dataclass
class Views:
    """Per camera and frame the people as ``[P, J, 3]``: normalised x, y and confidence."""

    cameras: List[str]
    frames: List[int]
    people: Dict[str, List[np.ndarray]]
    focal: Dict[str, float]
    tracks: Dict[str, List[np.ndarray]] = field(default_factory=dict)


@dataclass
class PairResult:
    """What one camera pair's estimation rests on."""

    a: str
    b: str
    E: Optional[np.ndarray]
    matches: Dict[int, List[Tuple[int, int, bool, float]]]  # frame -> (pa, pb, flip, cost)
    person_frames: int = 0        # person matches over all frames
    correspondences: int = 0      # joints behind the final essential matrix
    inliers: int = 0              # of them consistent with it
    note: str = ''


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


# ------------------------------------------------------------------------------------ inputs
def normalise_views(sequence: Iterable[Tuple[int, Mapping[str, np.ndarray]]],
                    intrinsics: Mapping[str, Camera], layout: str,
                    settings: Optional[Settings] = None) -> Views:
    """
    Undistort every frame's keypoints (pixels + confidence) with the cameras' intrinsics.

    Joints under ``min_confidence`` get confidence 0; people with fewer than ``min_joints``
    joints left are dropped.
    """
    s = settings or Settings()
    num = get_layout(layout).num_joints
    names = list(intrinsics)
    people: Dict[str, List[np.ndarray]] = {c: [] for c in names}
    frames: List[int] = []
    for frame, views in sequence:
        frames.append(int(frame))
        for c in names:
            p = np.asarray(views.get(c, np.zeros((0, num, 3))), dtype=float).reshape(-1, num, 3)
            conf = np.where(p[..., 2] >= s.min_confidence, p[..., 2], 0.0)
            xy = intrinsics[c].undistort(np.where(conf[..., None] > 0, p[..., :2], np.nan))
            out = np.concatenate([xy, conf[..., None]], axis=-1)
            out[conf == 0] = [np.nan, np.nan, 0.0]
            people[c].append(out[(conf > 0).sum(1) >= s.min_joints])
    return Views(names, frames, people, {c: intrinsics[c].focal for c in names})


def _nanmedian(a: np.ndarray) -> np.ndarray:
    """Return the median over the last axis ignoring NaN (numpy's is 20x slower on small rows)."""
    a = np.sort(a, axis=-1)                  # NaN sort last
    n = np.isfinite(a).sum(-1)
    lo = np.take_along_axis(a, np.maximum((n - 1) // 2, 0)[..., None], -1)[..., 0]
    hi = np.take_along_axis(a, np.maximum(n // 2, 0)[..., None], -1)[..., 0]
    return np.where(n > 0, 0.5 * (lo + hi), np.nan)


def _height(p: np.ndarray) -> np.ndarray:
    """Return the ``[P]`` 2D extents (max of box width and height) of people ``[P, J, 3]``."""
    if not len(p):
        return np.zeros(0)
    with np.errstate(invalid='ignore'):
        lo, hi = np.nanmin(p[..., :2], axis=1), np.nanmax(p[..., :2], axis=1)
    return np.nan_to_num(np.max(hi - lo, axis=1), nan=0.0)


def track_2d(frames: List[np.ndarray], gate: float = 0.35) -> List[np.ndarray]:
    """
    Follow people from frame to frame in one view; return per frame ``[P]`` tracklet ids.

    Consecutive detections are linked by Hungarian matching on the median joint distance
    relative to the person's size, under ``gate``.
    """
    ids, prev, prev_ids, nxt = [], np.zeros((0, 0, 3)), np.zeros(0, int), 0
    for p in frames:
        cur = np.full(len(p), -1)
        if len(p) and len(prev):
            d = np.linalg.norm(p[:, None, :, :2] - prev[None, :, :, :2], axis=-1)
            cost = _nanmedian(d) if d.size else d.sum(-1)
            size = np.maximum(_height(p)[:, None], _height(prev)[None, :])
            cost = np.where(np.isfinite(cost), cost / np.maximum(size, 1e-9), 1e9)
            rows, cols = linear_sum_assignment(cost)
            for r, c in zip(rows, cols):
                if cost[r, c] < gate:
                    cur[r] = prev_ids[c]
        for k in np.flatnonzero(cur < 0):
            cur[k] = nxt
            nxt += 1
        ids.append(cur)
        prev, prev_ids = p, cur
    return ids


# ------------------------------------------------------------------------------------ pairs
def _sampson(E: np.ndarray, xa: np.ndarray, xb: np.ndarray) -> np.ndarray:
    """Return Sampson distances (normalised units) of ``x_b^T E x_a = 0`` for ``[..., 2]``."""
    ha = np.concatenate([xa, np.ones(xa.shape[:-1] + (1,))], -1)
    hb = np.concatenate([xb, np.ones(xb.shape[:-1] + (1,))], -1)
    Ea = ha @ E.T           # E x_a
    Eb = hb @ E             # E^T x_b
    num = np.sum(hb * Ea, -1)
    den = Ea[..., 0] ** 2 + Ea[..., 1] ** 2 + Eb[..., 0] ** 2 + Eb[..., 1] ** 2
    with np.errstate(invalid='ignore', divide='ignore'):
        return np.abs(num) / np.sqrt(den)


def _pair_cost(E: np.ndarray, pa: np.ndarray, pb: np.ndarray, flip: np.ndarray,
               min_common: int = 5) -> Tuple[np.ndarray, np.ndarray]:
    """Return ``[Pa, Pb]`` median Sampson distances / person size, and whether flipped."""
    best = np.full((len(pa), len(pb)), np.inf)
    flipped = np.zeros(best.shape, bool)
    if not len(pa) or not len(pb):
        return best, flipped
    size = np.maximum(_height(pa)[:, None], 1e-9)
    for k, q in enumerate((pb, pb[:, flip])):
        d = _sampson(E, pa[:, None, :, :2], q[None, :, :, :2])
        ok = np.isfinite(d)
        med = _nanmedian(d) / size
        med = np.where((ok.sum(2) >= min_common) & np.isfinite(med), med, np.inf)
        better = med < best
        best = np.where(better, med, best)
        flipped = np.where(better, bool(k), flipped)
    return best, flipped


def _score(E: np.ndarray, views: Views, a: str, b: str, flip: np.ndarray, s: Settings,
           frames: Optional[Sequence[int]] = None
           ) -> Dict[int, List[Tuple[int, int, bool, float]]]:
    """Match people per frame under ``E``; return frame -> accepted (pa, pb, flip, cost)."""
    out = {}
    gate_min = s.match_gate_min_px / min(views.focal[a], views.focal[b])
    for f in range(len(views.frames)) if frames is None else frames:
        pa, pb = views.people[a][f], views.people[b][f]
        if not len(pa) or not len(pb):
            continue
        cost, flipped = _pair_cost(E, pa, pb, flip)
        gate = np.maximum(s.match_gate, gate_min / np.maximum(_height(pa), 1e-9))[:, None]
        finite = np.where(np.isfinite(cost), cost, 1e9)
        rows, cols = linear_sum_assignment(finite)
        keep = [(int(r), int(c), bool(flipped[r, c]), float(cost[r, c]))
                for r, c in zip(rows, cols) if cost[r, c] < gate[r, 0]]
        if keep:
            out[f] = keep
    return out


def _correspondences(views: Views, a: str, b: str, pairs, flip: np.ndarray):
    """Stack the joints both views see of matched people: ``(xa [N, 2], xb [N, 2], w)``."""
    xa, xb, w = [], [], []
    for f, items in pairs:
        for pa, pb, flipped in items:
            p, q = views.people[a][f][pa], views.people[b][f][pb]
            if flipped:
                q = q[flip]
            ok = (p[:, 2] > 0) & (q[:, 2] > 0)
            xa.append(p[ok, :2])
            xb.append(q[ok, :2])
            w.append(np.minimum(p[ok, 2], q[ok, 2]))
    if not xa:
        return np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0)
    return np.concatenate(xa), np.concatenate(xb), np.concatenate(w)


def _essential(xa: np.ndarray, xb: np.ndarray, thr: float, seed: int, limit: int = 0,
               iterations: int = 1000):
    """
    Return ``(E, inlier mask)`` by 5-point RANSAC on normalised coordinates, or None.

    ``limit``: at most this many correspondences (evenly picked) feed the RANSAC, the mask
    is then that of all of them; a wrong hypothesis has few inliers and would otherwise run
    every iteration on every joint.
    """
    if len(xa) < 8:
        return None, None
    sel = np.linspace(0, len(xa) - 1, limit).astype(int) if limit and len(xa) > limit \
        else slice(None)
    cv2.setRNGSeed(seed)
    E, mask = cv2.findEssentialMat(xa[sel].reshape(-1, 1, 2), xb[sel].reshape(-1, 1, 2),
                                   np.eye(3), method=cv2.RANSAC, prob=0.999, threshold=thr,
                                   maxIters=iterations)
    if E is None or E.shape[0] < 3:
        return None, None
    E = E[:3]
    if not isinstance(sel, slice):
        mask = _sampson(E, xa, xb) < thr
    return E, np.asarray(mask).ravel().astype(bool)


def estimate_pair(views: Views, a: str, b: str, layout: Layout,
                  settings: Optional[Settings] = None) -> PairResult:
    """
    Estimate the person matching and essential matrix between cameras ``a`` and ``b``.

    Hypotheses: pairs of the longest 2D tracklets of both views (with one person per frame
    the right one is among them); each is scored by the person matches its essential matrix
    explains over all frames, and the best is re-estimated from all of them, twice.
    """
    s = settings or Settings()
    flip = layout.flip_permutation
    thr = 2.0 / min(views.focal[a], views.focal[b])     # RANSAC threshold, 2 px
    result = PairResult(a, b, None, {})
    tracks = {c: views.tracks.get(c) or track_2d(views.people[c], s.track_gate) for c in (a, b)}
    both = [f for f in range(len(views.frames))
            if len(views.people[a][f]) and len(views.people[b][f])]
    if len(both) < 3:
        result.note = f'people seen by both in {len(both)} frame(s)'
        return result
    lengths = {}
    for c in (a, b):
        ids = np.concatenate([tracks[c][f] for f in both])
        u, n = np.unique(ids, return_counts=True)
        lengths[c] = u[np.argsort(-n)][:s.hypotheses]
    probe = both[::max(1, len(both) // s.probe_frames)]   # hypotheses scored on these
    best, best_score = None, 0
    for ta in lengths[a]:
        for tb in lengths[b]:
            items = []
            for f in both:
                ia = np.flatnonzero(tracks[a][f] == ta)
                ib = np.flatnonzero(tracks[b][f] == tb)
                if len(ia) and len(ib):
                    items.append((f, [(int(ia[0]), int(ib[0]), False)]))
            if len(items) < 3:
                continue
            xa, xb, _ = _correspondences(views, a, b, items, flip)
            E, _ = _essential(xa, xb, thr, s.seed, 400, 300)
            if E is None:
                continue
            score = sum(len(v) for v in _score(E, views, a, b, flip, s, probe).values())
            if score > best_score:
                best, best_score = E, score
    if best is None:
        result.note = 'no person pairing gave an essential matrix'
        return result
    E, matches = best, _score(best, views, a, b, flip, s)
    for k in range(3):
        items = [(f, [(pa, pb, fl) for pa, pb, fl, _ in v]) for f, v in matches.items()]
        xa, xb, _ = _correspondences(views, a, b, items, flip)
        E2, mask = _essential(xa, xb, thr, s.seed, 3000)
        if E2 is None:
            break
        if k == 0:
            result.correspondences = len(xa)
            result.inliers = int((_sampson(E, xa, xb) < thr).sum())
        m2 = _score(E2, views, a, b, flip, s)
        if sum(len(v) for v in m2.values()) < sum(len(v) for v in matches.values()):
            break
        E, matches = E2, m2
        result.correspondences, result.inliers = len(xa), int(mask.sum())
    result.E, result.matches = E, matches
    result.person_frames = sum(len(v) for v in matches.values())
    return result


# ------------------------------------------------------------------------------------ people
class _Union:
    """Union-find over (camera, person) nodes with a left/right parity per node."""

    def __init__(self):
        self.parent, self.parity, self.cams = {}, {}, {}

    def find(self, n):
        if n not in self.parent:
            self.parent[n], self.parity[n], self.cams[n] = n, False, {n[0]}
        root, par = n, False
        while self.parent[root] != root:
            par ^= self.parity[root]
            root = self.parent[root]
        return root, par

    def join(self, u, v, flip: bool) -> bool:
        (ru, pu), (rv, pv) = self.find(u), self.find(v)
        if ru == rv:
            return (pu ^ pv) == flip
        if self.cams[ru] & self.cams[rv]:
            return False          # would put two people of one camera into one
        self.parent[rv], self.parity[rv] = ru, pu ^ pv ^ flip
        self.cams[ru] |= self.cams[rv]
        return True


def group_people(views: Views, pairs: Sequence[PairResult]
                 ) -> List[List[Dict[str, Tuple[int, bool]]]]:
    """
    Join the pairwise person matches of each frame into people seen by several cameras.

    Returns per frame a list of people, each ``{camera: (person index, flipped)}`` with two
    cameras or more; the flip is relative to the person's majority left/right labelling.
    """
    out = []
    for f in range(len(views.frames)):
        edges = []
        for pr in pairs:
            for pa, pb, fl, cost in pr.matches.get(f, ()):
                edges.append((cost, (pr.a, pa), (pr.b, pb), fl))
        uf = _Union()
        for _, u, v, fl in sorted(edges, key=lambda e: e[0]):
            uf.join(u, v, fl)
        groups: Dict[tuple, Dict[str, Tuple[int, bool]]] = {}
        for n in list(uf.parent):
            root, par = uf.find(n)
            groups.setdefault(root, {})[n[0]] = (n[1], par)
        people = []
        for g in groups.values():
            if len(g) < 2:
                continue
            if sum(par for _, par in g.values()) * 2 > len(g):
                g = {c: (p, not par) for c, (p, par) in g.items()}
            people.append(g)
        out.append(people)
    return out


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
        pts = subset_points(pts, _even(n_pt, max_points, pts.person))
    return pts


def _even(n: int, keep: int, person: np.ndarray) -> np.ndarray:
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


def _drop_observations(pts: Points, keep: np.ndarray) -> Points:
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
    with _quiet():
        typical = np.nanmedian(length, axis=0)
        ratio = np.abs(np.log(length / typical))
        off = np.nanmedian(ratio, axis=1)
    good = ~(off > np.log(tolerance))          # NaN (too few bones) stays
    return good[pts.person]


# ------------------------------------------------------------------------------------ rig
def _observed_by(prob: bundle.Problem, cams: Sequence[int]) -> bundle.Problem:
    o = np.isin(prob.camera, list(cams))
    return bundle.Problem(prob.camera[o], prob.point[o], prob.xy[o], prob.weight[o],
                          prob.focal)


def _bundle(R, t, pts: Points, placed: Sequence[int], fixed, s: Settings,
            max_nfev: int = 50, limit: int = 0):
    """Adjust the ``placed`` cameras but ``fixed`` (one or several) and their points."""
    if limit and len(pts.frame) > limit:
        R, t, _ = _bundle(R, t, subset_points(pts, _even(len(pts.frame), limit, pts.person)),
                          placed, fixed, s, max_nfev)
        return R, t, bundle.triangulate(R, t, _observed_by(pts.prob, placed), len(pts.frame))
    sub = _observed_by(pts.prob, placed)
    X = bundle.triangulate(R, t, sub, len(pts.frame))
    # gross errors (wrong person matches, points behind a camera) out before adjusting:
    # a robust loss bounds their pull only once they are near, far off they steer the rig
    res = bundle.residuals_px(R, t, np.nan_to_num(X), sub)
    med = float(np.nanmedian(res)) if np.isfinite(res).any() else np.inf
    gate = np.isfinite(res) & (res < max(2 * s.outlier_px, 8 * med))
    sub = bundle.Problem(sub.camera[gate], sub.point[gate], sub.xy[gate], sub.weight[gate],
                         sub.focal)
    X = bundle.triangulate(R, t, sub, len(pts.frame))
    ok = np.isfinite(X).all(1)
    if not ok.any():
        return R, t, X
    new = np.full(len(X), -1)
    new[ok] = np.arange(ok.sum())
    o = ok[sub.point]
    sub = bundle.Problem(sub.camera[o], new[sub.point[o]], sub.xy[o], sub.weight[o], sub.focal)
    fixed_all = [c for c in range(len(R)) if c not in set(placed)] + list(np.atleast_1d(fixed))
    R, t, Xo, _ = bundle.adjust(R, t, X[ok], sub, fixed=fixed_all, loss_px=s.loss_px,
                                max_nfev=max_nfev)
    X[ok] = Xo
    return R, t, X


def _pnp(X: np.ndarray, prob: bundle.Problem, c: int, focal: float, px: float = 4.0):
    """Return camera ``c``'s ``(R, t)`` from its views of the points ``X`` (RANSAC), or None."""
    o = (prob.camera == c) & np.isfinite(X).all(1)[prob.point]
    obj, img = X[prob.point[o]], prob.xy[o]
    if len(obj) < 12:
        return None
    okp, rvec, tvec, inl = cv2.solvePnPRansac(obj, img, np.eye(3), None,
                                              reprojectionError=px / focal, iterationsCount=500,
                                              confidence=0.999, flags=cv2.SOLVEPNP_EPNP)
    if not okp or inl is None or len(inl) < 12:
        return None
    inl = inl.ravel()
    _, rvec, tvec = cv2.solvePnP(obj[inl], img[inl], np.eye(3), None, rvec, tvec, True,
                                 cv2.SOLVEPNP_ITERATIVE)
    return cv2.Rodrigues(rvec)[0], tvec.ravel()


def held_out_px(R: np.ndarray, t: np.ndarray, pts: Points, cams: Sequence[int],
                exclude: Sequence[int] = (), shift: bool = False) -> Dict[int, float]:
    """
    Return per camera the median px between its joints and the others' triangulations.

    Each camera of ``cams`` is checked against the people the other cameras (not in
    ``exclude``) triangulate without it (the best of all of them and all but one): a camera
    that sees other instants or other people, or was bumped, stands out; one fitted into an
    adjustment cannot hide its disagreement. NaN where fewer than 30 joints can be checked.
    ``shift``: instead, how far (median px) its image of those people moves when its pose is
    fitted to them: the systematic part only, which noise does not inflate (a bumped camera).
    """
    out = {}
    for c in cams:
        others = [o for o in cams if o != c and o not in set(exclude)]
        # with three others or more, also without each one: an odd camera among the others
        # must not make a good one look odd
        trials = [others] + ([[o for o in others if o != e] for e in others]
                             if len(others) >= 3 else [])
        out[c] = float('nan')
        for use in trials:
            X = bundle.triangulate(R, t, _observed_by(pts.prob, use), len(pts.frame))
            own = _observed_by(pts.prob, [c])
            r = bundle.residuals_px(R, t, X, own)
            ok = np.isfinite(r)
            if ok.sum() < 30:
                continue
            v = float(np.median(r[ok]))
            if shift:
                v = _pose_shift_px(R[c], t[c], X[own.point[ok]], own.xy[ok], r[ok],
                                   float(pts.prob.focal[c]))
            if not v >= out[c]:
                out[c] = v
    return out


def _pose_shift_px(R: np.ndarray, t: np.ndarray, X: np.ndarray, xy: np.ndarray,
                   r: np.ndarray, focal: float) -> float:
    """Return the median px the camera's image of ``X`` moves when its pose is fitted to them."""
    keep = r < max(50.0, 3 * float(np.median(r)))
    if keep.sum() < 12:
        return float('nan')
    rvec = cv2.Rodrigues(R)[0]
    rvec, tvec = cv2.solvePnPRefineLM(X[keep].reshape(-1, 1, 3), xy[keep].reshape(-1, 1, 2),
                                      np.eye(3), None, rvec.copy(), t.reshape(3, 1).copy())
    R2 = cv2.Rodrigues(rvec)[0]
    a, b = X @ R.T + t, X @ R2.T + tvec.ravel()
    with np.errstate(divide='ignore', invalid='ignore'):
        d = np.linalg.norm(a[:, :2] / a[:, 2:] - b[:, :2] / b[:, 2:], axis=1) * focal
    d = d[np.isfinite(d)]
    return float(np.median(d)) if len(d) else float('nan')


def odd_cameras(R: np.ndarray, t: np.ndarray, pts: Points, cams: Sequence[int],
                ratio: float, floor_px: float, shift: bool = False
                ) -> Tuple[List[int], Dict[int, float]]:
    """
    Return ``(odd, px)``: cameras whose ``held_out_px`` stands out, worst first, and the figures.

    One by one, the camera over ``ratio`` times the median of the rest and over ``floor_px``
    is set aside (and no longer triangulates for the others) while three cameras remain.
    """
    odd: List[int] = []
    px = held_out_px(R, t, pts, cams, shift=shift)
    while len(cams) - len(odd) >= 3:
        rest = {c: v for c, v in px.items() if c not in odd and np.isfinite(v)}
        if len(rest) < 3:
            break
        worst = max(rest, key=rest.get)
        med = float(np.median([v for c, v in rest.items() if c != worst]))
        if rest[worst] > max(floor_px, ratio * med):
            odd.append(worst)
            px = {**held_out_px(R, t, pts, cams, odd, shift), **{c: px[c] for c in odd}}
        else:
            break
    return odd, px


def _initial_rig(views: Views, pts: Points, pairs: Sequence[PairResult], s: Settings):
    """Place cameras one by one: best pair by its essential matrix, the rest by PnP."""
    n = len(views.cameras)
    idx = {c: k for k, c in enumerate(views.cameras)}
    R, t = np.tile(np.eye(3), (n, 1, 1)), np.zeros((n, 3))
    best = max(pairs, key=lambda p: p.inliers)
    a, b = idx[best.a], idx[best.b]
    # correspondences of that pair through the grouped points
    prob = pts.prob
    xa = np.full((len(pts.frame), 2), np.nan)
    xb = np.full((len(pts.frame), 2), np.nan)
    xa[prob.point[prob.camera == a]] = prob.xy[prob.camera == a]
    xb[prob.point[prob.camera == b]] = prob.xy[prob.camera == b]
    ok = np.isfinite(xa).all(1) & np.isfinite(xb).all(1)
    _, Rb, tb, _ = cv2.recoverPose(best.E, xa[ok].reshape(-1, 1, 2), xb[ok].reshape(-1, 1, 2),
                                   np.eye(3))
    R[b], t[b] = Rb, tb.ravel()
    placed = [a, b]
    R, t, X = _bundle(R, t, pts, placed, a, s, 30, s.init_points)
    why = {}
    while len(placed) < n:
        finite = np.isfinite(X).all(1)
        counts = {}
        for c in range(n):
            if c in placed or views.cameras[c] in why:
                continue
            o = (prob.camera == c) & finite[prob.point]
            counts[c] = int(o.sum())
        if not counts:
            break
        c = max(counts, key=counts.get)
        name = views.cameras[c]
        if counts[c] < 30:
            why[name] = (f'sees only {counts[c]} joints the placed cameras triangulated '
                         '(need 30)')
            continue
        pose = _pnp(X, prob, c, views.focal[name])
        if pose is None:
            why[name] = 'no consistent pose from its joints (PnP found no inlier set)'
            continue
        R[c], t[c] = pose
        placed.append(c)
        R, t, X = _bundle(R, t, pts, placed, a, s, 30, s.init_points)
    return R, t, placed, why, a


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


# ------------------------------------------------------------------------------------ world
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
    with np.errstate(invalid='ignore'), _quiet():
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


class _quiet:
    """Silence numpy's 'mean of empty slice' warnings of all-NaN rows."""

    def __enter__(self):
        import warnings
        self._w = warnings.catch_warnings()
        self._w.__enter__()
        warnings.simplefilter('ignore', RuntimeWarning)

    def __exit__(self, *exc):
        self._w.__exit__(*exc)


# ------------------------------------------------------------------------------------ checks
def check_views(views: Views, s: Settings) -> None:
    """Raise ``SelfCalError`` for too few people or frames, or people who barely move."""
    shared = sum(sum(len(views.people[c][f]) > 0 for c in views.cameras) >= 2
                 for f in range(len(views.frames)))
    if not any(len(p) for c in views.cameras for p in views.people[c]):
        raise SelfCalError(f'no people with {s.min_joints} joints of confidence >= '
                           f'{s.min_confidence} in any of {len(views.frames)} frames')
    if shared < s.min_frames:
        raise SelfCalError(f'too few frames: people are seen by two cameras or more in '
                           f'{shared} of {len(views.frames)} frames (need {s.min_frames}; '
                           'record longer, with people walking through the whole rig)')
    spans = []
    for c in views.cameras:                  # how far each person moves in each view
        ids = track_2d(views.people[c], s.track_gate)
        roots, sizes, who = [], [], []
        for p, k in zip(views.people[c], ids):
            if len(p):
                with _quiet():
                    roots.append(np.nanmean(p[..., :2], axis=1))
                sizes.append(_height(p))
                who.append(k)
        if not roots:
            continue
        roots, sizes, who = np.concatenate(roots), np.concatenate(sizes), np.concatenate(who)
        for k in np.unique(who):
            r = roots[who == k]
            if len(r) >= 5:
                span = np.max(np.nanpercentile(r, 95, axis=0) - np.nanpercentile(r, 5, axis=0))
                spans.append(span / max(float(np.median(sizes[who == k])), 1e-9))
    if spans and max(spans) < 0.25:
        raise SelfCalError(f'degenerate motion: the people barely move (in every view each '
                           f'one moves at most {max(spans):.2f} of their height); a few poses '
                           'do not fix the cameras: walk through the whole capture volume')


# ------------------------------------------------------------------------------------ main
def _final_adjustment(R, t, pts: Points, placed: Sequence[int], fixed, s: Settings,
                      lay: Layout):
    """Adjust, drop observations far off and implausible people, adjust again."""
    R, t, X = _bundle(R, t, pts, placed, fixed, s, 50)
    res = bundle.residuals_px(R, t, X, pts.prob)
    thr = max(s.outlier_px, 5 * float(np.nanmedian(res)))
    keep = np.isfinite(res) & (res < thr) & plausible_people(X, pts, lay)[pts.prob.point]
    pts = _drop_observations(pts, keep)
    R, t, X = _bundle(R, t, pts, placed, fixed, s, 50)
    return R, t, X, pts


def _refine_start(R, t, pts: Points, placed: List[int], s: Settings, names, log):
    """
    Refine: find the cameras the people disagree with and re-place them; return the fixed.

    A bumped camera's joints stand out from where the other cameras triangulate them; it is
    placed again by PnP on those triangulations and adjusted alone, the others holding the
    given frame. Without such a camera all but the first move (a drifted rig).
    """
    bumped, px = odd_cameras(R, t, pts, placed, s.bumped_ratio, s.bumped_px, shift=True)
    if not bumped:
        log('refine: no camera stands out (median px its image moves when fitted to the '
            "others' triangulations: "
            + ', '.join(f'{names[c]} {v:.1f}' for c, v in px.items()) + '); adjusting all')
        return placed[0]
    good = [c for c in placed if c not in bumped]
    X = bundle.triangulate(R, t, _observed_by(pts.prob, good), len(pts.frame))
    for c in bumped:
        pose = _pnp(X, pts.prob, c, float(pts.prob.focal[c]), 2 * s.loss_px)
        if pose is not None:
            R[c], t[c] = pose
    log('refine: ' + ', '.join(f'{names[c]} ({px[c]:.1f} px)' for c in bumped)
        + " stand(s) out: fitted to the others' triangulations their image moves that much ("
        + ', '.join(f'{names[c]} {px[c]:.1f}' for c in good) + ' px): adjusted alone, '
        + ', '.join(names[c] for c in good) + ' hold the frame')
    return good


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
            R, t, placed, why, ref = _initial_rig(views, pts, usable, s)
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
        pts = _drop_observations(pts, np.isin(pts.prob.camera, placed))
        fixed = ref
        if initial is not None:
            fixed = _refine_start(R, t, pts, placed, s, names, log)
        R, t, X, kept = _final_adjustment(R, t, pts, placed, fixed, s, lay)
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
