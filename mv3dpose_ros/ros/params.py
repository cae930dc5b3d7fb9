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
Declare ROS parameters with descriptors, including every field of a core config dataclass.

Core config dataclasses (``FusionConfig``, ``SyncConfig``) stay the single source of truth for
names, types and defaults: ``declare_config`` declares ``<prefix>.<field>`` for each scalar
field (recursing into nested dataclasses), with the description taken from the field's
trailing ``# comment`` in the source (or ``metadata['help']``), and ``build_config`` reads
them back into an instance.
"""

import dataclasses
import difflib
import inspect
import io
import os
import re
import tokenize
import typing
from typing import Any, Dict, List, Optional, Sequence

from rcl_interfaces.msg import ParameterDescriptor
from rclpy.exceptions import ParameterUninitializedException
from rclpy.parameter import Parameter

_ARRAY_TYPES = {str: Parameter.Type.STRING_ARRAY, float: Parameter.Type.DOUBLE_ARRAY,
                int: Parameter.Type.INTEGER_ARRAY, bool: Parameter.Type.BOOL_ARRAY}
_SCALARS = (bool, int, float, str)


def descriptor(description: str, read_only: bool = False, dynamic: bool = False,
               dynamic_typing: bool = False) -> ParameterDescriptor:
    """Return a descriptor; dynamic parameters are tagged '[DYNAMIC]' (ZED convention)."""
    text = f'[DYNAMIC] {description}' if dynamic else description
    return ParameterDescriptor(description=text, read_only=read_only,
                               dynamic_typing=dynamic_typing)


def declare(node: Any, name: str, default: Any, description: str, read_only: bool = False,
            dynamic: bool = False, element_type: type = str,
            dynamic_typing: bool = False) -> None:
    """Declare one parameter; an empty-list default needs ``element_type`` to type the array."""
    desc = descriptor(description, read_only, dynamic, dynamic_typing)
    if isinstance(default, (list, tuple)) and len(default) == 0:
        node.declare_parameter(name, _ARRAY_TYPES[element_type], desc)
    else:
        node.declare_parameter(name, list(default) if isinstance(default, tuple) else default,
                               desc)


def value(node: Any, name: str, default: Any = None) -> Any:
    """Return a parameter value; ``default`` when it was declared without a value."""
    try:
        v = node.get_parameter(name).value
    except ParameterUninitializedException:
        return default
    return list(v) if isinstance(v, (list, tuple)) or hasattr(v, 'tolist') else v


def field_comments(cls: type) -> Dict[str, str]:
    """
    Return ``{field: trailing comment}`` from the source of a dataclass (empty if absent).

    A comment continues on the following comment-only lines whose text is indented by two or
    more spaces after the ``#`` (aligned under the first line), as in ``core.fusion.config``.
    """
    try:
        source = inspect.getsource(cls)
    except (OSError, TypeError):
        return {}
    out: Dict[str, str] = {}
    line_of_field: Dict[int, str] = {}
    lines = source.splitlines()
    for lineno, line in enumerate(lines, 1):
        m = re.match(r'\s+([A-Za-z_]\w*)\s*:[^=]*=', line)
        if m:
            line_of_field[lineno] = m.group(1)
    try:
        for tok in tokenize.generate_tokens(io.StringIO(source).readline):
            if tok.type == tokenize.COMMENT and tok.start[0] in line_of_field:
                name = line_of_field[tok.start[0]]
                text = tok.string.lstrip('#').strip()
                for follow in lines[tok.start[0]:]:
                    m = re.match(r'^\s*#\s{2,}(\S.*)$', follow)
                    if not m:
                        break
                    text += ' ' + m.group(1).strip()
                out[name] = text
    except (tokenize.TokenError, IndentationError):
        pass
    return out


def _scalar_type(hint: Any) -> Optional[type]:
    origin = typing.get_origin(hint)
    if origin is typing.Union:
        args = [a for a in typing.get_args(hint) if a is not type(None)]
        return _scalar_type(args[0]) if len(args) == 1 else None
    if hint in _SCALARS:
        return hint
    return None


def _array_type(hint: Any) -> Optional[type]:
    origin = typing.get_origin(hint)
    if origin in (list, tuple, List, Sequence, typing.Tuple):
        args = [a for a in typing.get_args(hint) if a is not Ellipsis]
        if args and all(a == args[0] for a in args) and args[0] in _ARRAY_TYPES:
            return args[0]
    return None


def _default_of(f: dataclasses.Field) -> Any:
    if f.default is not dataclasses.MISSING:
        return f.default
    if f.default_factory is not dataclasses.MISSING:  # type: ignore[misc]
        return f.default_factory()  # type: ignore[misc]
    return dataclasses.MISSING


def dataclass_parameters(cls: type, prefix: str) -> List[Dict[str, Any]]:
    """List the parameters a dataclass maps to: name, field path, default, type, description."""
    hints = typing.get_type_hints(cls)
    comments = field_comments(cls)
    out = []
    for f in dataclasses.fields(cls):
        default = _default_of(f)
        hint = hints.get(f.name, f.type)
        name = f'{prefix}.{f.name}'
        help_text = f.metadata.get('help') or comments.get(f.name) or f.name.replace('_', ' ')
        if dataclasses.is_dataclass(hint) and isinstance(hint, type):
            for sub in dataclass_parameters(hint, name):
                sub['path'] = [f.name] + sub['path']
                out.append(sub)
            continue
        scalar = _scalar_type(hint)
        if scalar is not None and default is not None and default is not dataclasses.MISSING:
            if scalar is float and isinstance(default, int) and not isinstance(default, bool):
                default = float(default)
            out.append({'name': name, 'path': [f.name], 'default': default, 'type': scalar,
                        'description': help_text})
            continue
        elem = _array_type(hint)
        if elem is not None and default is not dataclasses.MISSING and default is not None:
            out.append({'name': name, 'path': [f.name], 'default': list(default),
                        'type': list, 'element': elem, 'description': help_text})
    return out


def _assemble(cls: type, values: Dict[tuple, Any], path: tuple) -> Any:
    hints = typing.get_type_hints(cls)
    kwargs = {}
    for f in dataclasses.fields(cls):
        hint = hints.get(f.name, f.type)
        key = path + (f.name,)
        if dataclasses.is_dataclass(hint) and isinstance(hint, type):
            kwargs[f.name] = _assemble(hint, values, key)
        elif key in values:
            default = _default_of(f)
            v = values[key]
            if isinstance(default, tuple):
                v = tuple(v)
            kwargs[f.name] = v
    return cls(**kwargs)


def resolve_path(path: str, search: Sequence[str] = ()) -> str:
    """Return ``path`` if it exists, else the first ``<dir>/<path>`` that does (else ``path``)."""
    path = os.path.expanduser(str(path))
    if os.path.isabs(path) or os.path.exists(path):
        return path
    for base in search:
        candidate = os.path.join(base, path)
        if os.path.exists(candidate):
            return candidate
    return path


def package_search_dirs() -> List[str]:
    """Return the directories relative paths of config files are resolved against."""
    dirs = [os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))]
    try:
        from ament_index_python.packages import get_package_share_directory
        dirs.append(get_package_share_directory('mv3dpose_ros'))
    except Exception:  # noqa: B902 - no ament index (plain wheels): the source tree is enough
        pass
    return dirs


def all_parameter_docs(node: Any) -> List[Dict[str, Any]]:
    """Return name, type, default value and description of every declared parameter."""
    rows = []
    for name in sorted(node._parameters):
        if name == 'use_sim_time':
            continue
        desc = node.describe_parameter(name)
        try:
            v = node.get_parameter(name).value
        except ParameterUninitializedException:
            v = []
        rows.append({'name': name, 'type': Parameter.Type(desc.type).name.lower(), 'default': v,
                     'description': desc.description, 'read_only': desc.read_only})
    return rows


def unknown_parameter_warnings(node: Any) -> List[str]:
    """
    Return one warning per parameter override the node did not declare (typo, stale name).

    Overrides come from ``-p``, params files and launch arguments (rcl merges them before the
    node starts); with ``allow_undeclared_parameters`` off rclpy silently ignores the ones the
    node never declares, so each is named here with the closest declared name.
    """
    declared = sorted(node._parameters)
    out = []
    for name in sorted(getattr(node, '_parameter_overrides', {}) or {}):
        if name in node._parameters or name in ('use_sim_time', 'start_type_description_service'):
            continue
        close = difflib.get_close_matches(name, declared, n=1, cutoff=0.6)
        hint = f'; did you mean {close[0]!r}?' if close else ''
        out.append(f'parameter {name!r} is not a parameter of {node.get_name()} and is '
                   f'ignored{hint}')
    return out


def config_parameters(cls: type, prefix: str = '') -> List[Dict[str, Any]]:
    """
    List the parameters of a node config dataclass, as ``dataclass_parameters`` does.

    An empty ``prefix`` gives top-level names (``rig_config``; nested dataclass fields give
    ``limits.max_persons``). Each row also says ``dynamic``: the field, or a dataclass field it
    is nested in, has ``metadata={'dynamic': True}`` (may change at run time), and
    ``dynamic_typing``: the field's ``metadata={'dynamic_typing': True}`` (takes any type).
    """
    rows = dataclass_parameters(cls, prefix or '_')
    for row in rows:
        if not prefix:
            row['name'] = row['name'][2:]
        owner, dynamic = cls, False
        for name in row['path']:
            f = {x.name: x for x in dataclasses.fields(owner)}[name]
            dynamic = dynamic or bool(f.metadata.get('dynamic', False))
            owner = typing.get_type_hints(owner).get(name, f.type)
        row['dynamic'] = dynamic
        row['dynamic_typing'] = bool(f.metadata.get('dynamic_typing', False))
    return rows


def declare_config(node: Any, cls: type, prefix: str = '') -> None:
    """Declare ``config_parameters(cls, prefix)``: dynamic ones '[DYNAMIC]', others read-only."""
    for p in config_parameters(cls, prefix):
        declare(node, p['name'], p['default'], p['description'], read_only=not p['dynamic'],
                dynamic=p['dynamic'], element_type=p.get('element', str),
                dynamic_typing=p['dynamic_typing'])


def build_config(node: Any, cls: type, prefix: str = '') -> Any:
    """Build an instance of ``cls`` from the parameters declared by ``declare_config``."""
    values: Dict[tuple, Any] = {}
    for p in config_parameters(cls, prefix):
        v = value(node, p['name'], p['default'])
        if p['type'] is float:
            v = float(v)
        elif p['type'] is list:
            v = type(p['default'])(v)
        values[tuple(p['path'])] = v
    return _assemble(cls, values, ())
