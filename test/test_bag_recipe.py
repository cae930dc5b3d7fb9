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
The README's "From a bag" recipe, run as typed on the real Panoptic frames.

``IMAGES`` and ``RIG`` are what the text tells a user to set: the five HD cameras of
``../shared/data/panoptic_demo`` (5 time points, 3 people) and their rig file. The block runs
in a scratch folder holding a link to ``env.sh``, as a user's shell in the checkout would, and
must leave a complete ``run.bag`` whose tracks hold the three people.
"""

import os
import subprocess

from mv3dpose_ros.core.types import TrackState
from mv3dpose_ros.ros.bag_convert import tracks_from_bag
import pytest
from test_live_rig import readme_block

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def test_readme_bag_recipe_names_what_the_text_says():
    script = readme_block('bag-recipe')
    assert '$IMAGES' in script and '$RIG' in script and 'run.bag' in script


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.timeout(600)
def test_readme_bag_recipe_as_typed_gives_the_three_people(shared_data, model, tmp_path):
    os.symlink(os.path.join(ROOT, 'env.sh'), tmp_path / 'env.sh')
    env = dict(os.environ, IMAGES=os.path.join(shared_data, 'panoptic_demo'),
               RIG=os.path.join(ROOT, 'config', 'rigs', 'panoptic_demo.yaml'))
    with open(tmp_path / 'recipe.log', 'w') as log:
        run = subprocess.run(['bash', '-c', 'set -m\n' + readme_block('bag-recipe')],
                             cwd=tmp_path, env=env, stdout=log, stderr=subprocess.STDOUT,
                             timeout=540)
    text = (tmp_path / 'recipe.log').read_text()
    assert run.returncode == 0, text[-4000:]
    # the recorder's own partial folder is no interrupted recording
    assert 'interrupted recording' not in text, text[-4000:]
    frames = list(tracks_from_bag(str(tmp_path / 'run.bag')))
    assert frames, text[-4000:]
    confirmed = [sum(t.state == TrackState.CONFIRMED for t in tracks) for _, _, tracks in frames]
    assert max(confirmed) == 3, (confirmed, text[-3000:])
