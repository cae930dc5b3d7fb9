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
Walking people with ground-truth 3D joints.

Bodies: per person a stature (normal, clipped) and per-segment scale factors around
anthropometric proportions of stature (Drillis & Contini / Winter: thigh 0.245, shank 0.246,
upper arm 0.186, forearm 0.146, shoulder height 0.818, ...), so bone lengths differ between
people but stay constant over time. Joints are generated for every joint name any layout uses
(COCO 17, neck, mid hip, upper neck, head top, six foot points) and picked by name for the
requested layout.

Motion: each person steers a smoothly wandering heading (an Ornstein-Uhlenbeck turn rate),
is pushed back from the edge of an elliptic area and away from the others (a social-force
model with a hard minimum separation), and walks at a personal preferred speed. The gait is
a sinusoidal hip/knee/shoulder/elbow pattern whose phase advances with the distance
walked; the pelvis height follows the stance leg, so feet touch the ground.
"""

from dataclasses import dataclass
from typing import Dict, Optional, Tuple

from mv3dpose_ros.core.skeleton import get_layout
import numpy as np

# Every joint the simulator produces, in this order.
SIM_JOINTS: Tuple[str, ...] = (
    'nose', 'left_eye', 'right_eye', 'left_ear', 'right_ear',
    'left_shoulder', 'right_shoulder', 'left_elbow', 'right_elbow', 'left_wrist', 'right_wrist',
    'left_hip', 'right_hip', 'left_knee', 'right_knee', 'left_ankle', 'right_ankle',
    'neck', 'mid_hip', 'upper_neck', 'head_top',
    'left_big_toe', 'left_small_toe', 'left_heel', 'right_big_toe', 'right_small_toe',
    'right_heel')
_J = {n: i for i, n in enumerate(SIM_JOINTS)}

# Segment lengths and offsets as fractions of stature.
_PROPORTIONS = {
    'thigh': 0.245, 'shank': 0.246, 'ankle_height': 0.039,
    'torso': 0.288,            # hip joint centre to shoulder joint centre (vertical)
    'shoulder_half': 0.105, 'hip_half': 0.070,
    'upper_arm': 0.186, 'forearm': 0.146,
    'upper_neck': 0.050, 'head_top': 0.182,   # above the mid-shoulder neck
    'foot_fwd': 0.105, 'heel_back': 0.035, 'toe_spread': 0.025,
}


@dataclass
class BodyConfig:
    """Distribution of body sizes."""

    stature_mean_m: float = 1.72
    stature_std_m: float = 0.08
    stature_range_m: Tuple[float, float] = (1.50, 1.98)
    segment_std: float = 0.03       # relative per-segment variation around the proportions


@dataclass
class WalkConfig:
    """Area and walking behaviour (metres, seconds)."""

    area_radius_m: float = 3.0              # semi-axis along x of the elliptic walking area
    area_radius_y_m: Optional[float] = None  # None: a circle
    center: Tuple[float, float] = (0.0, 0.0)
    speed_range_mps: Tuple[float, float] = (0.8, 1.5)
    turn_rate_std_dps: float = 40.0         # std of the wandering turn rate, degrees/s
    turn_time_s: float = 1.5                # correlation time of the turn rate
    min_separation_m: float = 0.7           # hard minimum distance between pelvises
    personal_space_m: float = 1.2           # range of the mutual repulsion
    hip_swing_deg: float = 18.0             # gait amplitudes at 1.2 m/s (scaled with speed)
    knee_flex_deg: float = 55.0
    arm_swing_deg: float = 20.0
    elbow_flex_deg: float = 20.0


@dataclass
class Body:
    """Fixed dimensions of one person (metres)."""

    stature: float
    seg: Dict[str, float]

    @classmethod
    def sample(cls, rng: np.random.Generator, cfg: BodyConfig) -> 'Body':
        """Draw a body from ``cfg``."""
        lo, hi = cfg.stature_range_m
        h = float(np.clip(rng.normal(cfg.stature_mean_m, cfg.stature_std_m), lo, hi))
        seg = {k: h * v * float(np.clip(rng.normal(1.0, cfg.segment_std), 0.9, 1.1))
               for k, v in _PROPORTIONS.items()}
        # the two sides of a body are equal, so only one factor per segment; rescale so the
        # upright body (ankle, legs, torso, head) is exactly ``h`` tall
        upright = sum(seg[k] for k in ('ankle_height', 'thigh', 'shank', 'torso', 'head_top'))
        return cls(stature=h, seg={k: v * h / upright for k, v in seg.items()})


def _sagittal(angle: np.ndarray, fwd: np.ndarray) -> np.ndarray:
    """Return unit vectors hanging down, rotated forward by ``angle`` rad: [..., 3]."""
    s, c = np.sin(angle)[..., None], np.cos(angle)[..., None]
    return s * fwd + c * np.array([0.0, 0.0, -1.0])


def body_joints(body: Body, root_xy: np.ndarray, heading: np.ndarray, phase: np.ndarray,
                amplitude: np.ndarray, cfg: WalkConfig) -> np.ndarray:
    """
    Pose one body over time: ``[T, len(SIM_JOINTS), 3]`` metres.

    ``root_xy [T, 2]`` is the pelvis ground position, ``heading [T]`` the walking direction
    (rad), ``phase [T]`` the gait phase (rad) and ``amplitude [T]`` in [0, 1.15] scales the
    swing (0 = standing).
    """
    s = body.seg
    n = len(phase)
    fwd = np.stack([np.cos(heading), np.sin(heading), np.zeros(n)], -1)
    left = np.stack([-np.sin(heading), np.cos(heading), np.zeros(n)], -1)
    up = np.array([0.0, 0.0, 1.0])
    a = amplitude
    out = np.zeros((n, len(SIM_JOINTS), 3))
    legs = {}
    for side, sign, ph in (('left', 1.0, phase), ('right', -1.0, phase + np.pi)):
        hip_ang = np.radians(cfg.hip_swing_deg) * a * np.sin(ph)
        # knee flexes in swing (after toe-off) and a little at loading response
        knee = (np.radians(cfg.knee_flex_deg) * a * np.clip(np.sin(ph - 0.6), 0, None) ** 2
                + np.radians(8.0) * a * np.clip(-np.sin(ph + 0.5), 0, None))
        thigh = _sagittal(hip_ang, fwd) * s['thigh']
        shank = _sagittal(hip_ang - knee, fwd) * s['shank']
        legs[side] = (sign, thigh, shank)
    # pelvis height: the longer (stance) leg touches the ground
    drop = np.maximum(-(legs['left'][1] + legs['left'][2])[:, 2],
                      -(legs['right'][1] + legs['right'][2])[:, 2])
    hip_z = drop + s['ankle_height']
    mid_hip = np.concatenate([root_xy, hip_z[:, None]], -1)
    out[:, _J['mid_hip']] = mid_hip
    for side, (sign, thigh, shank) in legs.items():
        hip = mid_hip + sign * s['hip_half'] * left
        knee_p = hip + thigh
        ankle = knee_p + shank
        ground = ankle - np.array([0, 0, 1.0]) * (ankle[:, 2:3] - 0.02)   # foot points ~2 cm
        out[:, _J[f'{side}_hip']] = hip
        out[:, _J[f'{side}_knee']] = knee_p
        out[:, _J[f'{side}_ankle']] = ankle
        out[:, _J[f'{side}_heel']] = ground - s['heel_back'] * fwd
        out[:, _J[f'{side}_big_toe']] = (ground + s['foot_fwd'] * fwd
                                         - sign * 0.2 * s['toe_spread'] * left)
        out[:, _J[f'{side}_small_toe']] = (ground + 0.8 * s['foot_fwd'] * fwd
                                           + sign * s['toe_spread'] * left)
    lean = np.radians(4.0) + np.radians(2.0) * a
    spine = (np.cos(lean)[:, None] * up + np.sin(lean)[:, None] * fwd) * s['torso']
    neck = mid_hip + spine
    out[:, _J['neck']] = neck
    for side, sign, ph in (('left', 1.0, phase + np.pi), ('right', -1.0, phase)):
        shoulder = neck + sign * s['shoulder_half'] * left
        # arms swing opposite to the leg of the same side, slightly abducted
        arm_ang = np.radians(cfg.arm_swing_deg) * a * np.sin(ph)
        upper = _sagittal(arm_ang, fwd) * np.cos(0.12) + sign * np.sin(0.12) * left
        elbow_ang = np.radians(cfg.elbow_flex_deg) * (1 + 0.5 * a * np.clip(np.sin(ph), 0, None))
        fore = _sagittal(arm_ang + elbow_ang, fwd) * np.cos(0.08) + sign * np.sin(0.08) * left
        elbow = shoulder + upper * s['upper_arm']
        out[:, _J[f'{side}_shoulder']] = shoulder
        out[:, _J[f'{side}_elbow']] = elbow
        out[:, _J[f'{side}_wrist']] = elbow + fore * s['forearm']
    h = body.stature
    out[:, _J['upper_neck']] = neck + s['upper_neck'] * up + 0.01 * h * fwd
    out[:, _J['head_top']] = neck + s['head_top'] * up
    out[:, _J['nose']] = neck + 0.108 * h * up + 0.058 * h * fwd
    for side, sign in (('left', 1.0), ('right', -1.0)):
        out[:, _J[f'{side}_eye']] = neck + h * (0.125 * up + 0.046 * fwd + sign * 0.019 * left)
        out[:, _J[f'{side}_ear']] = neck + h * (0.117 * up - 0.004 * fwd + sign * 0.044 * left)
    return out


def _inside(p: np.ndarray, c: np.ndarray, rx: float, ry: float) -> np.ndarray:
    """Return the normalised elliptic radius of points ``[..., 2]`` (< 1 inside)."""
    d = (p - c) / np.array([rx, ry])
    return np.linalg.norm(d, axis=-1)


def walk_paths(num_people: int, num_frames: int, fps: float, cfg: WalkConfig,
               rng: np.random.Generator) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    Simulate pelvis paths: ``(xy [T, M, 2], heading [T, M], speed [T, M])``.

    Paths are smooth, stay inside the elliptic area and keep ``min_separation_m`` apart.
    """
    rx = cfg.area_radius_m
    ry = cfg.area_radius_y_m or rx
    c = np.asarray(cfg.center, dtype=float)
    dt = 1.0 / fps
    # start positions: rejection sampling with separation (area shrinks to 75 % of its size)
    pos = np.zeros((num_people, 2))
    for m in range(num_people):
        for attempt in range(1000):
            r, th = np.sqrt(rng.uniform()) * 0.75, rng.uniform(0, 2 * np.pi)
            p = c + np.array([rx * r * np.cos(th), ry * r * np.sin(th)])
            sep = 1.5 * cfg.min_separation_m if attempt < 500 else cfg.min_separation_m
            if m == 0 or np.min(np.linalg.norm(pos[:m] - p, axis=1)) >= sep:
                break
        else:
            raise ValueError(f'cannot place {num_people} people at least '
                             f'{cfg.min_separation_m} m apart in the area')
        pos[m] = p
    pref = rng.uniform(*cfg.speed_range_mps, size=num_people)
    heading = rng.uniform(0, 2 * np.pi, size=num_people)
    vel = pref[:, None] * np.stack([np.cos(heading), np.sin(heading)], -1)
    turn = np.zeros(num_people)
    sigma = np.radians(cfg.turn_rate_std_dps)
    decay = np.exp(-dt / cfg.turn_time_s)
    xy = np.zeros((num_frames, num_people, 2))
    hd = np.zeros((num_frames, num_people))
    sp = np.zeros((num_frames, num_people))
    for t in range(num_frames):
        xy[t] = pos
        speed = np.linalg.norm(vel, axis=1)
        hd[t] = np.arctan2(vel[:, 1], vel[:, 0])
        sp[t] = speed
        # wandering desired direction
        turn = decay * turn + np.sqrt(1 - decay ** 2) * sigma * rng.normal(size=num_people)
        heading = heading + turn * dt
        desired = pref[:, None] * np.stack([np.cos(heading), np.sin(heading)], -1)
        force = (desired - vel) / 0.5
        # boundary: push towards the centre when beyond 70 % of the area
        rr = _inside(pos, c, rx, ry)
        inward = (c - pos) / np.maximum(np.linalg.norm(c - pos, axis=1, keepdims=True), 1e-9)
        force += (4.0 * np.clip(rr - 0.7, 0, None) / 0.3)[:, None] * inward * pref[:, None]
        force += _avoidance(pos, vel, cfg.personal_space_m)
        vel = vel + force * dt
        speed = np.linalg.norm(vel, axis=1, keepdims=True)
        vel = vel * np.clip(speed, 0, 1.3 * cfg.speed_range_mps[1]) / np.maximum(speed, 1e-9)
        # steer the wandering heading along the realised velocity so it does not fight it
        heading = np.arctan2(vel[:, 1], vel[:, 0]) * 0.2 + 0.8 * _unwrap_to(heading, vel)
        pos = pos + vel * dt
        pos = _separate(pos, cfg.min_separation_m)
        pos = _clip_to_area(pos, c, rx, ry)
    return xy, hd, sp


