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

"""Pictures to files: a PNG, an animated GIF or a video, each complete or not at all."""

import os
from typing import Sequence

import cv2
from mv3dpose_ros.core.files import temp_path_beside
import numpy as np


class RenderError(ValueError):
    """Input that cannot be rendered; the text names the file and the reason."""


def _atomic_path(output: str) -> str:
    try:
        return temp_path_beside(output)
    except FileNotFoundError as exc:
        raise RenderError(str(exc)) from exc


def write_png(image: np.ndarray, output: str) -> str:
    """Write a picture atomically (a temp file renamed into place)."""
    tmp = _atomic_path(output)
    try:
        if not cv2.imwrite(tmp, image):
            raise RenderError(f'{output}: OpenCV could not write the picture')
        os.replace(tmp, output)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return output


def write_animation(frames: Sequence[np.ndarray], output: str, fps: float,
                    max_width: int = 720) -> str:
    """Write an animated GIF (``.gif``) or a video (``.mp4``/``.avi``) atomically."""
    if not frames:
        raise RenderError(f'{output}: no frames to animate')
    h, w = frames[0].shape[:2]
    scale = min(1.0, max_width / w)
    size = (int(w * scale) // 2 * 2, int(h * scale) // 2 * 2)
    small = [cv2.resize(f, size, interpolation=cv2.INTER_AREA) for f in frames]
    tmp = _atomic_path(output)
    try:
        if output.lower().endswith('.gif'):
            anim = cv2.Animation()
            anim.frames = small
            anim.durations = [max(20, int(round(1000 / fps)))] * len(small)
            anim.loop_count = 0
            if not cv2.imwriteanimation(tmp, anim):
                raise RenderError(f'{output}: OpenCV could not write the GIF')
        else:
            fourcc = cv2.VideoWriter_fourcc(*('mp4v' if output.lower().endswith('.mp4')
                                              else 'MJPG'))
            writer = cv2.VideoWriter(tmp, fourcc, fps, size)
            if not writer.isOpened():
                raise RenderError(f'{output}: OpenCV cannot write this video format')
            for f in small:
                writer.write(f)
            writer.release()
        os.replace(tmp, output)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return output
