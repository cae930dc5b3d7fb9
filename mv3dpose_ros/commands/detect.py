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
``mv3dpose detect``: 2D poses of recorded camera images or videos, as OpenPose JSON (offline).

    mv3dpose detect --images DIR [-c CALIB] -o POSES_ROOT [--model yolo11n-pose]
    mv3dpose track -c CALIB --poses POSES_ROOT --layout coco17 --fps F -o tracks.jsonl

``DIR`` holds one image folder or one video file per camera (the layout ``mv3dpose convert
images`` and the demo read). With ``-c`` the folders and videos are matched to the calibrated
cameras the way ``mv3dpose track`` matches pose folders (``cam01/`` or ``cam01.mp4`` is
``cam_01``; a camera fitting several is an error naming them) and the output folders take the
calibrated names; without it every folder / video is a camera, named as it is.

With ``-c`` the image size is also compared with the calibration by the rule the live
``fusion_node`` applies (``core.geometry.camera.fit_image_size``): a codec's crop or padding of at
most ``--image-size-tolerance-px`` per dimension (1080 vs 1088) keeps the keypoints, a resize with
the same aspect ratio scales them into the calibration's pixels; either is printed as a note
per camera naming the assumption. Any other size is written in image pixels with a warning
(tracking will be wrong until the calibration or the images are fixed).

