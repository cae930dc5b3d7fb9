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
Multi-person 2D pose estimation with onnxruntime behind one interface, per model family.

``open_estimator(path)`` inspects the ONNX (metadata and tensor shapes), picks the family
adapter and refuses anything else with a message that says what was found and what is
supported. ``PoseEstimator.infer(image)`` returns ``Detections`` in original-image pixels:

- ``yolo-pose`` (Ultralytics YOLOv8/11 pose, COCO-17): input ``[1, 3, H, W]`` float RGB / 255,
  output ``[1, 56, N]`` = box cx, cy, w, h, person score, 17 x (x, y, conf) in input pixels;
  score threshold, class-agnostic NMS and letterbox inversion here.
- ``movenet-multipose`` (MoveNet MultiPose Lightning): input ``[1, H, W, 3]`` uint8/int32 RGB,
  output ``[1, 6, 56]`` = 17 x (y, x, score) normalised, box, instance score; no NMS.
"""

import contextlib
from dataclasses import dataclass, field
import io
import os
import time
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

import cv2
from mv3dpose_ros.pose2d.models import ModelIntegrityError, read_sidecar, verify_model
from mv3dpose_ros.pose2d.ops import Letterbox, nms, xywh_to_xyxy
import numpy as np

NUM_JOINTS = 17
LAYOUT = 'coco17'
FAMILIES = ('yolo-pose', 'movenet-multipose')
_SUPPORTED = ('supported: yolo-pose (Ultralytics pose export, input [1,3,H,W] float, output '
              '[1,56,N], exported with nms=False) and movenet-multipose (input [1,H,W,3] '
              'uint8/int32, output [1,6,56])')


class ModelError(ValueError):
    """The ONNX file is missing, unreadable, corrupt or not a supported 2D pose model."""


#: onnxruntime execution providers that ``auto`` tries, fastest first; short names for params.
PROVIDERS = {'tensorrt': 'TensorrtExecutionProvider', 'cuda': 'CUDAExecutionProvider',
             'openvino': 'OpenVINOExecutionProvider', 'cpu': 'CPUExecutionProvider'}
CPU = PROVIDERS['cpu']


def available_providers() -> List[str]:
    """Return the execution providers this onnxruntime build offers."""
    import onnxruntime as ort
    return list(ort.get_available_providers())


#: The TensorRT libraries onnxruntime-gpu's TensorRT provider links (TensorRT 10).
TENSORRT_LIBRARIES = ('libnvinfer.so.10', 'libnvonnxparser.so.10')


def tensorrt_found() -> bool:
    """Tell whether TensorRT's libraries load, i.e. the TensorRT provider can start."""
    import ctypes
    try:
        for name in TENSORRT_LIBRARIES:
            ctypes.CDLL(name)
    except OSError:
        return False
    return True


def resolve_providers(request: Union[str, Sequence[str]] = 'auto',
                      available: Optional[Sequence[str]] = None,
                      tensorrt: Optional[bool] = None) -> Tuple[List[str], List[str]]:
    """
    Turn a provider request into the list onnxruntime gets, CPU always last.

    ``request`` is 'auto' (TensorRT, CUDA, OpenVINO, CPU: those available, in that order), or
    a comma-separated text / sequence of short names (tensorrt, cuda, openvino, cpu) or full
    onnxruntime names. Returns ``(providers, warnings)``: a requested provider this build
    does not offer is left out with a warning. Raises ``ValueError`` for an unknown name.
    onnxruntime-gpu always offers TensorRT, so 'auto' keeps it only where TensorRT itself is
    installed (``tensorrt``: None probes ``TENSORRT_LIBRARIES``); else onnxruntime would
    fail it, print an error block per model and retry on CUDA.
    """
    available = list(available_providers() if available is None else available)
    items = ([p.strip() for p in request.split(',')] if isinstance(request, str)
             else [str(p).strip() for p in request])
    items = [p for p in items if p]
    if not items or items == ['auto']:
        chosen = [p for p in PROVIDERS.values() if p in available and p != CPU]
        if PROVIDERS['tensorrt'] in chosen and not (tensorrt_found() if tensorrt is None
                                                    else tensorrt):
            chosen.remove(PROVIDERS['tensorrt'])
        return chosen + [CPU], []
    full = {v.lower(): v for v in PROVIDERS.values()}
    chosen, warnings = [], []
    for item in items:
        name = PROVIDERS.get(item.lower()) or full.get(item.lower())
        if name is None:
            raise ValueError(f'unknown execution provider {item!r}: use auto or a comma-separated '
                             f'list of {", ".join(PROVIDERS)} (or onnxruntime names)')
        if name not in available:
            warnings.append(f'execution provider {name} was requested but this onnxruntime '
                            f'offers only {", ".join(available)}; falling back (for GPUs '
                            'install onnxruntime-gpu: ONNXRUNTIME=gpu make setup)')
        elif name not in chosen:
            chosen.append(name)
    if CPU in chosen:
        chosen.remove(CPU)
    return chosen + [CPU], warnings


