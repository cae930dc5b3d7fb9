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
Deprecated console-script names, kept for one release (0.1.x); removed in 0.2.0.

``bringup`` and ``image_publisher`` are generic names that can shadow, or be shadowed by, another
package's scripts on a PATH. The package now installs ``mv3dpose_bringup`` and
``mv3dpose_image_publisher``; the old names still work but say once on stderr which name to use.
"""

import sys
from typing import Callable, Optional


def _deprecated(old: str, new: str, main: Callable[[], Optional[int]]) -> Optional[int]:
    print(f'{old}: this name is deprecated and will be removed in 0.2.0; use {new}',
          file=sys.stderr, flush=True)
    return main()


def bringup() -> Optional[int]:
    """Run ``mv3dpose_bringup`` under its deprecated name ``bringup``."""
    from mv3dpose_ros.nodes.bringup import main
    return _deprecated('bringup', 'mv3dpose_bringup', main)


def image_publisher() -> Optional[int]:
    """Run ``mv3dpose_image_publisher`` under its deprecated name ``image_publisher``."""
    from mv3dpose_ros.nodes.image_publisher import main
    return _deprecated('image_publisher', 'mv3dpose_image_publisher', main)