def _avoidance(pos: np.ndarray, vel: np.ndarray, space: float,
               horizon_s: float = 2.5) -> np.ndarray:
    """Return anticipatory repulsion ``[M, 2]``: steer away from the closest approach ahead."""
    dp = pos[:, None] - pos[None]                                # [M, M, 2]
    dv = vel[:, None] - vel[None]
    dv2 = (dv ** 2).sum(-1)
    tca = np.clip(-(dp * dv).sum(-1) / np.maximum(dv2, 1e-9), 0, horizon_s)
    closest = dp + dv * tca[..., None]
    dist = np.linalg.norm(closest, axis=-1)
    np.fill_diagonal(dist, np.inf)
    push = np.clip(space - dist, 0, None) / space
    away = closest / np.maximum(dist, 1e-9)[..., None]
    # a head-on approach has no sideways component: break the tie with a right-hand turn
    side = np.stack([dp[..., 1], -dp[..., 0]], -1) / np.maximum(
        np.linalg.norm(dp, axis=-1), 1e-9)[..., None]
    away = np.where((dist < 0.1 * space)[..., None], side, away)
    return (6.0 * push[..., None] / (1.0 + tca[..., None]) * away).sum(1)


def _unwrap_to(heading: np.ndarray, vel: np.ndarray) -> np.ndarray:
    """Return ``heading`` shifted by multiples of 2 pi to lie near the velocity angle."""
    ang = np.arctan2(vel[:, 1], vel[:, 0])
    return ang + np.angle(np.exp(1j * (heading - ang)))