_cuda_preloaded: Optional[List[str]] = None


def preload_cuda() -> List[str]:
    """
    Load CUDA and cuDNN for onnxruntime-gpu once, from the nvidia-* wheels beside it if present.

    ``ONNXRUNTIME=gpu make setup`` installs CUDA and cuDNN as wheels (``onnxruntime-gpu[cuda,
    cudnn]``); onnxruntime's CUDA provider finds them only through ``preload_dlls``, else it
    looks on the loader's path alone (a system CUDA, which still works) and the model would
    fall back to the CPU. Returns onnxruntime's lines about libraries it could not load.
    """
    global _cuda_preloaded
    if _cuda_preloaded is None:
        import onnxruntime as ort
        printed = io.StringIO()
        preload = getattr(ort, 'preload_dlls', None)
        if preload is not None:
            try:
                with contextlib.redirect_stdout(printed):
                    preload(cuda=True, cudnn=True, msvc=False)
            except Exception as exc:  # noqa: B902 - the provider's own error comes next
                printed.write(f'onnxruntime.preload_dlls failed: {exc}\n')
        _cuda_preloaded = [line.strip() for line in printed.getvalue().splitlines()
                           if line.strip().startswith(('Failed', 'onnxruntime.preload'))]
    return list(_cuda_preloaded)


def options_in_use(session: Any, provider: str, model_path: str) -> Dict[str, str]:
    """
    Return the session's values of the provider options this package sets, and the device.

    onnxruntime reports all of a GPU provider's options (25 for CUDA); these are the ones a
    user of this package changes or needs to tell the machines' GPUs apart.
    """
    every = session.get_provider_options().get(provider, {})
    keys = set(_provider_options(provider, model_path)) | {'device_id'}
    return {k: str(v) for k, v in every.items() if k in keys}


def _provider_options(name: str, model_path: str) -> Dict[str, str]:
    """Return the options given to one provider (engine cache beside the model for TensorRT)."""
    if name == PROVIDERS['tensorrt']:
        cache = os.path.join(os.path.dirname(os.path.abspath(model_path)), 'trt-cache')
        return {'trt_engine_cache_enable': 'True', 'trt_engine_cache_path': cache,
                'trt_fp16_enable': 'True'}
    if name == PROVIDERS['cuda']:
        return {'cudnn_conv_algo_search': 'HEURISTIC'}
    return {}


@dataclass
class Detections:
    """People found in one image, in original-image pixels (x right, y down)."""

    keypoints: np.ndarray     # [P, 17, 3] float32: x, y, confidence in [0, 1]
    boxes: np.ndarray         # [P, 4] float32: x0, y0, x1, y1
    scores: np.ndarray        # [P] float32 person score in [0, 1]

    @classmethod
    def empty(cls) -> 'Detections':
        """Return a result with nobody in it."""
        return cls(np.zeros((0, NUM_JOINTS, 3), np.float32), np.zeros((0, 4), np.float32),
                   np.zeros((0,), np.float32))

    def __len__(self) -> int:
        return int(self.scores.shape[0])


@dataclass
class Timing:
    """Milliseconds spent in each stage of the last ``infer`` call."""

    pre_ms: float = 0.0
    infer_ms: float = 0.0
    post_ms: float = 0.0

    @property
    def total_ms(self) -> float:
        """Return the sum of the stages."""
        return self.pre_ms + self.infer_ms + self.post_ms


