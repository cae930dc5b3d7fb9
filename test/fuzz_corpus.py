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
A deterministic corpus of bad input files for every format the CLI reads.

``build(root, data)`` writes valid base inputs made from the real Pose2Sim session in
``data`` (its calibration converted into every calibration format, 3 frames of its OpenPose
detections, black images of the calibrated size, the tracks ``mv3dpose track`` makes of
them, those tracks as MCAP and sqlite3 bags) and then, beside them, one bad variant per
case. Every variant is bad by construction (a value out of range or of the wrong type, broken
syntax, a hostile document, a corrupted or garbled bag), and each case lists the CLI
invocations that read it. Nothing is random
beyond a fixed seed, so a failure names a file that can be rebuilt.

Run as a script to write the corpus somewhere and look at it::

    python test/fuzz_corpus.py /tmp/corpus ../shared/data
"""

import itertools
import json
import os
from pathlib import Path
import random
import shutil
import sqlite3
import sys
from typing import Callable, Dict, List, NamedTuple

BIG_INT = '9' * 400
DEEP = '[' * 3000 + ']' * 3000
#: Raw JSON texts that are bad wherever a number is required.
BAD_NUMBERS = ['1e400', '-1e400', BIG_INT, DEEP, '"abc"', '{}', '[1, 2]']
#: Extra values that are bad for calibration numbers (range checks).
BAD_CALIBRATION = BAD_NUMBERS + ['1e300', 'null']
#: Whole-document replacements that are bad for every JSON reader.
BAD_DOCUMENTS = ['', 'null', '[]', '"text"', '{}', DEEP, '{"a": ' + BIG_INT + '}']
ALIAS_BOMB = 'a0: &a0 [x, x, x, x, x, x, x, x, x]\n' + ''.join(
    f'a{i}: &a{i} [' + ', '.join([f'*a{i - 1}'] * 9) + ']\n' for i in range(1, 10)) + \
    'cameras: *a9\n'
BAD_YAML_DOCUMENTS = [ALIAS_BOMB, 'cameras: ' + DEEP, 'cameras: [\n', 'cameras:\n\t- x\n',
                      'cameras: *nothing\n', "cameras: !!python/object/apply:os.system ['true']\n",
                      '\xff', 'cameras: ' + BIG_INT + '\n', 'cameras: {}\n', '- 1\n- 2\n']

SENTINEL = '"__FUZZ__"'
_OUTPUTS = itertools.count()


def _out(root: Path, suffix: str = '') -> str:
    """Return a fresh output path under ``root`` (every run writes somewhere new)."""
    return str(root / f'out_{next(_OUTPUTS)}{suffix}')


class Case(NamedTuple):
    """One bad file and the CLI invocations that read it."""

    kind: str            # format family, for the counts
    path: str            # the bad file (or bag folder) the messages must name
    argvs: List[List[str]]


def _dump_with(doc, path: List, raw: str) -> str:
    """Return ``json.dumps(doc)`` with the value at ``path`` replaced by the raw text."""
    doc = json.loads(json.dumps(doc))
    node = doc
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = '__FUZZ__'
    return json.dumps(doc).replace(SENTINEL, raw, 1)


# ------------------------------------------------------------------------------------ bases

def _calibration_docs(cameras) -> Dict[str, object]:
    """Write the cameras in every calibration format (as documents)."""
    import numpy as np
    from mv3dpose_ros.core.geometry.calibration import PANOPTIC_TO_WORLD, rig_yaml_dict
    panoptic = {'cameras': []}
    voxelpose = {}
    for name, cam in cameras.items():
        K = cam.K.tolist()
        panoptic['cameras'].append({
            'name': name, 'type': 'hd', 'resolution': [cam.width, cam.height], 'K': K,
            'distCoef': cam.dist.tolist(), 'R': (cam.R @ PANOPTIC_TO_WORLD).tolist(),
            't': [[v] for v in (cam.t * 100).tolist()]})
        voxelpose[name] = {
            'R': cam.R.tolist(), 'T': [[v] for v in (-cam.R.T @ cam.t * 1000).tolist()],
            'fx': K[0][0], 'fy': K[1][1], 'cx': K[0][2], 'cy': K[1][2],
            'k': [[cam.dist[0]], [cam.dist[1]], [cam.dist[4]]],
            'p': [[cam.dist[2]], [cam.dist[3]]], 'width': cam.width, 'height': cam.height}
    first = next(iter(cameras.values()))
    info = {'image_width': first.width, 'image_height': first.height,
            'camera_name': first.name, 'distortion_model': 'plumb_bob',
            'camera_matrix': {'rows': 3, 'cols': 3, 'data': first.K.ravel().tolist()},
            'distortion_coefficients': {'rows': 1, 'cols': 5, 'data': first.dist.tolist()},
            'rectification_matrix': {'rows': 3, 'cols': 3, 'data': np.eye(3).ravel().tolist()},
            'projection_matrix': {'rows': 3, 'cols': 4,
                                  'data': np.hstack([first.K, np.zeros((3, 1))]).ravel().tolist()}}
    return {'panoptic': panoptic, 'voxelpose': voxelpose, 'rig': rig_yaml_dict(cameras),
            'camera_info': info}


def build_bases(base: Path, data: str) -> Dict[str, Path]:
    """Write the valid inputs every bad variant is derived from; return their paths."""
    import yaml
    from mv3dpose_ros import cli
    from mv3dpose_ros.core.geometry.calibration import load_calibration
    src = Path(data) / 'pose2sim_multiperson'
    base.mkdir(parents=True)
    out = {'toml': base / 'calib.toml', 'poses': base / 'poses'}
    shutil.copy(src / 'Calib_qualisys.toml', out['toml'])
    for cam in sorted((src / 'pose').iterdir()):
        (out['poses'] / cam.name).mkdir(parents=True)
        for f in sorted(cam.glob('*.json'))[:3]:
            shutil.copy(f, out['poses'] / cam.name / f.name)
    cameras = load_calibration(str(out['toml']))
    docs = _calibration_docs(cameras)
    out['panoptic'] = base / 'calib_panoptic.json'
    out['panoptic'].write_text(json.dumps(docs['panoptic']))
    out['voxelpose'] = base / 'calib_voxelpose.json'
    out['voxelpose'].write_text(json.dumps(docs['voxelpose']))
    out['rig'] = base / 'rig.yaml'
    out['rig'].write_text(yaml.safe_dump(docs['rig'], sort_keys=False))
    out['camera_info'] = base / 'cam_info.yaml'
    out['camera_info'].write_text(yaml.safe_dump(docs['camera_info'], sort_keys=False))
    out['tracks'] = base / 'tracks.jsonl'
    common = ['--poses', str(out['poses']), '--layout', 'body25b', '--fps', '60',
              '--smooth', 'none', '--no-progress']
    rc = cli.main(['track', '--calibration', str(out['toml']), '-o', str(out['tracks'])]
                  + common)
    assert rc == 0, f'base tracks: mv3dpose track exited {rc}'
    for storage in ('mcap', 'sqlite3'):
        out[storage] = base / f'tracks_{storage}'
        rc = cli.main(['convert', 'tracks', str(out['tracks']), '-o', str(out[storage]),
                       '--storage', storage, '-q'])
        assert rc == 0, f'base {storage} bag: mv3dpose convert exited {rc}'
    out['openpose_file'] = sorted((out['poses'] / 'cam01_json').glob('*.json'))[1]
    out['images'] = base / 'images'            # black frames of the calibrated size
    import cv2
    import numpy as np
    for name, cam in cameras.items():
        (out['images'] / name).mkdir(parents=True)
        for k in range(2):
            cv2.imwrite(str(out['images'] / name / f'{name}_{k:04d}.png'),
                        np.zeros((cam.height, cam.width, 3), np.uint8))
    return out


# ------------------------------------------------------------------------------------ cases

def _track_argv(calibration, poses, tmp: Path) -> List[str]:
    return ['track', '--calibration', str(calibration), '--poses', str(poses),
            '--layout', 'body25b', '--fps', '60', '--smooth', 'none', '--no-progress',
            '-o', _out(tmp, '.jsonl')]


def _convert_openpose_argv(calibration, poses, tmp: Path) -> List[str]:
    return ['convert', 'openpose', str(poses), '-c', str(calibration), '--layout', 'body25b',
            '-o', _out(tmp), '-q']


def _convert_images_argv(calibration, images, tmp: Path) -> List[str]:
    return ['convert', 'images', str(images), '-c', str(calibration), '-o', _out(tmp), '-q']


def _calibration_cases(bases, root: Path) -> List[Case]:
    """Bad calibration files of every format, read by ``track`` and ``convert``."""
    import yaml
    docs = _calibration_docs(__import__('mv3dpose_ros.core.geometry.calibration', fromlist=['x'])
                             .load_calibration(str(bases['toml'])))
    texts: List[tuple] = []        # (kind, file name, text)
    pan, vox = docs['panoptic'], docs['voxelpose']
    for path in (['cameras', 0, 'K', 0, 0], ['cameras', 1, 'distCoef', 0],
                 ['cameras', 0, 'R', 1, 2], ['cameras', 1, 't', 0, 0],
                 ['cameras', 0, 'resolution', 0]):
        for i, raw in enumerate(BAD_CALIBRATION):
            texts.append(('panoptic', f'pan_{"_".join(map(str, path))}_{i}.json',
                          _dump_with(pan, path, raw)))
    names = list(vox)
    for path in ([names[0], 'fx'], [names[1], 'R', 0, 0], [names[0], 'T', 2, 0],
                 [names[1], 'k', 0, 0], [names[0], 'width']):
        for i, raw in enumerate(BAD_CALIBRATION):
            texts.append(('voxelpose', f'vox_{"_".join(map(str, path))}_{i}.json',
                          _dump_with(vox, path, raw)))
    for i, raw in enumerate(BAD_DOCUMENTS):
        texts.append(('panoptic', f'pan_doc_{i}.json', raw))
    full = json.dumps(pan)
    for frac in (0.2, 0.5, 0.9):
        texts.append(('panoptic', f'pan_cut_{int(frac * 100)}.json', full[:int(len(full) * frac)]))
    toml = bases['toml'].read_text()
    for key in ('size', 'matrix', 'distortions', 'rotation', 'translation'):
        line = next(li for li in toml.splitlines() if li.startswith(f'{key} ='))
        for i, raw in enumerate(['1e400', BIG_INT, '"abc"', DEEP, 'inf', 'nan', '1e300',
                                 '[ 1, 2 ]']):
            texts.append(('pose2sim', f'p2s_{key}_{i}.toml',
                          toml.replace(line, f'{key} = {raw}', 1)))
        texts.append(('pose2sim', f'p2s_{key}_cut.toml', toml[:toml.index(line) + len(key) + 5]))
    texts.append(('pose2sim', 'p2s_fisheye.toml', toml.replace('fisheye = false',
                                                               'fisheye = true', 1)))
    texts.append(('pose2sim', 'p2s_binary.toml', '\x00\x01garbage = [[[['))
    rig = docs['rig']
    cam0 = next(iter(rig['cameras']))
    for i, text in enumerate(BAD_YAML_DOCUMENTS):
        texts.append(('rig', f'rig_doc_{i}.yaml', text))
    edits = {'image_width': ['abc', '.inf', '-5', '0', BIG_INT, '1.5', '[1]'],
             'K': ['[1, 2]', '[.nan, 1, 2, 3]', '[1.0e30, 500, 300, 200]', '[a, b, c, d]',
                   DEEP],
             'distortion': ['[1.0e300, 0, 0, 0, 0]', '[abc]', '[1, 2, 3]'],
             'distortion_model': ['fisheye'],
             'T_world_cam': ['{rotation: [0, 0, 0, 0], translation: [0, 0, 0]}',
                             '{rotation: [0, 0, 0, 1], translation: [.nan, 0, 0]}',
                             '{rotation: [0, 0, 0, 1], translation: [1.0e300, 0, 0]}',
                             '{rotation: [1, 2, 3], translation: [0, 0, 0]}', 'null']}
    for key, values in edits.items():
        for i, raw in enumerate(values):
            doc = json.loads(json.dumps(rig))
            doc['cameras'][cam0][key] = '__FUZZ__'
            text = yaml.safe_dump(doc, sort_keys=False, width=10 ** 6)
            texts.append(('rig', f'rig_{key}_{i}.yaml', text.replace('__FUZZ__', raw, 1)))
    cases = []
    for kind, name, text in texts:
        path = root / name
        path.write_text(text, encoding='utf-8', errors='surrogateescape')
        cases.append(Case(kind, str(path), [
            _track_argv(path, bases['poses'], root),
            _convert_openpose_argv(path, bases['poses'], root),
            _convert_images_argv(path, bases['images'], root)]))
    # camera_info files, used through a rig's intrinsics_file
    info = docs['camera_info']
    info_edits = {'image_width': ['abc', BIG_INT, '-1'],
                  'camera_matrix': ['{data: [1, 2, 3]}', '{data: abc}',
                                    '{data: [1.0e30, 0, 0, 0, 1, 0, 0, 0, 1]}'],
                  'distortion_coefficients': ['{data: [1.0e300, 0, 0, 0, 0]}',
                                              '{data: [1, 2, 3, 4, 5, 6, 7, 8, 9]}'],
                  'distortion_model': ['equidistant']}
    rig_doc = json.loads(json.dumps(rig))
    entry = rig_doc['cameras'][cam0]
    for key in ('K', 'distortion', 'image_width', 'image_height'):
        entry.pop(key, None)
    k = 0
    variants = [(key, raw) for key, values in info_edits.items() for raw in values]
    variants += [(None, ALIAS_BOMB), (None, '\tbroken: [')]
    for key, raw in variants:
        if key is None:
            text = raw
        else:
            doc = json.loads(json.dumps(info))
            doc[key] = '__FUZZ__'
            text = yaml.safe_dump(doc, sort_keys=False, width=10 ** 6).replace(
                '__FUZZ__', raw, 1)
        info_path = root / f'caminfo_{k}.yaml'
        info_path.write_text(text)
        entry['intrinsics_file'] = info_path.name
        rig_path = root / f'rig_with_caminfo_{k}.yaml'
        rig_path.write_text(yaml.safe_dump(rig_doc, sort_keys=False))
        cases.append(Case('camera_info', str(info_path), [
            _track_argv(rig_path, bases['poses'], root),
            _convert_openpose_argv(rig_path, bases['poses'], root)]))
        k += 1
    return cases


def _openpose_cases(bases, root: Path) -> List[Case]:
    """Bad OpenPose files among valid ones, read by ``track`` and ``convert openpose``."""
    good = bases['openpose_file']
    doc = json.loads(good.read_text())
    texts = []
    for path in (['people', 1, 'pose_keypoints_2d', 0], ['people', 1, 'pose_keypoints_2d', 5],
                 ['people', 2, 'pose_keypoints_2d', 31], ['people', 1, 'pose_keypoints_2d'],
                 ['people', 2]):
        for raw in BAD_NUMBERS + ['1e300', 'true']:
            texts.append(_dump_with(doc, path, raw))
    texts += BAD_DOCUMENTS
    full = good.read_text()
    texts += [full[:int(len(full) * f)] for f in (0.1, 0.5, 0.95)]
    texts += ['\udcff\udcfe not utf-8', '{"people": [{"pose_keypoints_2d": [1, 2, 3]}]}']
    cases = []
    for i, text in enumerate(texts):
        poses = root / f'poses_{i}'
        shutil.copytree(bases['poses'], poses)
        bad = poses / good.parent.name / good.name
        bad.write_text(text, encoding='utf-8', errors='surrogateescape')
        cases.append(Case('openpose', str(bad), [
            _track_argv(bases['toml'], poses, root),
            _convert_openpose_argv(bases['toml'], poses, root)]))
    return cases


def _image_cases(bases, root: Path) -> List[Case]:
    """Unreadable or mis-sized images among valid ones, read by ``convert images``."""
    import cv2
    import numpy as np
    good = sorted((bases['images'] / 'cam_02').glob('*.png'))[1]
    png = good.read_bytes()
    small = cv2.imencode('.png', np.zeros((10, 10, 3), np.uint8))[1].tobytes()
    deep = cv2.imencode('.png', np.zeros((1920, 1088), np.uint16))[1].tobytes()
    variants = [b'', b'not an image', png[:len(png) // 2], png[:40], small, deep,
                b'\x89PNG\r\n\x1a\n' + bytes(200)]
    cases = []
    for i, raw in enumerate(variants):
        images = root / f'images_{i}'
        shutil.copytree(bases['images'], images)
        bad = images / good.parent.name / good.name
        bad.write_bytes(raw)
        cases.append(Case('image', str(bad),
                          [_convert_images_argv(bases['toml'], images, root)]))
    return cases


def _params_cases(bases, root: Path) -> List[Case]:
    """Bad ``--params`` files of ``mv3dpose track``."""
    texts = [ALIAS_BOMB, 'fusion: ' + DEEP, 'theta_norm: abc\n', 'no_such_field: 1\n',
             'min_views: 1\n', 'max_coast_s: .nan\n', '1: 2\n', 'theta_norm: ' + BIG_INT,
             '[1, 2]\n', '\tbroken: [\n']
    cases = []
    for i, text in enumerate(texts):
        path = root / f'params_{i}.yaml'
        path.write_text(text)
        argv = _track_argv(bases['toml'], bases['poses'], root) + ['--params', str(path)]
        cases.append(Case('track_params', str(path), [argv]))
    return cases


def _tracks_cases(bases, root: Path) -> List[Case]:
    """Tracks JSON Lines with one bad line, read by ``convert``, ``render`` and ``eval``."""
    lines = bases['tracks'].read_text().splitlines()
    k = next(i for i, li in enumerate(lines) if json.loads(li)['tracks'])
    doc = json.loads(lines[k])
    joints = doc['tracks'][0]['joints']
    j = next(i for i, p in enumerate(joints) if p is not None)
    texts = []
    paths = [['frame'], ['stamp'], ['tracks', 0, 'id'], ['tracks', 0, 'joints', j, 1],
             ['tracks', 0, 'confidence', j], ['tracks', 0, 'joint_state', j],
             ['tracks', 0, 'num_views', j], ['tracks', 0, 'position', 0], ['tracks', 0, 'score'],
             ['tracks', 0, 'state'], ['tracks', 0, 'joints', j], ['tracks']]
    for path in paths:
        for raw in ('1e400', BIG_INT, '"abc"', DEEP, '{}', 'true'):
            if path == ['tracks', 0, 'state'] and raw == '"abc"':
                raw = '"lost"'
            texts.append(_dump_with(doc, path, raw))
    texts += ['', 'null', '[]', '{"frame": 1}', lines[k][:len(lines[k]) // 2], '\udcff\udcfe',
              '{"frame": 1, "units": "furlong", "tracks": []}']
    cases = []
    for i, text in enumerate(texts):
        bad = root / f'tracks_{i}.jsonl'
        body = lines[:k] + [text] + lines[k + 1:]
        if text == '':
            body = ['', ' ', '\t']          # a file without any line of tracks
        bad.write_text('\n'.join(body) + '\n', encoding='utf-8', errors='surrogateescape')
        cases.append(Case('tracks_jsonl', str(bad), [
            ['convert', 'tracks', str(bad), '-o', _out(root), '-q'],
            ['render', str(bad), '-o', _out(root, '.png'), '-q'],
            ['eval', '--tracks', str(bad), '--gt', str(bases['tracks']), '--format', 'tracks',
             '--states', 'tentative,confirmed,coasting']]))
    return cases


def _bag_argvs(bag: Path, root: Path) -> List[List[str]]:
    return [['bag', 'info', str(bag)],
            ['bag', 'play', str(bag), '--rate', '0', '-q'],
            ['convert', 'tracks', str(bag), '-o', _out(root, '.jsonl'), '-q'],
            ['render', str(bag), '-o', _out(root, '.png'), '-q']]


def mcap_chunks(raw: bytes) -> List[tuple]:
    """Return ``(offset, length)`` of every chunk record of MCAP bytes."""
    pos, out = 8, []
    while pos + 9 <= len(raw) and raw[pos] != 0x0F:
        length = int.from_bytes(raw[pos + 1:pos + 9], 'little')
        if raw[pos] == 0x06:
            out.append((pos, length))
        pos += 9 + length
    return out


def _bag_cases(bases, root: Path) -> List[Case]:
    """Corrupted, truncated and garbled MCAP and sqlite3 bags, and broken metadata."""
    rng = random.Random(11)
    cases = []

    def variant(storage: str, name: str, edit: Callable[[Path], None]) -> None:
        bag = root / f'{storage}_{name}'
        shutil.copytree(bases[storage], bag)
        edit(next(p for p in bag.iterdir() if p.suffix in ('.mcap', '.db3')))
        cases.append(Case(f'bag_{storage}', str(bag), _bag_argvs(bag, root)))

    # MCAP: flipped bits inside chunk payloads, truncations, garbage
    mcap = next(bases['mcap'].glob('*.mcap')).read_bytes()
    chunks = mcap_chunks(mcap)
    for i in range(30):
        offset, length = chunks[rng.randrange(len(chunks))]
        pos = offset + 9 + 60 + rng.randrange(length - 60)
        bit = 1 << rng.randrange(8)

        def flip(f, pos=pos, bit=bit):
            raw = bytearray(f.read_bytes())
            raw[pos] ^= bit
            f.write_bytes(bytes(raw))
        variant('mcap', f'flip_{i}', flip)
    for frac in (0.0, 0.1, 0.5, 0.9, 0.999):
        variant('mcap', f'cut_{frac}', lambda f, frac=frac: f.write_bytes(
            f.read_bytes()[:int(f.stat().st_size * frac)]))
    variant('mcap', 'garbage', lambda f: f.write_bytes(b'\x89MCAP0\r\n' + bytes(range(256)) * 9))
    variant('mcap', 'summary', lambda f: f.write_bytes(
        f.read_bytes()[:-80] + bytes([f.read_bytes()[-80] ^ 0x40]) + f.read_bytes()[-79:]))
    # sqlite3: garbled rows, changed payloads, truncation
    garble = [
        'UPDATE messages SET data = randomblob(40) WHERE id = 2',
        "UPDATE messages SET data = 'abc' WHERE id = 3",
        'UPDATE messages SET data = zeroblob(0) WHERE id = 1',
        "UPDATE messages SET timestamp = 'abc' WHERE id = 1",
        'UPDATE messages SET timestamp = timestamp + 1 WHERE id = 2',
        'UPDATE messages SET topic_id = 99 WHERE id = 3',
        'DELETE FROM messages WHERE id = 2',
        'INSERT INTO messages (topic_id, timestamp, data) SELECT topic_id, timestamp, data '
        'FROM messages WHERE id = 1',
        "UPDATE topics SET type = 'no_pkg/msg/Nothing'",
        "UPDATE topics SET offered_qos_profiles = '- {depth: [[[['",
        'DROP TABLE messages',
        'UPDATE messages SET data = substr(data, 1, 20) WHERE id = 3',
    ]
    for i, sql in enumerate(garble):
        def run_sql(f, sql=sql):
            with sqlite3.connect(f) as conn:
                conn.execute(sql)
            conn.close()
        variant('sqlite3', f'garbled_{i}', run_sql)
    for i in range(10):
        def flip_blob(f, i=i):
            with sqlite3.connect(f) as conn:
                (n,) = conn.execute('SELECT COUNT(*) FROM messages').fetchone()
                rowid, blob = conn.execute(
                    'SELECT id, data FROM messages ORDER BY id LIMIT 1 OFFSET ?',
                    (i % n,)).fetchone()
                blob = bytearray(blob)
                blob[(i * 37) % len(blob)] ^= 0x08
                conn.execute('UPDATE messages SET data = ? WHERE id = ?', (bytes(blob), rowid))
            conn.close()
        variant('sqlite3', f'blob_{i}', flip_blob)
    for frac in (0.0, 0.3, 0.7):
        variant('sqlite3', f'cut_{frac}', lambda f, frac=frac: f.write_bytes(
            f.read_bytes()[:int(f.stat().st_size * frac)]))
    variant('sqlite3', 'garbage', lambda f: f.write_bytes(b'SQLite format 3\x00' + bytes(900)))
    # metadata.yaml, for both storages
    for storage in ('mcap', 'sqlite3'):
        for i, text in enumerate(['', ALIAS_BOMB, 'rosbag2_bagfile_information: ' + DEEP,
                                  'rosbag2_bagfile_information: {relative_file_paths: [../x]}',
                                  '\tbroken: [', '{}', 'rosbag2_bagfile_information: 5']):
            def meta(f, text=text):
                (f.parent / 'metadata.yaml').write_text(text)
            variant(storage, f'meta_{i}', meta)
        variant(storage, 'no_meta', lambda f: (f.parent / 'metadata.yaml').unlink())
        variant(storage, 'no_storage', lambda f: f.unlink())
    # interrupted recordings that hold nothing salvageable
    for i, content in enumerate([b'', b'not an mcap file', b'\x89MCAP0\r\n\x06' + bytes(20)]):
        partial = root / f'.rec{i}.partial-999999999' / f'rec{i}'
        partial.mkdir(parents=True)
        (partial / f'rec{i}.mcap').write_bytes(content)
        cases.append(Case('partial_bag', str(partial.parent),
                          [['bag', 'recover', str(partial.parent), '-o',
                            _out(root)]]))
    return cases


def build(root: Path, data: str) -> List[Case]:
    """Write the base inputs and every bad variant under ``root``; return the cases."""
    root = Path(root)
    bases = build_bases(root / 'base', data)
    groups = {'calibration': _calibration_cases, 'openpose': _openpose_cases,
              'images': _image_cases, 'params': _params_cases, 'tracks': _tracks_cases,
              'bags': _bag_cases}
    cases: List[Case] = []
    for name, make in groups.items():
        folder = root / name
        folder.mkdir()
        cases += make(bases, folder)
    return cases


if __name__ == '__main__':
    if len(sys.argv) != 3:
        sys.exit('usage: python test/fuzz_corpus.py OUTPUT_DIR SHARED_DATA_DIR')
    if os.path.exists(sys.argv[1]):
        sys.exit(f'{sys.argv[1]} exists')
    made = build(Path(sys.argv[1]), sys.argv[2])
    kinds: Dict[str, int] = {}
    for c in made:
        kinds[c.kind] = kinds.get(c.kind, 0) + 1
    print(f'{len(made)} bad files, {sum(len(c.argvs) for c in made)} CLI runs: {kinds}')
