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
A rig's cameras and their inputs: calibration, image folders or videos, aligned time points.

Camera names come from the calibration; folders and videos are matched to them as
``mv3dpose track`` matches pose folders (exactly, else loosely: ``cam01.mp4`` is ``cam_01``).
Errors are ``SourceError`` naming the file or folder and both sides of a mismatch.
"""

import os
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple

from mv3dpose_ros.core.geometry.calibration import load_calibration
from mv3dpose_ros.io.media import frame_key, IMAGE_EXTENSIONS, list_images, SourceError
from mv3dpose_ros.io.media import VIDEO_EXTENSIONS
from mv3dpose_ros.io.openpose import match_camera_names


def load_cameras(calibration: str, names: Optional[Sequence[str]] = None) -> dict:
    """Load ``{name: Camera}`` from a calibration file, with errors naming the file."""
    if not os.path.exists(calibration):
        raise SourceError(f'{calibration}: calibration file does not exist')
    try:
        cams = load_calibration(calibration)
    except (ValueError, OSError) as exc:
        raise SourceError(f'{calibration}: cannot read the calibration: {exc}') from exc
    if names:
        missing = [n for n in names if n not in cams]
        if missing:
            raise SourceError(f'{calibration}: no camera {", ".join(missing)} in the '
                              f'calibration (it has {", ".join(cams)})')
        cams = {n: cams[n] for n in names}
    return cams


def camera_sources(root: str, cameras: Sequence[str], calibration: str = '',
                   strict: bool = True) -> Tuple[Dict[str, str], List[str]]:
    """
    Map each camera to its (image or JSON) folder or video file under ``root``.

    ``cameras`` are the calibrated names; folders and videos (by their stem) are matched to them
    as ``mv3dpose track`` matches pose folders (``io.openpose.match_camera_names``: ``cam01.mp4``
    is camera ``cam_01``; a camera fitting several, e.g. a folder and a video, is an error
    naming them). Returns ``(camera -> path, calibrated cameras without data)``. With
    ``strict``, every sub-folder or video of ``root`` must match a calibrated camera, else
    ``SourceError`` names it and the calibration's cameras.
    """
    if not os.path.isdir(root):
        raise SourceError(f'{root}: input folder does not exist')
    entries = sorted(os.listdir(root))
    videos = {e: Path(e).stem for e in entries if e.lower().endswith(VIDEO_EXTENSIONS)
              and os.path.isfile(os.path.join(root, e))}
    folders = [e for e in entries if os.path.isdir(os.path.join(root, e))
               and not e.startswith('.')]
    if not folders and not videos:
        raise SourceError(f'{root}: no per-camera image folders or video files inside')
    try:
        # The loose rule of `mv3dpose track` (cam01.mp4 or cam01/ is camera cam_01); a camera
        # with both a folder and a video is ambiguous.
        matched, _ = match_camera_names(cameras, {**{f: f for f in folders}, **videos}, root,
                                        'folders or videos')
    except ValueError as exc:
        raise SourceError(f'{root}: {exc}') from exc
    found = {cam: os.path.join(root, entry) for cam, entry in matched.items()}
    used = {os.path.basename(p) for p in found.values()}
    orphans = [f for f in folders if f not in used]
    orphans += [v for v in videos if v not in used]
    source = f' in {calibration}' if calibration else ''
    if orphans and strict:
        raise SourceError(f'{root}: {", ".join(orphans)} match no calibrated camera{source} '
                          f'(cameras: {", ".join(cameras)}); rename them or fix the '
                          'calibration')
    if not found:
        raise SourceError(f'{root}: no folder or video matches a calibrated camera{source} '
                          f'(cameras: {", ".join(cameras)})')
    ignored = [c for c in cameras if c not in found]
    return {c: found[c] for c in cameras if c in found}, ignored


def time_points(sources: Dict[str, str]) -> Tuple[List[Optional[int]], Dict[str, list]]:
    """
    Align the images of all cameras into time points.

    When every file name carries a frame number, images with the same number form one time
    point (a camera without that number is absent there); otherwise the i-th images do.
    """
    per_cam = {c: list_images(p) for c, p in sources.items() if os.path.isdir(p)}
    for cam, files in per_cam.items():
        if not files:
            raise SourceError(f'{sources[cam]}: no images ({", ".join(IMAGE_EXTENSIONS)}) '
                              f'for camera {cam}')
    numbered = all(frame_key(f) is not None for files in per_cam.values() for f in files)
    if numbered and per_cam:
        keys = sorted({frame_key(f) for files in per_cam.values() for f in files})
        table = {c: [next((f for f in files if frame_key(f) == k), None) for k in keys]
                 for c, files in per_cam.items()}
        return list(keys), table
    n = max((len(f) for f in per_cam.values()), default=0)
    return [None] * n, {c: files + [None] * (n - len(files)) for c, files in per_cam.items()}