@dataclass
class PoseEstimator:
    """
    One onnxruntime session plus the pre/post-processing of its model family.

    ``image`` arguments are uint8 ``[H, W, 3]`` in ``order`` 'bgr' or 'rgb', or ``[H, W]`` grey.
    """

    session: object
    path: str
    input_size: Tuple[int, int]           # (height, width) of the network input
    score_threshold: float
    keypoint_threshold: float = 0.0       # keypoint confidences below this become 0
    nms_iou: float = 0.7
    max_people: int = 100
    metadata: Dict[str, str] = field(default_factory=dict)
    licence: str = 'unknown'
    family: str = ''
    layout: str = LAYOUT
    last_timing: Timing = field(default_factory=Timing)
    provider: str = CPU                     # the execution provider that runs the model
    provider_options: Dict[str, str] = field(default_factory=dict)   # those set here, and device
    warnings: List[str] = field(default_factory=list)   # e.g. a provider fell back to CPU
    precision: str = 'fp32'                 # 'int8' for a quantised variant

    def __post_init__(self) -> None:
        self._input_name = self.session.get_inputs()[0].name
        self._output_names = [o.name for o in self.session.get_outputs()]

    # -- the three stages; subclasses implement preprocess and postprocess ---------------------
    def preprocess(self, image: np.ndarray, order: str = 'bgr') -> Tuple[np.ndarray, Letterbox]:
        """Return the network input tensor and the letterbox used."""
        raise NotImplementedError

    def postprocess(self, outputs: Sequence[np.ndarray], box: Letterbox) -> Detections:
        """Turn raw network outputs into ``Detections`` in original-image pixels."""
        raise NotImplementedError

    def run(self, tensor: np.ndarray) -> List[np.ndarray]:
        """Run the bare onnxruntime session on a prepared input tensor."""
        return self.session.run(self._output_names, {self._input_name: tensor})

    def warm_up(self) -> float:
        """
        Run the model once on a blank image of its input size; return the milliseconds taken.

        A GPU provider sets itself up on its first run (CUDA: kernels, cuDNN algorithms, memory;
        TensorRT: its engine), which otherwise falls on a camera's first images.
        """
        t0 = time.perf_counter()
        self.run(self.preprocess(np.zeros((*self.input_size, 3), np.uint8))[0])
        return (time.perf_counter() - t0) * 1e3

    def infer(self, image: np.ndarray, order: str = 'bgr') -> Detections:
        """Detect people in one image; stage times go to ``last_timing``."""
        t0 = time.perf_counter()
        tensor, box = self.preprocess(_check_image(image, order), order)
        t1 = time.perf_counter()
        outputs = self.run(tensor)
        t2 = time.perf_counter()
        dets = self.postprocess(outputs, box)
        t3 = time.perf_counter()
        self.last_timing = Timing((t1 - t0) * 1e3, (t2 - t1) * 1e3, (t3 - t2) * 1e3)
        return dets

    def _finish(self, kpts: np.ndarray, boxes: np.ndarray, scores: np.ndarray,
                box: Letterbox) -> Detections:
        """
        Clip confidences, apply the keypoint threshold, cast to float32.

        Keypoints guessed outside the image get confidence 0: no camera saw them there.
        """
        kpts = np.asarray(kpts, np.float32).reshape(-1, NUM_JOINTS, 3)
        conf = np.clip(np.nan_to_num(kpts[..., 2]), 0.0, 1.0)
        conf[(conf < self.keypoint_threshold) | ~box.inside(kpts[..., :2])] = 0.0
        kpts[..., 2] = conf
        return Detections(kpts, np.asarray(boxes, np.float32).reshape(-1, 4),
                          np.clip(np.asarray(scores, np.float32).reshape(-1), 0.0, 1.0))


def _check_image(image: np.ndarray, order: str) -> np.ndarray:
    """Refuse images the adapters cannot read, with a message naming the problem."""
    if not isinstance(image, np.ndarray) or image.dtype != np.uint8:
        raise ValueError(f'image must be a uint8 numpy array, got '
                         f'{getattr(image, "dtype", type(image))}')
    if order not in ('bgr', 'rgb', 'gray'):
        raise ValueError(f"order must be 'bgr', 'rgb' or 'gray', got {order!r}")
    if image.ndim == 3 and image.shape[2] == 1:
        image = image[:, :, 0]
    if not (image.ndim == 2 or (image.ndim == 3 and image.shape[2] == 3)):
        raise ValueError(f'image must be [H, W, 3] or [H, W], got shape {image.shape}')
    if image.shape[0] < 2 or image.shape[1] < 2:
        raise ValueError(f'image too small: {image.shape}')
    return image


