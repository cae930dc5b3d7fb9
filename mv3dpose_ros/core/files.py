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
Untrusted input files and atomic output files: the one implementation every reader uses.

Parsing (``load_json``, ``load_yaml``, ``load_toml``, ``read_text``) has bounded cost and
raises ``LoadError`` (a ``ValueError``) saying what is wrong; readers add the file name and
turn it into their own error type (``CalibrationError``, ``TracksFormatError``, ...):

* JSON: nesting deeper than ``MAX_DEPTH`` is refused before parsing (no ``RecursionError``),
  an integer literal longer than ``MAX_INT_DIGITS`` digits or a number that overflows a double
  (``1e400``) is refused instead of becoming a huge int or inf, ``NaN``/``Infinity`` only where
  the caller allows them.
* YAML: the safe loader (plain data only) with the same depth limit, and aliases resolved by
  reference and counted: a document whose expanded size exceeds ``MAX_YAML_NODES`` (the
  "billion laughs" alias bomb) is refused after composing its few nodes, before anything is
  expanded.
* TOML: ``tomllib`` with the same integer limit and deep nesting refused.
* ``read_text`` refuses files beyond a size limit and text that is not UTF-8.

Outputs (``temp_path_beside``, ``atomic_path``): write to a hidden temporary file in the
target's folder and rename it onto the target only on success, so an interrupted or failed
run never leaves a partial file under the final name.
"""

from contextlib import contextmanager
import json
import math
import os
from pathlib import Path
import re
import tempfile
import tomllib
from typing import Any, Iterator, Union

import numpy as np
import yaml

#: Deepest nesting of lists / objects accepted in any input document.
MAX_DEPTH = 64
#: Longest integer literal accepted (int64 has 19 digits).
MAX_INT_DIGITS = 20
#: Largest expanded YAML document (nodes, aliases counted at every use).
MAX_YAML_NODES = 200_000
#: Default size limit of a whole input file read into memory [bytes].
MAX_FILE_BYTES = 256 * 1024 * 1024

PathLike = Union[str, os.PathLike]


class LoadError(ValueError):
    """Text that is not valid, or exceeds a limit; the message says what (no file name)."""


# ------------------------------------------------------------------------------------ reading

def read_text(path: PathLike, max_bytes: int = MAX_FILE_BYTES) -> str:
    """Return the UTF-8 text of ``path``; LoadError beyond ``max_bytes`` or for non-UTF-8."""
    with open(path, 'rb') as f:
        raw = f.read(max_bytes + 1)
    if len(raw) > max_bytes:
        raise LoadError(f'file larger than {max_bytes} bytes')
    try:
        return raw.decode('utf-8')
    except UnicodeDecodeError as e:
        raise LoadError(f'not UTF-8 text (byte {e.start})') from None


_JSON_STRING = re.compile(r'"(?:[^"\\]|\\.)*"')


def nesting_depth(text: str) -> int:
    """Return the deepest bracket nesting of JSON ``text`` (brackets in strings not counted)."""
    raw = np.frombuffer(_JSON_STRING.sub('""', text).encode('utf-8', 'replace'), np.uint8)
    if not raw.size:
        return 0
    step = (np.isin(raw, (91, 123)).astype(np.int32) - np.isin(raw, (93, 125)))
    return int(max(np.cumsum(step).max(), 0))


def _parse_int(text: str) -> int:
    if len(text.lstrip('-')) > MAX_INT_DIGITS:
        raise LoadError(f'integer with {len(text.lstrip("-"))} digits (at most '
                        f'{MAX_INT_DIGITS}): {text[:12]}...')
    return int(text)


def _parse_float(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        raise LoadError(f'number {text[:24]} is out of range (not a finite double)')
    return value


def _refuse_constant(name: str) -> float:
    raise LoadError(f'{name} is not a JSON number')


def load_json(text: Union[str, bytes], allow_nan: bool = False) -> Any:
    """
    Parse JSON ``text`` with the depth and number limits; LoadError says what is wrong.

    ``allow_nan``: ``NaN``, ``Infinity`` and ``-Infinity`` (Python's extension) become float
    NaN / inf instead of an error.
    """
    if isinstance(text, bytes):
        try:
            text = text.decode('utf-8')
        except UnicodeDecodeError as e:
            raise LoadError(f'not UTF-8 text (byte {e.start})') from None
    depth = nesting_depth(text)
    if depth > MAX_DEPTH:
        raise LoadError(f'nesting {depth} levels deep (at most {MAX_DEPTH})')
    try:
        return json.loads(text, parse_int=_parse_int, parse_float=_parse_float,
                          parse_constant=float if allow_nan else _refuse_constant)
    except json.JSONDecodeError as e:
        raise LoadError(f'invalid JSON ({e.msg} at line {e.lineno} column {e.colno})') from None
    except RecursionError:   # only if MAX_DEPTH is raised beyond what the parser can do
        raise LoadError('nesting too deep') from None


class _BoundedLoader(yaml.SafeLoader):
    """SafeLoader with a nesting limit and big integers refused."""

    def __init__(self, stream: str) -> None:
        super().__init__(stream)
        self._depth = 0

    def compose_node(self, parent, index):
        self._depth += 1
        try:
            if self._depth > MAX_DEPTH:
                raise LoadError(f'nesting deeper than {MAX_DEPTH} levels')
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1

    def construct_yaml_int(self, node):
        digits = re.sub(r'[^0-9a-fA-F]', '', str(node.value))
        if len(digits) > MAX_INT_DIGITS:
            raise LoadError(f'integer with {len(digits)} digits (at most {MAX_INT_DIGITS}) at '
                            f'line {node.start_mark.line + 1}')
        return super().construct_yaml_int(node)


_BoundedLoader.add_constructor('tag:yaml.org,2002:int', _BoundedLoader.construct_yaml_int)


def _expanded_size(node, memo: dict) -> int:
    """Return the node count of ``node`` with every alias expanded (memoised per node)."""
    key = id(node)
    if key in memo:
        return memo[key]
    memo[key] = 1                        # a cycle (recursive alias) counts once per visit
    size = 1
    if isinstance(node, yaml.MappingNode):
        for k, v in node.value:
            size += _expanded_size(k, memo) + _expanded_size(v, memo)
    elif isinstance(node, yaml.SequenceNode):
        for v in node.value:
            size += _expanded_size(v, memo)
    memo[key] = size
    return size


def load_yaml(text: str) -> Any:
    """Parse YAML ``text`` safely (plain data, bounded depth and expanded size)."""
    loader = _BoundedLoader(text)
    try:
        node = loader.get_single_node()
        if node is None:
            return None
        size = _expanded_size(node, {})
        if size > MAX_YAML_NODES:
            raise LoadError(f'document expands to {size} nodes through aliases (at most '
                            f'{MAX_YAML_NODES}): an alias bomb?')
        return loader.construct_document(node)
    except yaml.YAMLError as e:
        msg = str(e).splitlines()[0] if str(e) else type(e).__name__
        mark = getattr(e, 'problem_mark', None)
        where = f' at line {mark.line + 1} column {mark.column + 1}' if mark else ''
        raise LoadError(f'invalid YAML ({msg}{where})') from None
    except RecursionError:
        raise LoadError('nesting too deep') from None
    finally:
        loader.dispose()


def load_toml(text: str) -> Any:
    """Parse TOML ``text`` with the integer and depth limits."""
    depth = nesting_depth(text)
    if depth > MAX_DEPTH:
        raise LoadError(f'nesting {depth} levels deep (at most {MAX_DEPTH})')
    try:
        data = tomllib.loads(text, parse_float=_parse_float)
    except tomllib.TOMLDecodeError as e:
        raise LoadError(f'invalid TOML ({e})') from None
    except RecursionError:
        raise LoadError('nesting too deep') from None
    _check_ints(data)
    return data


def _check_ints(value: Any, depth: int = 0) -> None:
    if isinstance(value, bool):
        return
    if isinstance(value, int):
        if abs(value) >= 10 ** MAX_INT_DIGITS:
            raise LoadError(f'integer with more than {MAX_INT_DIGITS} digits')
    elif isinstance(value, dict):
        for v in value.values():
            _check_ints(v, depth + 1)
    elif isinstance(value, list):
        for v in value:
            _check_ints(v, depth + 1)


# ------------------------------------------------------------------------------------ writing

def temp_path_beside(output: PathLike) -> str:
    """
    Create an empty hidden temp file beside ``output`` (same folder, same suffix).

    Writers fill it and ``os.replace`` it onto ``output`` when done, so a crash never leaves a
    half-written file under the final name. Permissions follow the umask like ``open``.
    Raises ``FileNotFoundError`` naming the output when its folder does not exist.
    """
    out = Path(output)
    if not out.parent.is_dir():
        raise FileNotFoundError(f'{output}: output folder {out.parent} does not exist')
    fd, tmp = tempfile.mkstemp(prefix=f'.{out.stem}.', suffix=f'.partial{out.suffix}',
                               dir=out.parent)
    os.close(fd)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)
    return tmp


@contextmanager
def atomic_path(output: PathLike) -> Iterator[str]:
    """
    Yield a temp path beside ``output``; renamed onto ``output`` if the block succeeds.

    On any exception (also KeyboardInterrupt) the temp file is removed and ``output`` is left
    as it was.
    """
    tmp = temp_path_beside(output)
    try:
        yield tmp
        os.replace(tmp, output)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
