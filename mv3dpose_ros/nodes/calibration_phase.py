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
calibration_phase: ``mv3dpose_bringup --calibrate``, from intrinsics alone to tracking.

The pose2d nodes start alone (the rig's extrinsics are not needed for 2D poses); once each has
said it publishes, ``mv3dpose bag record`` records their ``persons_2d`` (and the cameras'
``camera_info``) for ``--calibrate-s`` seconds, then ``mv3dpose calibrate --bag`` estimates the
extrinsics into ``--save-rig``. Both are child processes, as the nodes are (nodes and commands
do not import each other), their lines forwarded with a prefix. A calibration that fails for
lack of data (exit 2, or 3: cameras left out) says why in one line and records again, up to
``--calibrate-attempts`` times. Then bringup starts fusion_node on the new rig (its calibration
watch writes its corrections to the same file) and supervises everything as usual.
"""

import os
import shutil
import signal
import subprocess
import tempfile
import threading
import time
from typing import Any, Callable, Dict, List, Optional, Sequence

from mv3dpose_ros.ros.names import camera_topic

#: how long the pose2d nodes may take to load their models and say they publish
READY_TIMEOUT_S = 180.0
#: the longest a calibration may take before it counts as failed
CALIBRATE_TIMEOUT_S = 900.0
#: seconds between progress lines while recording
PROGRESS_EVERY_S = 5.0
#: what a pose2d node logs once it is active (``nodes/pose2d/node.py``)
READY_MARK = 'persons_2d ['


def end(proc: subprocess.Popen, timeout: float = 20.0) -> int:
    """Stop ``proc``'s session: SIGINT, then SIGKILL after ``timeout`` s; return its status."""
    for sig, wait in ((signal.SIGINT, timeout), (signal.SIGKILL, 5.0)):
        if proc.poll() is not None:
            break
        try:
            os.killpg(proc.pid, sig)
        except ProcessLookupError:
            break
        try:
            proc.wait(wait)
        except subprocess.TimeoutExpired:
            pass
    return proc.wait(5.0)


def recorded_topics(cameras: Sequence[str], namespace: str, image_topic: str) -> List[str]:
    """Return the topics to record: each camera's ``persons_2d`` and ``camera_info``."""
    persons = namespace.rstrip('/') + '/persons_2d'
    info = image_topic.rsplit('/', 1)[0] + '/camera_info'
    return [camera_topic(t, cam) for cam in cameras for t in (persons, info)]


class CalibrationPhase:
    """Record the pose2d nodes' output, calibrate from it, retry while data is missing."""

    def __init__(self, sup: Any, pose2d: Sequence[str], mv3dpose: List[str],
                 topics: Sequence[str], intrinsics: str, rig: str, seconds: float,
                 attempts: int, env: Optional[Dict[str, str]] = None) -> None:
        self.sup, self.pose2d, self.mv3dpose = sup, list(pose2d), list(mv3dpose)
        self.topics, self.intrinsics, self.rig = list(topics), intrinsics, rig
        self.seconds, self.attempts, self.env = float(seconds), int(attempts), env
        self.reason = ''
        self.started = time.monotonic()

    # ------------------------------------------------------------------ child processes

    def _child(self, argv: List[str], prefix: str) -> subprocess.Popen:
        """Start a command child in its own session; forward its lines with ``prefix``."""
        proc = subprocess.Popen(argv, start_new_session=True, env=self.env, text=True,
                                stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                errors='replace', bufsize=1)
        proc.lines = []                      # type: ignore[attr-defined]

        def forward() -> None:
            for line in iter(proc.stdout.readline, ''):
                proc.lines.append(line.rstrip())            # type: ignore[attr-defined]
                self.sup.say(f'{prefix}: {line.rstrip()}')
            proc.stdout.close()
        proc.reader = threading.Thread(target=forward, daemon=True)   # type: ignore
        proc.reader.start()                                           # type: ignore
        return proc

    def _end(self, proc: subprocess.Popen, timeout: float = 20.0) -> int:
        """Stop a command child; return its exit status once its output is forwarded."""
        code = end(proc, timeout)
        proc.reader.join(timeout=2.0)                                 # type: ignore
        return code

    def _trouble(self) -> bool:
        """Return True (and set ``reason``) on a stop request or a dead pose2d node."""
        if self.sup.stopping:
            self.reason = self.reason or 'stopped during the calibration phase'
            return True
        for name in self.pose2d:
            code = self.sup.procs[name].poll()
            if code is not None:
                self.reason = self.sup._exit_text(name, code)
                self.sup.failed = True
                return True
        return False

    # ------------------------------------------------------------------ steps

    def wait_ready(self) -> bool:
        """Wait (bounded) until every pose2d node says it publishes; False on trouble."""
        deadline = time.monotonic() + READY_TIMEOUT_S
        waiting = list(self.pose2d)
        while time.monotonic() < deadline:
            if self._trouble():
                return False
            waiting = [n for n in waiting   # seen once is enough: the tails are short
                       if not any(READY_MARK in ln for ln in list(self.sup.tails[n]))]
            if not waiting:
                return True
            time.sleep(0.2)
        self.sup.say(f'calibration: {", ".join(waiting)} did not say they publish within '
                     f'{READY_TIMEOUT_S:g} s; recording anyway')
        return True

    def record(self, bag: str, attempt: int) -> bool:
        """Record ``self.seconds`` of the topics into ``bag``; False on trouble."""
        proc = self._child(self.mv3dpose + ['bag', 'record', *self.topics, '-o', bag, '-q'],
                           'bag record')
        start = time.monotonic()
        said = start
        ok = True
        while True:
            now = time.monotonic()
            if now - start >= self.seconds or proc.poll() is not None:
                break
            if self._trouble():
                ok = False
                break
            if now - said >= PROGRESS_EVERY_S:
                said = now
                self.sup.say(f'calibration: recorded {now - start:.0f} of {self.seconds:g} s '
                             f'(attempt {attempt} of {self.attempts}); people should walk '
                             'through everything the cameras see')
            time.sleep(0.2)
        code = self._end(proc)
        if ok and code not in (0, -signal.SIGINT, 130):
            self.reason = f'bag record failed (exit status {code})'
            self.sup.failed = True
            return False
        return ok

    def calibrate(self, bag: str) -> int:
        """Run ``mv3dpose calibrate`` on ``bag``; return its exit status (-1 on trouble)."""
        proc = self._child(self.mv3dpose + ['calibrate', '--bag', bag, '--calibration',
                                            self.intrinsics, '-o', self.rig], 'calibrate')
        deadline = time.monotonic() + CALIBRATE_TIMEOUT_S
        while proc.poll() is None:
            if self._trouble() or time.monotonic() > deadline:
                self.reason = self.reason or (f'calibrate took over {CALIBRATE_TIMEOUT_S:g} s')
                self._end(proc)
                return -1
            time.sleep(0.2)
        proc.reader.join(timeout=2.0)                                 # type: ignore
        code = proc.returncode
        lines = [ln for ln in proc.lines if ln.strip()]               # type: ignore
        if code == 3 and 'not placed:' in lines:      # the report's list: '  NAME: why'
            self.reason = 'not placed: ' + '; '.join(
                ln.strip() for ln in lines[lines.index('not placed:') + 1:]
                if ln.startswith('  '))
        elif code not in (0, 1):
            last = lines[-1] if lines else 'no output'
            self.reason = last.split(': ', 1)[-1] if last.startswith('mv3dpose') else last
        elif code == 1:
            self.reason = f'calibrate could not write {self.rig}'
        return code

    def run(self) -> bool:
        """Calibrate the rig into ``self.rig``; False (``reason`` says why) if it could not."""
        if not self.wait_ready():
            return False
        folder = tempfile.mkdtemp(prefix='mv3dpose_calibrate_')
        try:
            for attempt in range(1, self.attempts + 1):
                bag = os.path.join(folder, f'walk_{attempt}')
                self.sup.say(f'calibration: recording {len(self.topics)} topics for '
                             f'{self.seconds:g} s into {bag} (attempt {attempt} of '
                             f'{self.attempts}, {time.monotonic() - self.started:.0f} s since '
                             'the nodes started)')
                if not self.record(bag, attempt):
                    return False
                self.sup.say(f'calibration: estimating the extrinsics into {self.rig}')
                began = time.monotonic()
                code = self.calibrate(bag)
                if code == 0:
                    self.sup.say(f'calibration: wrote {self.rig} in {time.monotonic() - began:.0f}'
                                 f' s ({time.monotonic() - self.started:.0f} s since the nodes '
                                 'started); starting the tracking')
                    return True
                if code not in (2, 3):
                    self.sup.failed = True
                    return False
                more = ('recording again' if attempt < self.attempts else
                        'no attempts left (--calibrate-attempts)')
                self.sup.say(f'calibration: not enough data: {self.reason}; {more} (walk '
                             'where the cameras overlap, keep moving)')
            self.reason = f'calibration failed {self.attempts} times: {self.reason}'
            self.sup.failed = True
            return False
        finally:
            shutil.rmtree(folder, ignore_errors=True)


def run_phase(sup: Any, start: Callable[[str], None], **kwargs: Any) -> bool:
    """Start the pose2d nodes (``kwargs['pose2d']``) and run the phase; False on failure."""
    sup.remove_stale_shm()
    for name in kwargs['pose2d']:
        start(name)
    phase = CalibrationPhase(sup, **kwargs)
    if phase.run():
        return True
    sup.say(f'calibration phase failed: {phase.reason}')
    return False
