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
The ``mv3dpose`` command: offline tracking, evaluation, models, bags, rendering, the demo.

Each subcommand lives in ``mv3dpose_ros.commands.<name>`` and exposes
``add_arguments(parser)`` and ``run(args) -> int``; modules are imported only when their
subcommand runs, so ``mv3dpose --help`` stays fast and one broken extra cannot break the rest.
"""

import argparse
import importlib
import sys
from typing import List, Optional

# name -> one-line help; the module mv3dpose_ros.commands.<name> implements it.
COMMANDS = {
    'detect': '2D poses of per-camera image folders or videos as OpenPose JSON (offline)',
    'track': 'track people in 3D from per-camera OpenPose JSON folders (offline)',
    'calibrate': "estimate a rig's extrinsics from the 2D keypoints of the people in it",
    'eval': 'score a tracks file against ground truth (PCP, MPJPE, MOTA)',
    'model': 'fetch and inspect 2D pose models (ONNX)',
    'bag': 'record, play and inspect rosbag2 files',
    'convert': 'convert image folders, OpenPose JSON and tracks to and from bags',
    'render': 'draw tracks as PNG / GIF pictures',
    'demo': 'run the live pipeline on an embedded synthetic rig or on image folders',
}


def _load(name: str):
    return importlib.import_module(f'mv3dpose_ros.commands.{name}')


def build_parser(argv: List[str]) -> argparse.ArgumentParser:
    """Build the parser; only the subcommand named in ``argv`` is imported."""
    parser = argparse.ArgumentParser(prog='mv3dpose', description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest='command', metavar='COMMAND')
    chosen = next((a for a in argv if not a.startswith('-')), None)
    for name, text in COMMANDS.items():
        p = sub.add_parser(name, help=text, description=text)
        if name == chosen:
            _load(name).add_arguments(p)
    return parser


def main(argv: Optional[List[str]] = None) -> int:
    """Entry point of the ``mv3dpose`` console script."""
    argv = sys.argv[1:] if argv is None else argv
    parser = build_parser(argv)
    args = parser.parse_args(argv)
    if not args.command:
        parser.print_help()
        return 2
    try:
        return int(_load(args.command).run(args) or 0)
    except KeyboardInterrupt:
        print('interrupted', file=sys.stderr)
        return 130


if __name__ == '__main__':
    sys.exit(main())
