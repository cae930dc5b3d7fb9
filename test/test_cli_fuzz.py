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
Every CLI command on a corpus of bad files: no traceback, a non-zero exit, the file named.

The corpus (``fuzz_corpus.py``: 426 bad files in every format the commands read) is built
from the real Pose2Sim session. Commands run in-process through ``cli.main`` (the console
script's own entry point) so that 1000 runs take a minute; a sample also runs as real
processes. Also here: atomic outputs (a run that fails midway leaves no file).
"""

import contextlib
import io
import os
from pathlib import Path
import subprocess
import sys
import traceback

from fuzz_corpus import build, build_bases
from mv3dpose_ros import cli
import pytest


def run_cli(argv):
    """Return ``(exit code, stdout + stderr, traceback or None)`` of ``mv3dpose argv``."""
    out, err = io.StringIO(), io.StringIO()
    tb = None
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            rc = cli.main([str(a) for a in argv])
        except SystemExit as exc:     # argparse: the corpus never gives bad arguments
            rc = exc.code
            tb = f'SystemExit {exc.code}'
        except BaseException:  # noqa: B902 - anything escaping main is a traceback
            rc = None
            tb = traceback.format_exc()
    return rc, out.getvalue() + err.getvalue(), tb


@pytest.fixture(scope='module')
def corpus(shared_data, tmp_path_factory):
    """Build the bad-file corpus once."""
    root = tmp_path_factory.mktemp('fuzz')
    return root, build(root, shared_data)


def test_corpus_is_large_and_covers_every_format(corpus):
    _, cases = corpus
    kinds = {c.kind for c in cases}
    assert len(cases) >= 300
    assert kinds >= {'panoptic', 'voxelpose', 'pose2sim', 'rig', 'camera_info', 'openpose',
                     'image', 'track_params', 'tracks_jsonl', 'bag_mcap', 'bag_sqlite3',
                     'partial_bag'}
    commands = {' '.join(a[:2]) if a[0] in ('bag', 'convert') else a[0]
                for c in cases for a in c.argvs}
    assert commands == {'track', 'eval', 'render', 'convert openpose', 'convert tracks',
                        'convert images', 'bag info', 'bag play', 'bag recover'}


def test_every_command_on_every_bad_file_fails_cleanly_naming_the_file(corpus):
    """No run on a hostile file ends in a traceback (34 of 359 once did); each names it."""
    root, cases = corpus
    failures, runs = [], 0
    for case in cases:
        for argv in case.argvs:
            rc, text, tb = run_cli(argv)
            runs += 1
            if tb is not None:
                failures.append(f'{" ".join(argv[:2])} {case.path}: traceback\n{tb}')
            elif rc == 0:
                failures.append(f'{" ".join(argv[:2])} {case.path}: exit 0\n{text[-500:]}')
            elif case.path not in text:
                failures.append(f'{" ".join(argv[:2])} {case.path}: message does not name '
                                f'the file\n{text[-500:]}')
            output = argv[argv.index('-o') + 1] if '-o' in argv else None
            if rc != 3 and output and os.path.exists(output):
                failures.append(f'{" ".join(argv[:2])} {case.path}: failed (exit {rc}) but '
                                f'left an output {output}')
    print(f'{len(cases)} bad files, {runs} CLI runs, {len(failures)} failures')
    assert not failures, f'{len(failures)} of {runs} runs:\n' + '\n'.join(failures[:10])
    # no temp file was left behind (outputs of runs that failed never appeared: exit 3
    # runs finished and wrote a complete output without the skipped input)
    leftovers = [p for p in root.rglob('*.partial*') if 'partial-999999999' not in str(p)]
    assert not leftovers, leftovers


def test_a_sample_as_real_processes(corpus):
    """The console command itself: one line naming the file on stderr, no traceback."""
    _, cases = corpus
    seen = set()
    for case in cases:
        if case.kind in seen:
            continue
        seen.add(case.kind)
        argv = list(case.argvs[0])
        if '-o' in argv:                      # not where the in-process run wrote
            argv[argv.index('-o') + 1] += '.proc'
        proc = subprocess.run([sys.executable, '-m', 'mv3dpose_ros.cli'] + argv,
                              capture_output=True, text=True, timeout=120)
        assert proc.returncode not in (0, None), (argv, proc.stderr)
        assert 'Traceback' not in proc.stderr, proc.stderr
        assert case.path in proc.stdout + proc.stderr, (argv, proc.stderr)


def test_outputs_are_atomic_when_a_run_fails_midway(shared_data, tmp_path, monkeypatch):
    """A track run that fails midway leaves no partial file that would look valid."""
    from mv3dpose_ros.core.fusion.pipeline import Fusion
    bases = build_bases(tmp_path / 'base', shared_data)
    calls = {'n': 0}
    step = Fusion.step

    def failing_step(self, *args, **kwargs):
        calls['n'] += 1
        if calls['n'] == 2:
            raise KeyboardInterrupt    # as Ctrl-C or a crash in the middle of the run
        return step(self, *args, **kwargs)

    monkeypatch.setattr(Fusion, 'step', failing_step)
    out = tmp_path / 'tracks.jsonl'
    argv = ['track', '--calibration', bases['toml'], '--poses', bases['poses'], '--layout',
            'body25b', '--smooth', 'causal', '--no-progress', '-o', out]
    rc, _, tb = run_cli(argv)
    assert rc == 130 and tb is None               # the CLI reports the interruption
    assert calls['n'] == 2 and not out.exists()
    out.write_text('previous run\n')              # an older result stays untouched
    calls['n'] = 0
    run_cli(argv)
    assert out.read_text() == 'previous run\n'
    assert sorted(p.name for p in tmp_path.iterdir()) == ['base', 'tracks.jsonl']
    monkeypatch.setattr(Fusion, 'step', step)
    rc, _, _ = run_cli(argv)
    assert rc == 0 and out.read_text().count('\n') == 3
    # convert tracks (bag -> JSON Lines) and eval --json: no temp file stays behind either
    conv = tmp_path / 'conv.jsonl'
    assert run_cli(['convert', 'tracks', bases['mcap'], '-o', conv, '-q'])[0] == 0
    js = tmp_path / 'eval.json'
    assert run_cli(['eval', '--tracks', conv, '--gt', bases['tracks'], '--format', 'tracks',
                    '--json', js])[0] == 0
    assert js.exists() and not [p for p in os.listdir(tmp_path) if '.partial' in p]
    assert Path(conv).read_text().count('\n') == 3
