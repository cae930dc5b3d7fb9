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
A complete synthetic scene: rig, walking people with ground truth, and noisy 2D detections.

>>> scene = make_scene(num_cameras=4, num_people=3, num_frames=100, seed=1)
>>> for stamp, views in scene.frames():
...     tracks = fusion.step(views, stamp)

Everything derives from ``seed`` through independent random streams (rig jitter, people,
detector), so changing the detector noise keeps the same people walking the same paths.
"""

from dataclasses import dataclass, field
from typing import Dict, Iterator, List, Optional, Tuple

from mv3dpose_ros.core.geometry.camera import Camera
from mv3dpose_ros.sim.detector import detect, DetectorNoise
from mv3dpose_ros.sim.people import Body, BodyConfig, simulate_people, WalkConfig
from mv3dpose_ros.sim.rig import make_rig, RigConfig
import numpy as np


@dataclass
class Scene:
    """
    A synthetic multi-camera sequence with ground truth.

    Attributes: ``cameras`` (name -> Camera), ``layout`` (joint layout of everything),
    ``fps``, ``stamps [T]`` seconds, ``gt [T, M, J, 3]`` metres (world, z up; person ``m`` keeps
    index ``m`` for the whole sequence, its ground-truth id), ``bodies`` (per person
    dimensions), ``views`` (per frame: camera -> ``[P, J, 3]`` raw pixels + confidence, the
    input of ``Fusion.step``), ``sources`` (per frame: camera -> ``[P]`` index of the GT person
    behind each detection, -1 for false positives), ``noise`` (the detector model used).
    """

    cameras: Dict[str, Camera]
    layout: str
    fps: float
    stamps: np.ndarray
    gt: np.ndarray
    bodies: Tuple[Body, ...]
    views: List[Dict[str, np.ndarray]]
    sources: List[Dict[str, np.ndarray]]
    noise: DetectorNoise
    seed: Optional[int] = None
    rig: RigConfig = field(default_factory=RigConfig)
    walk: WalkConfig = field(default_factory=WalkConfig)

    @property
    def num_frames(self) -> int:
        """Return the number of frames T."""
        return int(self.gt.shape[0])

    @property
    def num_people(self) -> int:
        """Return the number of people M."""
        return int(self.gt.shape[1])

    def frames(self) -> Iterator[Tuple[float, Dict[str, np.ndarray]]]:
        """Yield ``(stamp, views)`` per frame, ready for ``Fusion.step(views, stamp)``."""
        for t in range(self.num_frames):
            yield float(self.stamps[t]), self.views[t]

    def redetect(self, noise: DetectorNoise, seed: Optional[int] = None) -> 'Scene':
        """Return the same scene seen through another detector model."""
        views, sources = detect(self.cameras, self.gt, self.layout, noise,
                                rng=_streams(self.seed if seed is None else seed)[2])
        return Scene(self.cameras, self.layout, self.fps, self.stamps, self.gt, self.bodies,
                     views, sources, noise, self.seed if seed is None else seed, self.rig,
                     self.walk)


def _streams(seed: Optional[int]) -> List[np.random.Generator]:
    return [np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(3)]


def make_scene(num_cameras: int = 4, num_people: int = 3, num_frames: int = 100,
               fps: float = 25.0, layout: str = 'coco17', seed: Optional[int] = 0,
               noise: Optional[DetectorNoise] = None, rig: Optional[RigConfig] = None,
               walk: Optional[WalkConfig] = None, body: Optional[BodyConfig] = None,
               start_stamp: float = 0.0) -> Scene:
    """
    Build a scene: ``num_cameras`` around an area, ``num_people`` walking for ``num_frames``.

    ``rig.num_cameras`` is overridden by ``num_cameras``. Same arguments and seed, same scene.
    """
    if num_frames < 1 or num_people < 0 or fps <= 0:
        raise ValueError('need num_frames >= 1, num_people >= 0 and fps > 0')
    rig = RigConfig(**{**(rig or RigConfig()).__dict__, 'num_cameras': num_cameras})
    walk = walk or WalkConfig()
    noise = noise or DetectorNoise()
    r_rig, r_people, r_det = _streams(seed)
    cameras = make_rig(rig, seed=int(r_rig.integers(2 ** 31)))
    gt, bodies, _ = simulate_people(num_people, num_frames, fps, layout, walk, body, r_people)
    views, sources = detect(cameras, gt, layout, noise, rng=r_det)
    stamps = start_stamp + np.arange(num_frames) / fps
    return Scene(cameras, layout, fps, stamps, gt, bodies, views, sources, noise, seed, rig,
                 walk)
