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
Image and video files: the extensions every reader of frames accepts, and the readers.

One list of extensions, so every reader agrees on what a frame file is; file names carry the
frame number (the last number in the name), by which folders are sorted and cameras aligned.
"""

import os
from pathlib import Path
import re
from typing import Iterator, List, Optional

import cv2
import numpy as np

#: Still images ``cv2.imread`` reads (OpenCV's bundled codecs).
IMAGE_EXTENSIONS = ('.jpg', '.jpeg', '.png', '.bmp', '.tif', '.tiff', '.webp', '.ppm', '.pgm')
#: Video containers ``cv2.VideoCapture`` opens with the FFmpeg backend of opencv-python.
VIDEO_EXTENSIONS = ('.mp4', '.avi', '.mov', '.mkv', '.webm', '.mpg', '.mpeg')
_DIGITS = re.compile(r'(\d+)')


class SourceError(ValueError):
    """An image folder, video or calibration that cannot be read; the text names it and why."""


def frame_key(name: str) -> Optional[int]:
    """Return the last number in a file name (the frame number), or None."""
    nums = _DIGITS.findall(Path(name).stem)
    return int(nums[-1]) if nums else None


def list_images(folder: str) -> List[str]:
    """Return the image files of ``folder`` sorted by frame number (then name)."""
    if not os.path.isdir(folder):
        raise SourceError(f'{folder}: image folder does not exist')
    files = [f for f in os.listdir(folder) if f.lower().endswith(IMAGE_EXTENSIONS)]
    files.sort(key=lambda f: (frame_key(f) is None, frame_key(f) or 0, f))
    return [os.path.join(folder, f) for f in files]


def read_video(path: str) -> Iterator[np.ndarray]:
    """Yield the BGR frames of a video file in order (``SourceError`` if it cannot be opened)."""
    cap = cv2.VideoCapture(path)
    if not cap.isOpened():
        raise SourceError(f'{path}: cannot open the video')
    try:
        while True:
            ok, frame = cap.read()
            if not ok:
                break
            yield frame
    finally:
        cap.release()


def video_fps(path: str) -> float:
    """Return the frame rate a video file declares, or 0.0 when it declares none."""
    cap = cv2.VideoCapture(path)
    fps = cap.get(cv2.CAP_PROP_FPS) if cap.isOpened() else 0.0
    cap.release()
    return float(fps) if fps and np.isfinite(fps) and fps > 0 else 0.0
