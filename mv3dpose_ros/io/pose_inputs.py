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
The inputs of the commands that read per-camera OpenPose JSON folders with a calibration.

``mv3dpose track`` and ``mv3dpose calibrate`` take the same ``--calibration``,
``--calibration-format``, ``--image-size``, ``--cameras``, ``--poses`` and ``--layout``; this
is their one reading of them.
"""

import argparse
from typing import List, Optional, Tuple


def image_size(text: str) -> Tuple[int, int]:
    """Parse ``WxH`` (e.g. ``1032x776``) into ``(w, h)``: an argparse type."""
    try:
        w, h = (int(v) for v in text.lower().split('x'))
    except ValueError:
        raise argparse.ArgumentTypeError(f'expected WIDTHxHEIGHT in pixels, e.g. 1920x1080, '
                                         f'got {text!r}') from None
    if w <= 0 or h <= 0:
        raise argparse.ArgumentTypeError(f'image size must be positive, got {text!r}')
    return w, h


def add_image_size_argument(parser: argparse.ArgumentParser) -> None:
    """Add ``--image-size WxH``: the size of calibrations that do not give one (VoxelPose)."""
    parser.add_argument('--image-size', type=image_size, metavar='WxH',
                        help="every camera's image size in pixels, for calibration files "
                             'that do not give it (VoxelPose JSON other than Shelf and '
                             'Campus, whose sizes are known by file name)')


def load_rig(args, cameras: Optional[List[str]] = None) -> dict:
    """Load ``args.calibration`` as these commands do (format, image size, camera subset)."""
    from mv3dpose_ros.core.geometry.calibration import load_calibration

    return load_calibration(args.calibration, args.calibration_format, cameras=cameras,
                            image_size=getattr(args, 'image_size', None))


def open_inputs(args) -> Tuple[dict, object, List[str]]:
    """Load the calibration and index the pose folders; return (cameras, sequence, notes)."""
    from mv3dpose_ros.core.skeleton import get_layout
    from mv3dpose_ros.io.openpose import match_camera_folders, OpenPoseSequence

    layout = get_layout(args.layout)
    cameras = load_rig(args, args.cameras)
    folders, missing = match_camera_folders(args.poses, list(cameras))
    notes = list(missing)
    if args.cameras and missing:
        raise ValueError('; '.join(missing))
    cameras = {name: cam for name, cam in cameras.items() if name in folders}
    if len(cameras) < 2:
        raise ValueError(f'need pose folders of at least two calibrated cameras under '
                         f'{args.poses}; found {sorted(folders) or "none"}'
                         + (f' ({"; ".join(missing)})' if missing else ''))
    seq = OpenPoseSequence({name: folders[name] for name in cameras}, layout.num_joints)
    if not len(seq):
        raise ValueError(f'no OpenPose JSON files under {args.poses} '
                         f'(folders: {", ".join(folders.values())})')
    check_layout(seq, layout)
    return cameras, seq, notes


def check_layout(seq, layout) -> None:
    """Fail early when the files hold another number of joints than the layout has."""
    from mv3dpose_ros.core.skeleton import get_layout, LAYOUT_NAMES
    from mv3dpose_ros.io.openpose import OpenPoseFormatError, read_openpose_file

    for files in seq.files.values():
        for path in list(files.values())[:20]:
            try:
                poses = read_openpose_file(path)
            except OpenPoseFormatError:
                continue
            if len(poses) == 0:
                continue
            count = poses.shape[1]
            if count != layout.num_joints:
                fits = [n for n in LAYOUT_NAMES if get_layout(n).num_joints == count]
                raise ValueError(f'{path} has {count} joints per person but layout '
                                 f'{layout.name!r} has {layout.num_joints}; layouts with '
                                 f'{count} joints: {", ".join(fits) or "none"}')
            return
