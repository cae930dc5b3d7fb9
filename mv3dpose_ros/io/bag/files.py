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
What a rosbag2 bag is on disk, and the one error every part of ``io.bag`` raises.

A bag is a directory with ``metadata.yaml`` and storage files (``.mcap``, ``.db3``), or a
lone storage file.
"""

import os
from pathlib import Path
import re
from typing import List, Union

from mv3dpose_ros.core.files import load_yaml, LoadError, read_text
from mv3dpose_ros.core.files import temp_path_beside as _temp_path_beside

STORAGES = ('mcap', 'sqlite3')
DEFAULT_STORAGE = 'mcap'
MCAP_MAGIC = b'\x89MCAP0\r\n'

PathLike = Union[str, os.PathLike]


class BagError(RuntimeError):
    """A bag cannot be read or written; the message names the file and the reason."""


def storage_files(path: Path) -> List[Path]:
    """Return the storage files of a bag directory (sorted), or ``[path]`` for a lone file."""
    if path.is_dir():
        return sorted(list(path.glob('*.mcap')) + list(path.glob('*.db3')))
    return [path]


def check_metadata(path: Path) -> None:
    """Read ``metadata.yaml`` with the bounded loader before rosbags does (alias bombs)."""
    meta = path / 'metadata.yaml'
    try:
        data = load_yaml(read_text(meta, 16 * 1024 * 1024))
    except (OSError, LoadError) as exc:
        raise BagError(f'{meta}: unreadable bag metadata: {exc}') from None
    info = data.get('rosbag2_bagfile_information') if isinstance(data, dict) else None
    files = info.get('relative_file_paths') if isinstance(info, dict) else None
    if not isinstance(files, list) or not all(isinstance(f, str) for f in files):
        raise BagError(f'{meta}: no rosbag2_bagfile_information.relative_file_paths list')
    for name in files:
        inside = (path / name).resolve()
        if path.resolve() not in inside.parents:
            raise BagError(f'{meta}: relative_file_paths entry {name!r} leaves the bag folder')


def is_bag(path: PathLike) -> bool:
    """
    Tell whether ``path`` is a rosbag2 bag this tool may replace.

    A storage file (``.mcap``, ``.db3``), or a directory holding ``metadata.yaml`` and
    otherwise only bag files (storage files, their journals, ``.yaml``), nothing nested.
    """
    p = Path(path)
    if p.is_file():
        return p.suffix in ('.mcap', '.db3')
    if not p.is_dir() or not (p / 'metadata.yaml').is_file():
        return False
    allowed = re.compile(r'.*\.(mcap|db3|db3-journal|db3-wal|db3-shm|yaml|zstd|lz4)$')
    return all(c.is_file() and allowed.match(c.name) for c in p.iterdir())


def check_replaceable(path: Path) -> None:
    """Raise ``BagError`` if something other than a bag stands at ``path``."""
    if path.exists() and not is_bag(path):
        kind = 'directory' if path.is_dir() else 'file'
        raise BagError(f'{path}: exists and is a {kind} that is not a rosbag2 bag; '
                       '--overwrite replaces only bags, so nothing was written')


def bag_path_type(path: PathLike) -> str:
    """Return 'bag' for a rosbag2 directory or storage file, 'file' otherwise (for dispatch)."""
    p = Path(path)
    if p.is_dir() and (p / 'metadata.yaml').exists():
        return 'bag'
    if p.suffix in ('.mcap', '.db3'):
        return 'bag'
    return 'file'


def temp_path_beside(output: PathLike) -> str:
    """``core.files.temp_path_beside`` with a missing output folder as ``BagError``."""
    try:
        return _temp_path_beside(output)
    except FileNotFoundError as exc:
        raise BagError(str(exc)) from None
