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

"""A node or console script as a child process, its log in a file, stopped as Ctrl-C would."""

import os
import signal
import subprocess
import time
from typing import Dict, Optional, Sequence, Union


class ProcessDied(AssertionError):
    """A watched process exited while a test or benchmark still needed it (log tail inside)."""


class NodeProcess:
    """
    One child process whose stdout and stderr go to ``log_path``.

    ``new_session`` (the default) starts it as its own process group, so that ``stop_group``
    reaches what it starts (bringup's nodes, a shell recipe's publishers).
    """

    def __init__(self, cmd: Union[Sequence[str], str], log_path: Union[str, os.PathLike], *,
                 name: str = '', cwd: Optional[str] = None, env: Optional[Dict[str, str]] = None,
                 shell: bool = False, new_session: bool = True) -> None:
        """Start ``cmd`` (a bash script when ``shell``)."""
        self.log_path = str(log_path)
        self.name = name or (cmd.split()[0] if isinstance(cmd, str) else os.path.basename(cmd[0]))
        self._log = open(self.log_path, 'w')
        self.proc = subprocess.Popen(cmd if shell else list(cmd), cwd=cwd, env=env, shell=shell,
                                     executable='/bin/bash' if shell else None,
                                     stdout=self._log, stderr=subprocess.STDOUT,
                                     start_new_session=new_session)

    @property
    def pid(self) -> int:
        """Return the process id (the group id too, with ``new_session``)."""
        return self.proc.pid

    @property
    def returncode(self) -> Optional[int]:
        """Return the exit code, None while it runs."""
        return self.proc.poll()

    def alive(self) -> bool:
        """Return whether the process still runs."""
        return self.proc.poll() is None

    def log(self) -> str:
        """Return the whole log so far."""
        with open(self.log_path, encoding='utf-8', errors='replace') as f:
            return f.read()

    def tail(self, chars: int = 5000) -> str:
        """Return the end of the log, what a failure message shows."""
        return self.log()[-chars:]

    def check(self) -> None:
        """Raise ``ProcessDied`` with the log tail if the process has exited."""
        if not self.alive():
            raise ProcessDied(f'{self.name} exited with code {self.proc.returncode}; its log '
                              f'{self.log_path} ends:\n{self.tail()}')

    def interrupt(self, timeout: float = 10.0) -> int:
        """SIGINT the process (not its group), kill it after ``timeout`` s; close the log."""
        try:
            return interrupt(self.proc, timeout)
        finally:
            self._log.close()

    def stop_group(self, timeout: float = 30.0) -> int:
        """SIGINT the process group, then SIGTERM, then SIGKILL; close the log."""
        try:
            return stop_group(self.proc, timeout)
        finally:
            self._log.close()


def interrupt(proc: subprocess.Popen, timeout: float) -> int:
    """Stop ``proc`` as Ctrl-C would; kill it if it has not exited after ``timeout`` s."""
    proc.send_signal(signal.SIGINT)
    try:
        return proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        return proc.wait()


def stop_group(proc: subprocess.Popen, timeout: float = 30.0) -> int:
    """
    SIGINT the process group ``proc`` leads (Ctrl-C), then SIGTERM / SIGKILL what is left.

    Each signal gets ``timeout`` s until the leader is reaped and nothing of its group is left.
    """
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGKILL):
        try:
            os.killpg(proc.pid, sig)
        except ProcessLookupError:
            return proc.wait()
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if proc.poll() is not None:        # reaped: is anything else of its group left?
                try:
                    os.killpg(proc.pid, 0)
                except ProcessLookupError:
                    return proc.returncode
            time.sleep(0.2)
    return proc.wait()


def stop_all(procs: Sequence[Union[NodeProcess, subprocess.Popen]],
             timeout: float = 20.0) -> None:
    """SIGINT every process group at once, then kill the groups left after ``timeout`` s."""
    popens = [p.proc if isinstance(p, NodeProcess) else p for p in procs]
    for p in popens:
        if p.poll() is None:
            try:
                os.killpg(p.pid, signal.SIGINT)
            except ProcessLookupError:
                pass
    deadline = time.monotonic() + timeout
    for p in popens:
        try:
            p.wait(timeout=max(0.1, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()
    for p in procs:
        if isinstance(p, NodeProcess):
            p._log.close()


def check_alive(processes: Sequence[Union[NodeProcess, subprocess.Popen]]) -> None:
    """Raise ``ProcessDied`` (with the log tail where there is one) if any has exited."""
    for p in processes:
        if isinstance(p, NodeProcess):
            p.check()
        elif p.poll() is not None:
            raise ProcessDied(f'process {p.args!r} exited with code {p.returncode}')
