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
``VideoReader`` is the one place a video file is opened (``read_video``, ``video_fps``,
``FrameSource``, detect, the calibration fetch); ``FrameSource`` plays a folder or a video by
index for the image publisher (stepping, seeking, and a bounded buffer for playing backward).
"""

import collections
import os
from pathlib import Path
import re
from types import TracebackType
from typing import Iterator, List, Optional, Type

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


class VideoReader:
    """
    One video file opened: its frames in order or from an index, and what its container says.

    ``frame_count`` is the count the container declares (0: unknown, e.g. a stream; it can be
    more than the file holds), ``fps`` its declared rate (0.0: none).
    """

    def __init__(self, path: str) -> None:
        self.path = path
        self._cap = cv2.VideoCapture(path)
        if not self._cap.isOpened():
            self._cap.release()
            raise SourceError(f'{path}: cannot open the video')
        self.frame_count = max(0, int(self._cap.get(cv2.CAP_PROP_FRAME_COUNT) or 0))
        fps = self._cap.get(cv2.CAP_PROP_FPS)
        self.fps = float(fps) if fps and np.isfinite(fps) and fps > 0 else 0.0

    def read(self) -> Optional[np.ndarray]:
        """Return the next BGR frame, or None at the end."""
        ok, frame = self._cap.read()
        return frame if ok else None

    def grab(self) -> bool:
        """Step over the next frame (decoded, not converted); False at the end."""
        return bool(self._cap.grab())

    def retrieve(self) -> Optional[np.ndarray]:
        """Return the frame the last ``grab`` stepped over, or None if it cannot be decoded."""
        ok, frame = self._cap.retrieve()
        return frame if ok else None

    def seek(self, index: int) -> None:
        """Make frame ``index`` the next one (the decoder starts from the keyframe before)."""
        self._cap.set(cv2.CAP_PROP_POS_FRAMES, index)

    def release(self) -> None:
        """Close the file."""
        self._cap.release()

    def __enter__(self) -> 'VideoReader':
        return self

    def __exit__(self, kind: Optional[Type[BaseException]], exc: Optional[BaseException],
                 trace: Optional[TracebackType]) -> None:
        self.release()


def read_video(path: str) -> Iterator[np.ndarray]:
    """Yield the BGR frames of a video file in order (``SourceError`` if it cannot be opened)."""
    with VideoReader(path) as video:
        while (frame := video.read()) is not None:
            yield frame


def video_fps(path: str) -> float:
    """Return the frame rate a video file declares, or 0.0 when it declares none."""
    try:
        with VideoReader(path) as video:
            return video.fps
    except SourceError:
        return 0.0


#: a video is stepped forward frame by frame (decoding them) up to this many, else it seeks
VIDEO_SEEK_FRAMES = 64


class FrameSource:
    """
    Frames of a folder or a video, in order or by index, as BGR uint8 arrays.

    A video whose container gives its frame count is indexed like a folder (``frame_at``
    steps forward or seeks), so looping publishers of a recorded rig show frame ``k`` of every
    camera at the same instant; a stream without a count is read in order. With
    ``back_bytes`` (played backward, ``--bounce``), the frames of a video that ``frame_at``
    returned last are kept up to that many bytes, and a frame before them is read with the
    ones before it in one seek, so going backward seeks once per buffer, not once per frame.
    """

    def __init__(self, path: str, preload: bool = False, back_bytes: int = 0) -> None:
        self.path = path
        self._video: Optional[VideoReader] = None
        self._back_bytes = back_bytes
        self._back: 'collections.OrderedDict[int, np.ndarray]' = collections.OrderedDict()
        self._back_used = 0
        self._frame_nbytes = 0
        if os.path.isdir(path):
            self.files = sorted(os.path.join(path, f) for f in os.listdir(path)
                                if f.lower().endswith(IMAGE_EXTENSIONS))
            if not self.files:
                raise SourceError(f'no images ({", ".join(IMAGE_EXTENSIONS)}) in folder {path}')
        elif os.path.isfile(path):
            self.files = None
            try:
                self._video = VideoReader(path)
            except SourceError:
                raise SourceError(f'cannot open video {path} (not a video OpenCV can '
                                  'read?)') from None
        else:
            raise SourceError(f'source not found: {path!r} (give an image folder or a video)')
        # frames the video's container reports (0: unknown, e.g. a stream)
        self._video_frames = 0 if self._video is None else self._video.frame_count
        self._index = 0
        self._cache: Optional[List[np.ndarray]] = None
        if preload:
            self._cache = []
            frame = self._read()
            while frame is not None:
                self._cache.append(frame)
                frame = self._read()
            self._index = 0

    def _read(self) -> Optional[np.ndarray]:
        if self.files is not None:
            if self._index >= len(self.files):
                return None
            name = self.files[self._index]
            self._index += 1
            image = cv2.imread(name, cv2.IMREAD_COLOR)
            if image is None:
                raise SourceError(f'cannot decode image {name}')
            return image
        frame = self._video.read()
        if frame is None:
            return None
        self._index += 1
        self._frame_nbytes = frame.nbytes
        return frame

    def read_next(self) -> Optional[np.ndarray]:
        """Return the next frame, or None at the end."""
        if self._cache is not None:
            if self._index >= len(self._cache):
                return None
            self._index += 1
            return self._cache[self._index - 1]
        return self._read()

    @property
    def seekable(self) -> bool:
        """Tell whether frames have an index (a folder, a preloaded video, a counted video)."""
        return self.files is not None or self._cache is not None or self._video_frames > 0

    @property
    def position(self) -> int:
        """Return the index of the next frame (seekable sources)."""
        return self._index

    @property
    def length(self) -> int:
        """Return the number of frames of a seekable source."""
        if self._cache is not None:
            return len(self._cache)
        return len(self.files) if self.files is not None else self._video_frames

    @property
    def back_frames(self) -> List[int]:
        """Return the indices of the video frames kept for playing backward, oldest first."""
        return list(self._back)

    @property
    def back_bytes_used(self) -> int:
        """Return the bytes the frames kept for playing backward hold (at most ``back_bytes``)."""
        return self._back_used

    def frame_at(self, index: int) -> np.ndarray:
        """
        Return frame ``index`` of a seekable source; the next frame is the one after it.

        A frame from the backward buffer (``back_bytes``) leaves the position as it was.
        """
        if self._streaming:
            if index in self._back:              # decoded lately: no seek back
                self._back.move_to_end(index)
                return self._back[index]
            ahead = index - self._index
            if ahead < 0 and self._back_bytes:
                return self._read_back(index)
            if 0 <= ahead <= VIDEO_SEEK_FRAMES:
                for _ in range(ahead):           # decodes, but cheaper than a seek back
                    self._video.grab()
            else:
                self._video.seek(index)
        self._index = index
        frame = self.read_next()
        if frame is None and self._streaming and 0 < index < self._video_frames:
            self._video_frames = index           # the container counted more than it holds
            return self.frame_at(0)
        if frame is None:
            raise SourceError(f'{self.path}: no frame {index}')
        self._keep(index, frame)
        return frame

    def _read_back(self, index: int) -> np.ndarray:
        """Read frame ``index`` of a video behind the decoder, with the frames before it."""
        fit = max(1, self._back_bytes // max(1, self._frame_nbytes))
        first = max(0, index - fit + 1)
        self._video.seek(first)                  # decodes from the keyframe before
        self._index = first
        for k in range(first, index + 1):
            frame = self._read()
            if frame is None:
                if 0 < k < self._video_frames:
                    self._video_frames = k       # the container counted more than it holds
                    return self.frame_at(0)
                raise SourceError(f'{self.path}: no frame {k}')
            self._keep(k, frame)
        return self._back[index]

    def _keep(self, index: int, frame: np.ndarray) -> None:
        """Keep a decoded video frame for playing backward, dropping the oldest beyond the cap."""
        if not (self._streaming and self._back_bytes):
            return
        self.forget(index)
        self._back[index] = frame
        self._back_used += frame.nbytes
        while self._back_used > self._back_bytes and len(self._back) > 1:
            self._back_used -= self._back.popitem(last=False)[1].nbytes

    def forget(self, index: int) -> None:
        """Drop frame ``index`` from the backward buffer (cached elsewhere)."""
        frame = self._back.pop(index, None)
        if frame is not None:
            self._back_used -= frame.nbytes

    @property
    def _streaming(self) -> bool:
        """Tell whether frames come from the video file (not preloaded)."""
        return self._video is not None and self._cache is None

    def skip(self) -> bool:
        """Step over the next frame (without converting it); False at the end."""
        if self._streaming:
            if self._video_frames and self._index >= self._video_frames or \
                    not self._video.grab():
                return False
        elif self._index >= self.length:
            return False
        self._index += 1
        return True

    def rewind(self) -> None:
        """Go back to the first frame."""
        self._index = 0
        if self._streaming:
            self._video.seek(0)