def _to_rgb(image: np.ndarray, order: str) -> np.ndarray:
    if image.ndim == 2:
        return cv2.cvtColor(image, cv2.COLOR_GRAY2RGB)
    return cv2.cvtColor(image, cv2.COLOR_BGR2RGB) if order == 'bgr' else image


class YoloPoseEstimator(PoseEstimator):
    """Ultralytics YOLO pose export (``nms=False``): letterbox 114, NMS and inversion here."""

    def preprocess(self, image: np.ndarray, order: str = 'bgr') -> Tuple[np.ndarray, Letterbox]:
        """
        Letterbox with grey 114, RGB, CHW float32 / 255.

        Only the resized content is converted (one cv2 call: swap, scale, transpose) and
        written into a tensor whose padding stays 114 / 255; the tensor is reused between
        calls (one estimator per thread).
        """
        box = Letterbox.fit(image.shape[:2], self.input_size)
        content = cv2.resize(image, (box.content_w, box.content_h),
                             interpolation=cv2.INTER_LINEAR)
        if content.ndim == 2:
            content = cv2.cvtColor(content, cv2.COLOR_GRAY2BGR)
            order = 'bgr'
        if getattr(self, '_padded_for', None) != box:
            self._tensor = np.full((1, 3) + tuple(self.input_size), 114.0 / 255.0, np.float32)
            self._padded_for = box
        self._tensor[:, :, box.top:box.top + box.content_h, box.left:box.left + box.content_w] = \
            cv2.dnn.blobFromImage(content, 1.0 / 255.0, swapRB=(order == 'bgr'))
        return self._tensor, box

    def postprocess(self, outputs: Sequence[np.ndarray], box: Letterbox) -> Detections:
        """Threshold person scores, NMS, map boxes and keypoints to the original image."""
        out = np.asarray(outputs[0])[0]                    # [56, N]
        cand = np.nonzero(out[4] > self.score_threshold)[0]
        if cand.size == 0:
            return Detections.empty()
        rows = out[:, cand].T.astype(np.float64)           # [M, 56]
        boxes = xywh_to_xyxy(rows[:, :4])
        keep = nms(boxes, rows[:, 4], self.nms_iou, self.max_people)
        rows, boxes = rows[keep], boxes[keep]
        kpts = rows[:, 5:5 + 3 * NUM_JOINTS].reshape(-1, NUM_JOINTS, 3)
        kpts[..., :2] = box.to_original(kpts[..., :2])
        boxes = box.to_original(boxes.reshape(-1, 2, 2)).reshape(-1, 4)
        return self._finish(kpts, boxes, rows[:, 4], box)


class MoveNetEstimator(PoseEstimator):
    """MoveNet MultiPose: zero-padded letterbox, normalised (y, x) outputs, no NMS."""

    def preprocess(self, image: np.ndarray, order: str = 'bgr') -> Tuple[np.ndarray, Letterbox]:
        """Letterbox with black padding, RGB, NHWC in the model's integer type."""
        box = Letterbox.fit(image.shape[:2], self.input_size)
        rgb = _to_rgb(box.apply(image, 0), 'gray' if image.ndim == 2 else order)
        dtype = np.int32 if 'int32' in self.session.get_inputs()[0].type else np.uint8
        return rgb[None].astype(dtype, copy=False), box

    def postprocess(self, outputs: Sequence[np.ndarray], box: Letterbox) -> Detections:
        """Keep instances above the score threshold, best first, in original pixels."""
        out = np.asarray(outputs[0], np.float64).reshape(-1, 56)
        ih, iw = self.input_size
        order = np.argsort(-out[:, 55], kind='stable')
        out = out[order[out[order, 55] > self.score_threshold]][:self.max_people]
        if out.shape[0] == 0:
            return Detections.empty()
        raw = out[:, :51].reshape(-1, NUM_JOINTS, 3)
        kpts = np.empty_like(raw)
        kpts[..., 0], kpts[..., 1], kpts[..., 2] = raw[..., 1] * iw, raw[..., 0] * ih, raw[..., 2]
        kpts[..., :2] = box.to_original(kpts[..., :2])
        corners = np.stack([out[:, 52] * iw, out[:, 51] * ih, out[:, 54] * iw, out[:, 53] * ih],
                           axis=1)
        boxes = box.to_original(corners.reshape(-1, 2, 2)).reshape(-1, 4)
        return self._finish(kpts, boxes, out[:, 55], box)


