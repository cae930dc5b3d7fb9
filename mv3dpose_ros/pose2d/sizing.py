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
Which input size of a camera's model runs: the size ladder and the estimator cache (no ROS).

``model.input_size auto`` starts on the registered model's default size; the first image picks
the fetched size that fits its aspect and the ladder of smaller fetched sizes that
``inference_rate_hz`` auto may step down to under load (``scheduling.size_ladder``). Each size
is a file of its own, opened once and kept: stepping back and forth costs nothing after the
first time.
"""

from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

from mv3dpose_ros.core.diagnostic_keys import Pose2DKeys as K
from mv3dpose_ros.pose2d.config import ModelConfig
from mv3dpose_ros.pose2d.estimator import DEFAULT_SCORE, ModelError
from mv3dpose_ros.pose2d.models import (fetched_sizes, fit_size, get_spec, ModelNotFound,
                                        parse_size, pick_precision, resolve_model_path, size_tag)
from mv3dpose_ros.pose2d.scheduling import size_ladder

Size = Tuple[int, int]
#: What the size choice has to say: (logger level, text).
Note = Tuple[str, str]
#: Dynamic parameters set on the estimator in use, carried over to the next size.
DYNAMIC_VALUES = ('score_threshold', 'keypoint_threshold', 'nms_iou', 'max_people')


class EstimatorCache:
    """
    The estimator a camera runs now and the other input sizes of its model, each opened once.

    ``open_file(path, input_size)`` opens an estimator (the node's, which logs and warms it
    up), ``on_cpu()`` tells whether the model runs on the CPU (for precision auto) and
    ``on_ladder(sizes)`` hears each new ladder (auto mode steps along it).
    """

    def __init__(self, config: ModelConfig, open_file: Callable[[str, Optional[Size]], Any],
                 on_cpu: Callable[[], bool], on_ladder: Callable[[List[Size]], None]) -> None:
        self.config = config
        self._open_file, self._on_cpu, self._on_ladder = open_file, on_cpu, on_ladder
        self.estimator: Any = None
        self.ladder: List[Size] = []      # sizes auto may use, the fitted one first
        self.fit_pending = False          # model.input_size auto: choose at the first image
        self._by_size: Dict[Size, Any] = {}

    def path(self, size: Optional[Sequence[int]]) -> str:
        """Return the file of the registered model at ``size`` (None: its default size)."""
        name, cache = self.config.name, self.config.cache_dir or None
        hw = tuple(size) if size else get_spec(name).default_size
        precision = pick_precision(name, hw, cache, self.config.precision, self._on_cpu())
        return resolve_model_path(name, size_tag(hw), cache, precision)

    def fetched_sizes(self) -> List[Size]:
        """Return the sizes of the registered model in the cache: registry order, then others."""
        precision = self.config.precision
        if precision == 'auto':
            precision = ('fp32', 'int8') if self._on_cpu() else 'fp32'
        return fetched_sizes(self.config.name, self.config.cache_dir or None, precision)

    def load(self) -> Any:
        """Open the estimator to start with: ``model.path`` or the registered model's file."""
        size = str(self.config.input_size).strip().lower()
        self.fit_pending = False
        path, hw = self.config.path, None
        if path:
            hw = parse_size(size) if size not in ('', 'auto') else None
        elif size == 'auto':
            spec = get_spec(self.config.name)
            have = self.fetched_sizes()
            # Start on the default size (or any fetched); the first image picks the best.
            path = self.path(spec.default_size if spec.default_size in have or not have
                             else have[0])
            self.fit_pending = True
        else:
            path = self.path(parse_size(size) if size else None)
        self.estimator = self._open_file(path, hw)
        return self.estimator

    def follow(self, image_hw: Size, auto_size: Callable[[], Optional[Size]]) -> Optional[
            List[Note]]:
        """
        Before inferring an image: fit the size to the first one, then use the size wanted.

        Wanted is ``auto_size()`` (auto mode's choice) or else the fitted size. Return what to
        log; None when nothing was done (else the time spent is a one-off, not image path
        time). A size that cannot be opened is logged, and the one in use kept.
        """
        notes: Optional[List[Note]] = None
        if self.fit_pending:
            notes = []
            try:
                self._fit(image_hw, notes)
            except (ModelError, ModelNotFound, ValueError) as exc:
                notes.append(('warning', f'keeping input size '
                                         f'{size_tag(self.estimator.input_size)}: {exc}'))
        wanted = auto_size()
        wanted = wanted if wanted is not None else self.ladder[0] if self.ladder else None
        if wanted is not None and wanted != tuple(self.estimator.input_size):
            notes = notes or []
            try:
                self.use(wanted)
            except (ModelError, ModelNotFound, ValueError) as exc:
                self.ladder = [tuple(self.estimator.input_size)]
                self._on_ladder(self.ladder)
                notes.append(('warning', f'keeping input size '
                                         f'{size_tag(self.estimator.input_size)}: {exc}'))
        return notes

    def _fit(self, image_hw: Size, notes: List[Note]) -> None:
        """At the first image: choose the fetched input size that fits it, and the ladder."""
        self.fit_pending = False
        spec = get_spec(self.config.name)
        best = fit_size(spec.sizes, image_hw)
        have = self.fetched_sizes()
        usable = fit_size(have, image_hw) if have else tuple(self.estimator.input_size)
        h, w = image_hw
        if best != usable:
            notes.append(('warning', f'{w}x{h} images fit the {size_tag(best)} input of '
                          f'{spec.name} best (same detail, less padding, faster); it is not '
                          f'fetched: run `mv3dpose model fetch --model {spec.name} --size '
                          f'{size_tag(best)}`'))
        self.ladder = size_ladder(image_hw, usable, have, int(self.config.min_input_side))
        self._on_ladder(self.ladder)
        steps = (f'; under load inference_rate_hz auto may step down to '
                 f'{", ".join(size_tag(s) for s in self.ladder[1:])}'
                 if len(self.ladder) > 1 else '')
        self.use(usable)
        notes.append(('info', f'input size {size_tag(usable)} for {w}x{h} images '
                              f'(model.input_size auto){steps}'))

    def use(self, size: Sequence[int]) -> None:
        """Switch to input size ``size``: its file opened once, the dynamic values kept."""
        est = self.estimator
        if est is None or tuple(est.input_size) == tuple(size):
            return
        self._by_size.setdefault(tuple(est.input_size), est)
        new = self._by_size.get(tuple(size))
        if new is None:
            new = self._by_size[tuple(size)] = self._open_file(self.path(size), None)
        for name in DYNAMIC_VALUES:
            setattr(new, name, getattr(est, name))      # dynamic values set since configure
        self.estimator = new

    def set_value(self, name: str, value: Any) -> None:
        """Apply a dynamic parameter of ``DYNAMIC_VALUES`` to the estimator in use."""
        est = self.estimator
        if est is None or name not in DYNAMIC_VALUES:
            return
        if name == 'score_threshold':
            est.score_threshold = float(value) if float(value) >= 0 else DEFAULT_SCORE[est.family]
        else:
            setattr(est, name, int(value) if name == 'max_people' else float(value))

    def values(self) -> Dict[str, Any]:
        """Return the /diagnostics values of the model in use (none before it is open)."""
        est = self.estimator
        if est is None:
            return {}
        return {'Model': est.path, 'Model family': est.family,
                K.INPUT_SIZE: f'{est.input_size[0]}x{est.input_size[1]}',
                'Input size steps (auto)': ', '.join(size_tag(z) for z in self.ladder)
                or 'fixed', K.PRECISION: est.precision, 'Execution provider': est.provider,
                K.THREADS: int(self.config.threads), 'Weights licence': est.licence}


def describe(est: Any, threads: int, ready_ms: Optional[float] = None) -> str:
    """Return the log line naming an opened estimator: file, size, provider and its options."""
    options = ', '.join(f'{k}={v}' for k, v in sorted(est.provider_options.items()))
    ready = f', set up in {ready_ms:.0f} ms' if ready_ms is not None else ''
    return (f'{est.family} model {est.path} input {est.input_size[0]}x{est.input_size[1]} '
            f'{est.precision} on {est.provider} ({options or "default options"}{ready}), '
            f'intra-op threads {threads or "one per core"}, score>{est.score_threshold:g}; '
            f'weights licence: {est.licence}')
