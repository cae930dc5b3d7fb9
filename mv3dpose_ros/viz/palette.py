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
One palette: a track keeps one colour everywhere it is drawn.

Tableau-10 order with navy for its grey (visible on grey camera images and on white panels).
OpenCV drawing takes BGR 0-255 (:func:`track_colour`); ROS ``ColorRGBA`` and Foxglove take RGB
0-1 (:func:`track_rgb`); both come from the same table.
"""

from typing import Tuple

#: Distinct colours, BGR 0-255.
PALETTE = ((180, 119, 31), (14, 127, 255), (44, 160, 44), (40, 39, 214), (189, 103, 148),
           (75, 86, 140), (194, 119, 227), (110, 30, 20), (34, 189, 188), (207, 190, 23))


def track_colour(track_id: int) -> Tuple[int, int, int]:
    """Return the BGR 0-255 colour of a track id (or of a detection index)."""
    return PALETTE[int(track_id) % len(PALETTE)]


def track_rgb(track_id: int) -> Tuple[float, float, float]:
    """Return the same colour as RGB 0-1 floats (ROS ``ColorRGBA``, Foxglove ``Color``)."""
    b, g, r = track_colour(track_id)
    return r / 255.0, g / 255.0, b / 255.0
