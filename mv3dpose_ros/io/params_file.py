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
ROS 2 parameter files (YAML) read as plain data, without rclpy.

A node reads its params files through rcl; what reads them outside a node (``mv3dpose track
--params``, the process list of a rig) reads them here, with the bounded YAML loader of
``core.files``. A params file maps node keys (``/**``, ``/**/fusion_node``, ``fusion_node``,
or namespaces nesting a node name) to ``ros__parameters`` mappings.
"""

from typing import Any, Dict, Iterator, Optional, Sequence, Tuple

from mv3dpose_ros.core.files import load_yaml, LoadError, read_text

#: most bytes of a params file read (a params file is a few kB)
PARAMS_FILE_BYTES = 16 * 1024 * 1024


class ParamsFileError(ValueError):
    """A params file that is not valid YAML or exceeds a limit; the text names the file."""


def read_params_file(path: str, max_bytes: int = PARAMS_FILE_BYTES) -> Any:
    """Return the YAML data of ``path`` (``OSError`` when it cannot be read)."""
    try:
        return load_yaml(read_text(path, max_bytes))
    except LoadError as e:
        raise ParamsFileError(f'{path}: {e}') from None


def parameter_sections(doc: Any, keys: Tuple[str, ...] = ()
                       ) -> Iterator[Tuple[Tuple[str, ...], Dict[str, Any]]]:
    """
    Yield ``(keys, parameters)`` of every ``ros__parameters`` mapping in ``doc``, in file order.

    ``keys`` are the mapping keys above it (``('/**/fusion_node',)``, or ``('ns',
    'fusion_node')`` for a node under a namespace key); depth first, a section before the
    mappings inside it.
    """
    if not isinstance(doc, dict):
        return
    params = doc.get('ros__parameters')
    if isinstance(params, dict):
        yield keys, params
    for key, value in doc.items():
        yield from parameter_sections(value, keys + (str(key),))


def first_section_with(doc: Any, name: str) -> Optional[Dict[str, Any]]:
    """Return mapping ``name`` of the first ``ros__parameters`` that holds one, whatever node."""
    return next((params[name] for _, params in parameter_sections(doc)
                 if isinstance(params.get(name), dict)), None)


def node_parameters(docs: Sequence[Dict[str, Any]], node: str) -> Dict[str, Any]:
    """
    Merge the ``ros__parameters`` of every top-level key that names ``node``, files in order.

    The keys are ``/**``, ``/**/<node>``, ``<node>`` and ``/<node>`` (a trailing ``/``
    ignored); a later section wins, as in rcl.
    """
    out: Dict[str, Any] = {}
    for doc in docs:
        for key, section in (doc or {}).items():
            name = str(key).rstrip('/')
            if name in ('/**', f'/**/{node}', node, f'/{node}') and isinstance(section, dict):
                out.update(section.get('ros__parameters', {}) or {})
    return out