def _separate(pos: np.ndarray, min_sep: float) -> np.ndarray:
    """Push overlapping people apart symmetrically until they are ``min_sep`` apart."""
    for _ in range(5):
        diff = pos[:, None] - pos[None]
        dist = np.linalg.norm(diff, axis=-1)
        np.fill_diagonal(dist, np.inf)
        overlap = np.clip(min_sep - dist, 0, None)
        if not overlap.any():
            break
        unit = diff / np.maximum(dist, 1e-9)[..., None]
        pos = pos + 0.5 * (overlap[..., None] * unit).sum(1)
    return pos


def _clip_to_area(pos: np.ndarray, c: np.ndarray, rx: float, ry: float) -> np.ndarray:
    rr = _inside(pos, c, rx, ry)
    scale = np.where(rr > 1.0, 1.0 / np.maximum(rr, 1e-9), 1.0)
    return c + (pos - c) * scale[:, None]


def simulate_people(num_people: int, num_frames: int, fps: float = 25.0,
                    layout: str = 'coco17', walk: Optional[WalkConfig] = None,
                    body: Optional[BodyConfig] = None,
                    rng: Optional[np.random.Generator] = None
                    ) -> Tuple[np.ndarray, Tuple[Body, ...], np.ndarray]:
    """
    Simulate ``num_people`` walking people.

    Returns ``(joints [T, M, J, 3] metres in the layout's order, bodies, root_xy [T, M, 2])``.
    """
    walk = walk or WalkConfig()
    body = body or BodyConfig()
    rng = rng if rng is not None else np.random.default_rng(0)
    lay = get_layout(layout)
    missing = [n for n in lay.joint_names if n not in _J]
    if missing:
        raise ValueError(f'the simulator has no joint(s) {missing} of layout {lay.name!r}')
    index = np.array([_J[n] for n in lay.joint_names])
    bodies = tuple(Body.sample(rng, body) for _ in range(num_people))
    xy, hd, sp = walk_paths(num_people, num_frames, fps, walk, rng)
    out = np.zeros((num_frames, num_people, lay.num_joints, 3))
    for m, b in enumerate(bodies):
        stride = 0.83 * b.stature                     # two steps per gait cycle
        dist = np.concatenate([[0.0], np.cumsum(sp[:-1, m] / fps)])
        phase = rng.uniform(0, 2 * np.pi) + 2 * np.pi * dist / stride
        amp = np.clip(sp[:, m] / 1.2, 0, 1.15)
        heading = np.unwrap(hd[:, m])
        out[:, m] = body_joints(b, xy[:, m], heading, phase, amp, walk)[:, index]
    return out, bodies, xy
