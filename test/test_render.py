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

"""Pictures of tracks: top and side views, reprojection onto images, animations."""

import os
import subprocess
import sys

import cv2
from mv3dpose_ros.commands.render import render_tracks
from mv3dpose_ros.core.geometry.calibration import save_rig_yaml
from mv3dpose_ros.core.types import JointState, Track, TrackState
from mv3dpose_ros.io.tracks_jsonl import TracksWriter
from mv3dpose_ros.ros.bag_convert import jsonl_to_bag
from mv3dpose_ros.sim.scene import make_scene
from mv3dpose_ros.viz.palette import PALETTE, track_colour
from mv3dpose_ros.viz.pictures import RenderError
import numpy as np
import pytest

FRAMES = 8
IDS = (3, 7)   # two ids with different palette colours


@pytest.fixture(scope='module')
def scene():
    return make_scene(num_cameras=3, num_people=2, num_frames=FRAMES, seed=3)


def _gt_track(tid, joints, stamp):
    n = len(joints)
    return Track(track_id=tid, state=TrackState.CONFIRMED, joints=joints.copy(),
                 confidence=np.ones(n), joint_state=np.full(n, JointState.TRIANGULATED, np.uint8),
                 num_views=np.full(n, 3, np.uint8), reprojection_error=np.zeros(n),
                 position=np.full(3, np.nan), velocity=np.full(3, np.nan), first_seen=stamp,
                 last_observed=stamp)


@pytest.fixture(scope='module')
def files(scene, tmp_path_factory):
    """Ground-truth tracks as JSON Lines, the rig as YAML, and plain per-camera images."""
    root = tmp_path_factory.mktemp('render')
    tracks = root / 'tracks.jsonl'
    with TracksWriter(str(tracks), scene.layout) as w:
        for t in range(FRAMES):
            stamp = float(scene.stamps[t])
            w.write(t, [_gt_track(IDS[m], scene.gt[t, m], stamp) for m in range(2)], stamp)
    rig = root / 'rig.yaml'
    save_rig_yaml(scene.cameras, str(rig))
    images = root / 'images'
    for name, cam in scene.cameras.items():
        (images / name).mkdir(parents=True)
        for t in range(FRAMES):
            img = np.full((cam.height, cam.width, 3), 90, np.uint8)
            cv2.imwrite(str(images / name / f'{name}_{t:04d}.png'), img)
    return {'root': root, 'tracks': str(tracks), 'rig': str(rig), 'images': str(images)}


def _colour_mask(img, colour, tol=40):
    return np.all(np.abs(img.astype(int) - np.array(colour)) <= tol, axis=-1)


def test_png_shows_both_tracks_in_both_views(files):
    out = str(files['root'] / 'plain.png')
    result = render_tracks(files['tracks'], out, quiet=True)
    img = cv2.imread(out)
    assert img is not None and img.shape[0] > 400 and img.shape[1] > 800
    assert result['png_index'] == FRAMES - 1
    views = img[40:]                     # below the header bar
    half = views.shape[1] // 2
    for tid in IDS:
        colour = track_colour(tid)
        top, side = _colour_mask(views[:, :half], colour), _colour_mask(views[:, half:], colour)
        assert top.sum() > 50, f'track {tid} missing from the top view'
        assert side.sum() > 50, f'track {tid} missing from the side view'
        # a standing person is taller than wide in the side view
        ys, xs = np.nonzero(side)
        assert np.ptp(ys) > 1.5 * np.ptp(xs) or np.ptp(ys) > 100
    assert track_colour(IDS[0]) != track_colour(IDS[1])
    assert len(set(PALETTE)) == len(PALETTE)


def test_reprojection_onto_images_lands_on_the_people(files, scene):
    out = str(files['root'] / 'images.png')
    render_tracks(files['tracks'], out, calibration=files['rig'], images=files['images'],
                  frame=2, quiet=True)
    img = cv2.imread(out)
    plain = cv2.imread(str(files['root'] / 'plain.png'))
    assert img.shape[0] > plain.shape[0] + 150, 'no camera tiles below the 3D views'
    tiles = img[plain.shape[0]:]
    # camera tiles are grey (90) except where skeletons were drawn in the track colours
    for tid in IDS:
        assert _colour_mask(tiles, track_colour(tid)).sum() > 100, f'track {tid} not drawn'
    # the first tile shows cam 0: the drawn skeleton sits where the GT projects
    cam = scene.cameras[next(iter(scene.cameras))]
    tile_w = plain.shape[1] // 2
    scale = tile_w / cam.width
    uv = cam.project(scene.gt[2, 0]) * scale
    mask = _colour_mask(tiles[:int(cam.height * scale), :tile_w], track_colour(IDS[0]))
    ys, xs = np.nonzero(mask)
    assert len(xs) > 20
    centre = np.array([np.median(xs), np.median(ys)])
    assert np.linalg.norm(centre - np.nanmean(uv, axis=0)) < 0.1 * tile_w


def test_bag_input_gives_the_same_picture(files):
    bag = str(files['root'] / 'tracks_bag')
    jsonl_to_bag(files['tracks'], bag)
    a, b = str(files['root'] / 'from_jsonl.png'), str(files['root'] / 'from_bag.png')
    render_tracks(files['tracks'], a, frame=4, quiet=True)
    render_tracks(bag, b, frame=4, quiet=True)
    assert np.array_equal(cv2.imread(a), cv2.imread(b))


def test_gif_and_video_have_every_frame(files):
    gif = str(files['root'] / 'seq.gif')
    mp4 = str(files['root'] / 'seq.mp4')
    result = render_tracks(files['tracks'], gif=gif, video=mp4, quiet=True)
    assert result['animated_frames'] == FRAMES
    ok, anim = cv2.imreadanimation(gif)
    assert ok and len(anim.frames) == FRAMES
    assert not np.array_equal(anim.frames[0], anim.frames[-1]), 'people did not move'
    cap = cv2.VideoCapture(mp4)
    assert int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) == FRAMES
    cap.release()
    leftovers = [f for f in os.listdir(files['root']) if '.partial' in f]
    assert leftovers == []


def test_errors_name_the_input(files, tmp_path):
    with pytest.raises(RenderError, match='missing.jsonl'):
        render_tracks(str(tmp_path / 'missing.jsonl'), str(tmp_path / 'x.png'))
    with pytest.raises(RenderError, match='calibration'):
        render_tracks(files['tracks'], str(tmp_path / 'x.png'), images=files['images'])
    bad = tmp_path / 'bad.jsonl'
    bad.write_text('not json\n')
    with pytest.raises(RenderError, match='bad.jsonl'):
        render_tracks(str(bad), str(tmp_path / 'x.png'))
    assert os.listdir(tmp_path) == ['bad.jsonl']


def test_cli_writes_png(files):
    out = files['root'] / 'cli.png'
    proc = subprocess.run([sys.executable, '-m', 'mv3dpose_ros.cli', 'render', files['tracks'],
                           '-o', str(out), '-c', files['rig'], '-q'],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert 'wrote' in proc.stdout and out.exists()
