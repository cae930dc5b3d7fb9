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
Which person is which between two cameras, and the pair's essential matrix (steps 2-3).

Each pair of long 2D tracklets is a hypothesis whose correspondences give an essential
matrix (RANSAC); it scores the person pairs it explains over all frames (Hungarian matching
on the median Sampson distance, left/right swaps tried). ``group_people`` joins the pairwise
matches of one frame into people seen by several cameras (union-find with a left/right parity).
"""

from dataclasses import dataclass
from typing import Dict, List, Optional, Sequence, Tuple

import cv2
from mv3dpose_ros.core.selfcal.views import extent_2d, nanmedian, Settings, track_2d, Views
from mv3dpose_ros.core.skeleton import Layout
import numpy as np
from scipy.optimize import linear_sum_assignment


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
    size = np.maximum(extent_2d(pa)[:, None], 1e-9)
    for k, q in enumerate((pb, pb[:, flip])):
        d = _sampson(E, pa[:, None, :, :2], q[None, :, :, :2])
        ok = np.isfinite(d)
        med = nanmedian(d) / size
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
        gate = np.maximum(s.match_gate, gate_min / np.maximum(extent_2d(pa), 1e-9))[:, None]
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
