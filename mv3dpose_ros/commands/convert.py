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
``mv3dpose convert``: files to bags and back, so recorded data can be replayed live.

images    per-camera image folders (or one video per camera) + a calibration file ->
          ``/<cam>/image_raw`` (sensor_msgs/Image, bgr8) and ``/<cam>/camera_info``; the i-th
          time point of every camera gets the same stamp ``start + i / fps``, so the fusion
          node's synchroniser sees complete sets.
openpose  per-camera OpenPose JSON folders -> ``/<cam>/persons_2d`` (Person2DArray), stamp
          ``start + frame / fps``, one message per frame and camera (empty when nobody or no
          file) as a live pose2d_node would publish.
tracks    a tracks bag (TrackedSkeletonArray) -> tracks JSON Lines of ``mv3dpose track``, or
          JSON Lines -> bag; the direction follows the input.

Camera names come from the calibration; folder names are matched to them (exactly, else
loosely: Pose2Sim's ``cam01_json`` is ``cam_01``). A folder without a calibrated camera, or a
requested camera without a folder, is an error naming both sides. ``<cam>`` in topic names is
the camera name, or ``cam<name>`` when the name is no valid ROS name token (``00_03``).

The conversions are ``ros.bag_convert``'s (camera inputs: ``io.cameras``); this module is
their command line. Outputs appear only complete (bags via ``BagWriter``, JSON Lines via a temp
file renamed on success). Exit status: 0 done, 1 error naming the file, 3 done but malformed
input files or lines were skipped (each named on stderr).
"""

import argparse
import os
import sys

from mv3dpose_ros.io.bag import bag_path_type, BagError, DEFAULT_STORAGE, STORAGES
from mv3dpose_ros.ros.bag_convert import bag_to_jsonl, ConvertError, DEFAULT_START_TIME
from mv3dpose_ros.ros.bag_convert import images_to_bag, jsonl_to_bag, openpose_to_bag
from mv3dpose_ros.ros.bag_convert import TRACKS_TOPIC


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the ``images``, ``openpose`` and ``tracks`` conversions."""
    sub = parser.add_subparsers(dest='convert_command', metavar='{images,openpose,tracks}')
    sub.required = True
    img = sub.add_parser('images', help='image folders / videos + calibration -> image bag')
    img.add_argument('root', help='folder with one image folder (or video file) per camera')
    img.add_argument('-c', '--calibration', required=True,
                     help='calibration file (rig YAML, Panoptic JSON, VoxelPose JSON, '
                          'Pose2Sim TOML)')
    img.add_argument('-o', '--output', required=True, help='output bag (must not exist)')
    img.add_argument('--fps', type=float, default=0.0,
                     help='time points per second (default: the rate of the videos, else 10)')
    img.add_argument('--cameras', nargs='+', help='use only these calibrated cameras')

    op = sub.add_parser('openpose', help='OpenPose JSON folders -> Person2DArray bag')
    op.add_argument('root', help='folder with one OpenPose JSON folder per camera')
    op.add_argument('-c', '--calibration', required=True,
                    help='calibration file (camera names and image sizes)')
    op.add_argument('-o', '--output', required=True, help='output bag (must not exist)')
    op.add_argument('--layout', default='body25',
                    help='keypoint layout of the JSON files (body25, body25b, coco17, ...)')
    op.add_argument('--fps', type=float, default=30.0, help='frames per second')
    op.add_argument('--cameras', nargs='+', help='use only these calibrated cameras')

    tr = sub.add_parser('tracks', help='tracks bag <-> tracks JSON Lines (by the input)')
    tr.add_argument('input', help='a bag (directory, .mcap, .db3) or a .jsonl file')
    tr.add_argument('-o', '--output', required=True)
    tr.add_argument('--topic', help=f'track topic (bag input: auto; JSONL input: '
                                    f'{TRACKS_TOPIC})')
    tr.add_argument('--frame-id', default='world', help='world frame id (JSONL input)')
    tr.add_argument('--fps', type=float, default=0.0,
                    help='JSONL input: stamps of lines without one; bag input: turn stamps '
                         'into frame numbers')
    for p in (img, op, tr):
        p.add_argument('--start-time', type=float, default=None,
                       help=f'stamp of frame 0 [s] (default {DEFAULT_START_TIME:.0f}; '
                            'bag -> JSONL: the first stamp)')
    for p in (img, op, tr):
        p.add_argument('--storage', choices=STORAGES, default=DEFAULT_STORAGE)
        p.add_argument('-q', '--quiet', action='store_true')


def run(args: argparse.Namespace) -> int:
    """Run ``mv3dpose convert <images|openpose|tracks>``."""
    start = DEFAULT_START_TIME if args.start_time is None else args.start_time
    try:
        if args.convert_command == 'images':
            s = images_to_bag(args.root, args.calibration, args.output, fps=args.fps,
                              start_time=start, cameras=args.cameras, storage=args.storage,
                              quiet=args.quiet)
            print(f'wrote {s["output"]}: {len(s["cameras"])} cameras '
                  f'({", ".join(s["cameras"])}), {s["time_points"]} time points at '
                  f'{s["fps"]:g} fps, {s["messages"]} messages')
        elif args.convert_command == 'openpose':
            s = openpose_to_bag(args.root, args.calibration, args.output, args.layout,
                                fps=args.fps, start_time=start, cameras=args.cameras,
                                storage=args.storage, quiet=args.quiet)
            print(f'wrote {s["output"]}: {len(s["cameras"])} cameras, {s["frames"]} frames '
                  f'({s["first_frame"]}..{s["last_frame"]}), {s["messages"]} messages')
            for issue in s['issues']:
                print(f'skipped {issue}', file=sys.stderr)
            if s['issues']:
                return 3          # written, but malformed input files were left out
        else:
            if bag_path_type(args.input) == 'bag' or not os.path.exists(args.input):
                if not os.path.exists(args.input):
                    raise ConvertError(f'{args.input}: input does not exist')
                s = bag_to_jsonl(args.input, args.output, topic=args.topic, fps=args.fps,
                                 start_time=args.start_time)
            else:
                s = jsonl_to_bag(args.input, args.output, topic=args.topic or TRACKS_TOPIC,
                                 frame_id=args.frame_id, fps=args.fps or 30.0,
                                 start_time=start, storage=args.storage)
                for issue in s['issues']:
                    print(f'skipped {issue}', file=sys.stderr)
            print(f'wrote {s["output"]}: {s["frames"]} frames, {s["tracks"]} track ids')
            if s.get('issues'):
                return 3          # written, but malformed lines were left out
    except (ConvertError, BagError, OSError, ValueError) as exc:
        print(f'error: {exc}', file=sys.stderr)
        return 1
    return 0