Each camera gets ``POSES_ROOT/<camera>/<camera>_<frame:012d>_keypoints.json`` (COCO-17
keypoints in image pixels, or the calibration's pixels as above; one file per image, also when
nobody is seen), the frame number being the last number of the image file name (or the
image's index when a folder has unnumbered files; the frame index for videos), so files of
different cameras with the same number form one time point for ``mv3dpose track``. The model
is the one ``pose2d_node`` runs (``pose2d/estimator.py``), so offline and live detections
agree. Unreadable images are reported and skipped (no file is written for them).
"""

import argparse
import os
import sys
from typing import Dict, Iterator, List, Optional, Tuple

import cv2
from mv3dpose_ros.core.geometry.camera import fit_image_size, IMAGE_SIZE_TOLERANCE_PX, ImageFit
from mv3dpose_ros.io.cameras import camera_sources, load_cameras
from mv3dpose_ros.io.media import frame_key, list_images, read_video, SourceError
from mv3dpose_ros.io.media import VIDEO_EXTENSIONS, VideoReader
from mv3dpose_ros.io.openpose import openpose_filename, write_openpose_file
from mv3dpose_ros.pose2d.estimator import ModelError, open_estimator
from mv3dpose_ros.pose2d.models import ModelNotFound, parse_size, resolve_model_path
import numpy as np
from tqdm import tqdm

LAYOUT = 'coco17'


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the options of ``mv3dpose detect``."""
    parser.add_argument('--images', required=True, metavar='DIR',
                        help='folder with one image folder or video file per camera')
    parser.add_argument('--calibration', '-c', metavar='FILE',
                        help='calibration: match folders to its cameras, check image sizes')
    parser.add_argument('--output', '-o', required=True, metavar='POSES_ROOT',
                        help='output: one OpenPose JSON folder per camera')
    parser.add_argument('--cameras', nargs='+', metavar='NAME',
                        help='only these cameras (default: all found)')
    parser.add_argument('--model', default='yolo11n-pose',
                        help='registered model (see `mv3dpose model list`)')
    parser.add_argument('--size', help='model input size N or HxW (registered model)')
    parser.add_argument('--model-path', help='explicit pose ONNX (overrides --model)')
    parser.add_argument('--threads', type=int, default=0,
                        help='onnxruntime intra-op threads (default 0 = one per core)')
    parser.add_argument('--score-threshold', type=float, default=None,
                        help='minimum person score (default: the model family default)')
    parser.add_argument('--image-size-tolerance-px', type=int, default=IMAGE_SIZE_TOLERANCE_PX,
                        metavar='PX',
                        help='with -c: images whose size differs from the calibration are '
                        'used when it is a resize (same aspect ratio: keypoints scaled into the '
                        'calibration pixels) or a crop or padding of at most this many pixels '
                        'per dimension (keypoints unchanged: assumed at the right/bottom, as '
                        'codecs do); other sizes are warned about. Negative: only the '
                        'calibrated size is accepted (default %(default)s, as the '
                        'input_image_size_tolerance_px parameter of fusion_node)')
    parser.add_argument('--no-progress', action='store_true', help='no progress bar')


def _sources(root: str, calibration: Optional[str], cameras: Optional[List[str]]
             ) -> Tuple[Dict[str, str], dict, List[str]]:
    """Return ``(camera -> folder or video, calibrated cameras, notes)``."""
    notes: List[str] = []
    if calibration:
        cams = load_cameras(calibration, cameras)
        found, ignored = camera_sources(root, list(cams), calibration, strict=False)
        if cameras and ignored:
            raise SourceError(f'{root}: no folder or video for camera(s) {", ".join(ignored)}')
        if ignored:
            shown = ', '.join(ignored[:5]) + (', ...' if len(ignored) > 5 else '')
            notes.append(f'{len(ignored)} calibrated camera(s) have no images: {shown}')
        return found, cams, notes
    if not os.path.isdir(root):
        raise SourceError(f'{root}: input folder does not exist')
    found = {}
    for entry in sorted(os.listdir(root)):
        path = os.path.join(root, entry)
        if os.path.isdir(path) and not entry.startswith('.'):
            found[entry] = path
        elif entry.lower().endswith(VIDEO_EXTENSIONS):
            found[os.path.splitext(entry)[0]] = path
    if cameras:
        missing = [c for c in cameras if c not in found]
        if missing:
            raise SourceError(f'{root}: no folder or video named {", ".join(missing)} '
                              f'(found: {", ".join(found) or "nothing"})')
        found = {c: found[c] for c in cameras}
    if not found:
        raise SourceError(f'{root}: no per-camera image folders or video files inside')
    return found, {}, notes


def _frames(path: str) -> Tuple[int, float, Iterator[Tuple[int, str, Optional[np.ndarray]]]]:
    """
    Return ``(count, fps, iterator of (frame number, name, BGR image or None))`` of a source.

    ``fps`` is the video's rate (0 for image folders or when the video does not say).
    """
    if os.path.isdir(path):
        files = list_images(path)
        numbered = all(frame_key(f) is not None for f in files)

        def images() -> Iterator[Tuple[int, str, Optional[np.ndarray]]]:
            for i, name in enumerate(files):
                yield frame_key(name) if numbered else i, name, cv2.imread(name,
                                                                           cv2.IMREAD_COLOR)
        return len(files), 0.0, images()
    try:
        with VideoReader(path) as video:
            count, fps = video.frame_count, video.fps
    except SourceError:                 # named when its frames are read
        count, fps = 0, 0.0

    def frames() -> Iterator[Tuple[int, str, Optional[np.ndarray]]]:
        for i, frame in enumerate(read_video(path)):
            yield i, f'{path} frame {i}', frame
    return count, fps, frames()


def _estimator(args):
    path = args.model_path or resolve_model_path(args.model, args.size)
    return open_estimator(path, threads=args.threads,
                          input_size=parse_size(args.size) if args.size and args.model_path
                          else None, score_threshold=args.score_threshold)


def _image_fit(cam: str, calib, image: np.ndarray, tolerance_px: int
               ) -> Tuple[Optional[ImageFit], Optional[str]]:
    """
    Return ``(fit or None, message or None)`` for an image of a calibrated camera.

    The fit maps keypoints into the calibration's pixels (None: same size, or a mismatch left
    in image pixels); the message is the note or warning to print for that image size.
    """
    height, width = image.shape[:2]
    fit = fit_image_size(calib.width, calib.height, width, height, tolerance_px)
    if fit.kind == 'same':
        return None, None
    if fit.accepted:
        return fit, (f'note: camera {cam}: {fit.kind}: {fit.note}; keypoints written in the '
                     f"calibration's {calib.width}x{calib.height} pixels "
                     f'(--image-size-tolerance-px {tolerance_px})')
    return None, (f'warning: camera {cam}: images are {width}x{height} but the calibration '
                  f'says {calib.width}x{calib.height} ({fit.note}); keypoints are in image '
                  'pixels, so tracking will be wrong unless the calibration is fixed (or, for '
                  'a crop or padding by the codec, --image-size-tolerance-px raised)')


def run(args) -> int:
    """Detect 2D poses in every image of every camera and write OpenPose JSON."""
    try:
        sources, cams, notes = _sources(args.images, args.calibration, args.cameras)
        estimator = _estimator(args)
    except (SourceError, ModelError, ModelNotFound, ValueError, OSError) as exc:
        print(f'mv3dpose detect: error: {exc}', file=sys.stderr)
        return 2
    for note in notes:
        print(f'mv3dpose detect: note: {note}', file=sys.stderr)
    plans = {cam: _frames(path) for cam, path in sources.items()}
    total = sum(count for count, _, _ in plans.values())
    print(f'{len(sources)} cameras ({", ".join(sources)}), {total} images; model '
          f'{estimator.path} ({estimator.family}, input {estimator.input_size[0]}x'
          f'{estimator.input_size[1]}, weights licence: {estimator.licence})', file=sys.stderr)
    bar = tqdm(total=total or None, unit='image', desc='detecting', file=sys.stderr,
               disable=True if args.no_progress else None, leave=False)
    written, failed, people = 0, [], []
    fps_seen = set()
    try:
        for cam, (_, fps, frames) in plans.items():
            if fps:
                fps_seen.add(round(fps, 3))
            folder = os.path.join(args.output, cam)
            os.makedirs(folder, exist_ok=True)
            fits: Dict[Tuple[int, int], Optional[ImageFit]] = {}    # per (height, width)
            for frame, name, image in frames:
                bar.update(1)
                if image is None:
                    failed.append(name)
                    bar.write(f'mv3dpose detect: skipped {name}: cannot decode the image',
                              file=sys.stderr)
                    continue
                size = image.shape[:2]
                if cam in cams and size not in fits:
                    fits[size], message = _image_fit(cam, cams[cam], image,
                                                     args.image_size_tolerance_px)
                    if message:
                        bar.write(f'mv3dpose detect: {message}', file=sys.stderr)
                fit = fits.get(size)
                det = estimator.infer(image, 'bgr')
                keypoints = fit.apply(det.keypoints) if fit is not None else det.keypoints
                write_openpose_file(os.path.join(folder, openpose_filename(cam, frame)),
                                    keypoints)
                written += 1
                people.append(len(det))
    except KeyboardInterrupt:
        bar.close()
        print(f'interrupted after {written} images', file=sys.stderr)
        return 130
    finally:
        bar.close()
    fps = f'{next(iter(fps_seen)):g}' if len(fps_seen) == 1 else 'F'
    calib = args.calibration or 'CALIB'
    print(f'wrote {written} OpenPose JSON files ({LAYOUT}) to {args.output}'
          + (f'; people per image median {int(np.median(people))}, max {max(people)}'
             if people else '')
          + (f'; {len(failed)} unreadable image(s) skipped' if failed else ''))
    print(f'next: mv3dpose track --calibration {calib} --poses {args.output} --layout {LAYOUT} '
          f'--fps {fps} -o tracks.jsonl')
    return 1 if failed and not written else 0