_ADAPTERS = {'yolo-pose': YoloPoseEstimator, 'movenet-multipose': MoveNetEstimator}
DEFAULT_SCORE = {'yolo-pose': 0.25, 'movenet-multipose': 0.2}
_DEFAULT_SIZE = {'yolo-pose': (640, 640), 'movenet-multipose': (256, 256)}


def _describe(session) -> str:
    ins = ', '.join(f'{i.name} {i.type} {i.shape}' for i in session.get_inputs())
    outs = ', '.join(f'{o.name} {o.type} {o.shape}' for o in session.get_outputs())
    return f'inputs [{ins}], outputs [{outs}]'


def _static(dim) -> Optional[int]:
    return dim if isinstance(dim, int) and dim > 0 else None


def detect_family(session, metadata: Dict[str, str]) -> Tuple[Optional[str], str]:
    """
    Return ``(family, reason)`` from the ONNX metadata and tensor shapes.

    ``family`` is None when the model is not a supported pose model; ``reason`` says why.
    """
    ins, outs = session.get_inputs(), session.get_outputs()
    if len(ins) != 1 or len(outs) < 1:
        return None, f'expected one input, found {len(ins)} inputs and {len(outs)} outputs'
    shape_in, shape_out = list(ins[0].shape), list(outs[0].shape)
    task = metadata.get('task', '')
    if metadata.get('family') in FAMILIES:
        hint = metadata['family']
    elif task or 'ultralytics' in metadata.get('author', '').lower():
        hint = 'yolo-pose'
    else:
        hint = None
    if len(shape_in) == 4 and shape_in[1] == 3 and 'float' in ins[0].type:
        if task and task != 'pose':
            return None, (f'this is an Ultralytics {task!r} model, not a pose model '
                          f'(metadata task={task!r})')
        kpt = metadata.get('kpt_shape', '').replace(' ', '')
        if kpt and kpt != '[17,3]':
            return None, f'keypoint shape {kpt}, only COCO-17 [17,3] is supported'
        if len(shape_out) != 3 or shape_out[1] != 56:
            extra = (' (exported with nms=True? re-export with nms=False)'
                     if len(shape_out) == 3 and shape_out[2] in (56, 57) else '')
            return None, (f'output shape {shape_out}: a COCO-17 YOLO pose model outputs '
                          f'[1, 56, N] (4 box + 1 score + 17 x 3){extra}')
        return 'yolo-pose', 'input [1,3,H,W] float, output [1,56,N]'
    integer = 'uint8' in ins[0].type or 'int32' in ins[0].type
    if len(shape_in) == 4 and shape_in[3] == 3 and integer:
        if len(shape_out) == 3 and shape_out[2] == 56 and hint in (None, 'movenet-multipose'):
            return 'movenet-multipose', 'input [1,H,W,3] integer, output [1,6,56]'
        return None, f'output shape {shape_out}: MoveNet MultiPose outputs [1, 6, 56]'
    return None, f'input {ins[0].type} {shape_in} matches no supported family'


def create_session(path: str, opts: Any, providers: List[str]) -> Tuple[Any, str, List[str]]:
    """
    Create the session on ``providers``; return it, the provider used and warnings.

    A provider that fails to initialise (missing CUDA libraries, no device, TensorRT build
    error) does not stop the model: the session is created again on the CPU, with a warning.
    """
    import onnxruntime as ort
    warnings = []
    listed = [(p, _provider_options(p, path)) for p in providers]
    try:
        session = ort.InferenceSession(path, sess_options=opts, providers=listed)
    except Exception as exc:  # noqa: B902 - onnxruntime raises several private exception types
        if providers == [CPU]:
            raise ModelError(f'{path}: onnxruntime cannot load it: {exc}') from None
        warnings.append(f'execution providers {", ".join(providers[:-1])} failed to initialise '
                        f'({str(exc).splitlines()[0] if str(exc) else type(exc).__name__}); '
                        'falling back to CPUExecutionProvider')
        try:
            session = ort.InferenceSession(path, sess_options=opts, providers=[CPU])
        except Exception as exc2:  # noqa: B902
            raise ModelError(f'{path}: onnxruntime cannot load it: {exc2}') from None
    used = session.get_providers()
    chosen = used[0] if used else CPU
    if chosen != providers[0]:
        if not warnings:
            warnings.append(f'execution provider {providers[0]} failed to initialise (onnxruntime '
                            f'runs the model on {", ".join(used)}); falling back to {chosen}')
    return session, chosen, warnings


def open_estimator(path: str, family: str = 'auto', threads: int = 0,
                   input_size: Optional[Tuple[int, int]] = None,
                   score_threshold: Optional[float] = None, keypoint_threshold: float = 0.0,
                   nms_iou: float = 0.7, max_people: int = 100,
                   spin: bool = False,
                   providers: Union[str, Sequence[str]] = 'auto') -> PoseEstimator:
    """
    Load an ONNX pose model and return the adapter of its family.

    ``threads`` is onnxruntime's intra-op thread count (0 = one per core). ``input_size``
    (height, width) is needed only for models with dynamic input dimensions; for a static
    model it must match. ``score_threshold`` None uses the family default (YOLO 0.25,
    MoveNet 0.2). ``spin`` lets worker threads busy-wait (lower latency, burns idle CPU).
    ``providers``: see ``resolve_providers`` ('auto' picks the fastest available); a provider
    that is missing or fails to initialise falls back to the CPU, explained in ``warnings``.
    A fetched model (one with a sidecar) is checked against its recorded sha256 first.
    Raises ``ModelError`` for a missing, corrupt or unsupported model.
    """
    import onnxruntime as ort
    if not path or not os.path.isfile(path):
        raise ModelError(f'model file not found: {path!r} (fetch one with '
                         f'`mv3dpose model fetch`, or pass the path of a pose ONNX)')
    try:
        verify_model(path)
    except (ModelIntegrityError, OSError) as exc:
        raise ModelError(str(exc)) from None
    try:
        wanted, warnings = resolve_providers(providers)
    except ValueError as exc:
        raise ModelError(str(exc)) from None
    if {PROVIDERS['cuda'], PROVIDERS['tensorrt']} & set(wanted):
        warnings += preload_cuda()
    opts = ort.SessionOptions()
    opts.intra_op_num_threads = max(0, int(threads))
    opts.inter_op_num_threads = 1
    opts.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    opts.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    if not spin:
        opts.add_session_config_entry('session.intra_op.allow_spinning', '0')
    opts.log_severity_level = 3
    session, chosen, more = create_session(path, opts, wanted)
    warnings += more
    metadata = dict(session.get_modelmeta().custom_metadata_map)
    sidecar = read_sidecar(path) or {}
    if sidecar.get('family') and 'family' not in metadata:
        metadata['family'] = sidecar['family']
    found, reason = detect_family(session, metadata)
    if found is None:
        raise ModelError(f'{path} is not a supported 2D pose model: {reason}. '
                         f'Found {_describe(session)}; {_SUPPORTED}.')
    if family not in ('auto', '', None) and family != found:
        if family not in FAMILIES:
            raise ModelError(f'unknown model family {family!r}; known: {", ".join(FAMILIES)}')
        raise ModelError(f'{path} is a {found} model ({reason}), but family {family!r} was '
                         f'requested')
    shape = session.get_inputs()[0].shape
    hw = (shape[2], shape[3]) if found == 'yolo-pose' else (shape[1], shape[2])
    static = tuple(_static(d) for d in hw)
    if all(static):
        if input_size and tuple(int(v) for v in input_size) != static:
            raise ModelError(f'{path} has a static input of {static[0]}x{static[1]} (HxW), '
                             f'but input size {input_size[0]}x{input_size[1]} was requested')
        size = static
    else:
        size = tuple(int(v) for v in (input_size or sidecar.get('input_size')
                                      or _DEFAULT_SIZE[found]))
    licence = metadata.get('license') or sidecar.get('licence') or 'unknown'
    thr = DEFAULT_SCORE[found] if score_threshold is None else float(score_threshold)
    return _ADAPTERS[found](session=session, path=path, input_size=size, score_threshold=thr,
                            keypoint_threshold=float(keypoint_threshold),
                            nms_iou=float(nms_iou), max_people=int(max_people),
                            metadata=metadata, licence=licence, family=found,
                            provider=chosen,
                            provider_options=options_in_use(session, chosen, path),
                            warnings=warnings, precision=sidecar.get('precision', 'fp32'))
