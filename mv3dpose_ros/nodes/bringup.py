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
bringup: one pose2d_node per camera plus fusion_node, from one rig and one parameter set.

Each node runs as a child process with the same ``--ros-args`` a launch file or ``ros2 run``
would give it (``-r __ns:=/<camera>``, the params files, then a generated override file).
Child processes rather than one process with a MultiThreadedExecutor, because:

- the GIL: pose2d pre/post-processing and the fusion core are Python/numpy, so N cameras in one
  interpreter share one core for most of their work; processes use every core;
- isolation: a camera whose model or driver fails takes down its own node only; the fusion
  node keeps tracking on the other cameras (partial sets) and reports the silent one;
- identical command lines to ``ros2 run`` and ``launch/mv3dpose.launch.py``, so what is
  tested here is what runs in a full ROS install;
- rclpy has no intra-process zero-copy anyway: messages between nodes of one process still go
  through the RMW, so one process would save only memory (about 60-100 MB per interpreter).

Overrides go into a generated params file passed last, because a node-specific key of a
params file (``/**/fusion_node``) wins over ``-p`` (which applies to ``/**``). Ctrl-C (SIGINT)
or SIGTERM stops all children: SIGINT to each, then SIGTERM after ``--stop-timeout``, then
SIGKILL. A child that dies is reported with its exit code; a dead fusion_node stops the
bringup (exit 1) unless ``--respawn`` restarts it, a dead pose2d_node is restarted only with
``--respawn``.
"""

import argparse
import os
import shlex
import signal
import subprocess
import sys
import tempfile
import time
from typing import Any, Dict, List, Optional, Sequence

from mv3dpose_ros.core.calibration import load_calibration
from mv3dpose_ros.ros.params import package_search_dirs, resolve_path
import yaml

DEFAULT_PARAMS = ('config/pose2d.yaml', 'config/fusion.yaml')


def _executable(name: str) -> List[str]:
    """Return the command of console script ``name`` (falls back to ``python -m``)."""
    here = os.path.dirname(os.path.abspath(sys.argv[0] or ''))
    for base in (here, *os.environ.get('PATH', '').split(os.pathsep)):
        path = os.path.join(base, name)
        if base and os.path.isfile(path) and os.access(path, os.X_OK):
            return [path]
    return [sys.executable, '-m', f'mv3dpose_ros.nodes.{name}']


def _node_section(docs: Sequence[Dict[str, Any]], node: str) -> Dict[str, Any]:
    """Merge the ros__parameters of every key matching ``node`` (wildcards included)."""
    out: Dict[str, Any] = {}
    for doc in docs:
        for key, section in (doc or {}).items():
            name = str(key).rstrip('/')
            if name in ('/**', f'/**/{node}', node, f'/{node}') and isinstance(section, dict):
                out.update(section.get('ros__parameters', {}) or {})
    return out


def _parse_assignments(items: Sequence[str], what: str) -> Dict[str, Any]:
    out = {}
    for item in items:
        if ':=' not in item:
            raise SystemExit(f'bringup: {what} {item!r} must look like name:=value')
        key, raw = item.split(':=', 1)
        out[key.strip()] = yaml.safe_load(raw) if raw.strip() else ''
    return out


def _nest(flat: Dict[str, Any]) -> Dict[str, Any]:
    """Turn dotted names into the nested mapping params files use."""
    out: Dict[str, Any] = {}
    for key, value in flat.items():
        node = out
        parts = key.split('.')
        for part in parts[:-1]:
            node = node.setdefault(part, {})
        node[parts[-1]] = value
    return out


class Plan:
    """The processes to start: names, commands and the generated override file's content."""

    def __init__(self, args: argparse.Namespace) -> None:
        search = [os.getcwd()] + package_search_dirs()
        self.params_files = [os.path.abspath(resolve_path(p, search))
                             for p in (args.params_file or DEFAULT_PARAMS)]
        for p in self.params_files:
            if not os.path.isfile(p):
                raise SystemExit(f'bringup: params file {p!r} not found')
        docs = []
        for p in self.params_files:
            with open(p, encoding='utf-8') as f:
                docs.append(yaml.safe_load(f) or {})
        fusion = _node_section(docs, 'fusion_node')
        fusion_over = _parse_assignments(args.fusion_param or [], '--fusion-param')
        rig = args.rig or fusion_over.get('rig_config') or fusion.get('rig_config')
        if not rig:
            raise SystemExit('bringup: no rig: pass --rig or set fusion_node rig_config')
        self.rig_path = os.path.abspath(resolve_path(rig, search))
        try:
            rig_cameras = list(load_calibration(self.rig_path))
        except (OSError, ValueError) as exc:
            raise SystemExit(f'bringup: cannot load rig {self.rig_path!r}: {exc}')
        cams = args.cameras or fusion_over.get('camera_ids') or fusion.get('camera_ids') or \
            rig_cameras
        unknown = [c for c in cams if c not in rig_cameras]
        if unknown:
            raise SystemExit(f'bringup: cameras {unknown} are not in {self.rig_path} '
                             f'({", ".join(rig_cameras)})')
        self.cameras = list(cams)
        ns_pattern = args.namespace
        self.namespaces = {c: ns_pattern.replace('{camera}', c) for c in self.cameras}
        bad = [ns for ns in self.namespaces.values()
               if any(tok[:1].isdigit() for tok in ns.strip('/').split('/'))]
        if bad and not args.no_pose2d:
            raise SystemExit(f'bringup: namespaces {bad} are invalid ROS names (a token starts '
                             "with a digit): use e.g. --namespace '/cam{camera}'")
        overrides: Dict[str, Any] = {}
        pose2d_over = _parse_assignments(args.pose2d_param or [], '--pose2d-param')
        for cam, ns in self.namespaces.items():
            overrides[f'{ns.rstrip("/")}/pose2d_node'] = {'ros__parameters': _nest(
                {**pose2d_over, 'camera_id': cam})}
        fusion_params = {**fusion_over, 'rig_config': self.rig_path,
                         'camera_ids': self.cameras,
                         'input_topic': ns_pattern.rstrip('/') + '/persons_2d'}
        overrides['/**/fusion_node'] = {'ros__parameters': _nest(fusion_params)}
        if args.use_sim_time:
            overrides['/**'] = {'ros__parameters': {'use_sim_time': True}}
        self.overrides = overrides
        self.args = args

    def commands(self, override_file: str) -> Dict[str, List[str]]:
        """Return ``{process name: argv}``."""
        files = []
        for p in self.params_files + [override_file]:
            files += ['--params-file', p]
        out = {}
        if not self.args.no_pose2d:
            for cam, ns in self.namespaces.items():
                argv = _executable('pose2d_node') + ['--ros-args', '-r', f'__ns:={ns}']
                if self.args.image_topic:
                    argv += ['-r', f'image:={self.args.image_topic.replace("{camera}", cam)}']
                out[f'pose2d_node[{cam}]'] = argv + files
        out['fusion_node'] = _executable('fusion_node') + ['--ros-args'] + files
        return out


class Supervisor:
    """Start, watch and stop the child processes."""

    def __init__(self, commands: Dict[str, List[str]], respawn: bool, stop_timeout: float,
                 log: Any = sys.stderr) -> None:
        self.commands = commands
        self.respawn = respawn
        self.stop_timeout = stop_timeout
        self.log = log
        self.procs: Dict[str, subprocess.Popen] = {}
        self.stopping = False
        self.failed = False

    def say(self, text: str) -> None:
        """Print one bringup status line."""
        print(f'[bringup] {text}', file=self.log, flush=True)

    def start(self, name: str) -> None:
        """Start (or restart) process ``name`` in its own session (we deliver the signals)."""
        self.procs[name] = subprocess.Popen(self.commands[name], start_new_session=True)
        self.say(f'started {name} (pid {self.procs[name].pid}): '
                 f'{" ".join(shlex.quote(a) for a in self.commands[name])}')

    def request_stop(self, signum: int = signal.SIGINT, frame: Any = None) -> None:
        """Signal handler: begin a clean shutdown."""
        self.stopping = True

    def run(self) -> int:
        """Start everything, supervise until a stop request, then stop; return the exit code."""
        for name in self.commands:
            self.start(name)
        while not self.stopping:
            for name, proc in list(self.procs.items()):
                code = proc.poll()
                if code is None or self.stopping:
                    continue
                self.say(f'{name} exited with code {code}')
                if self.respawn:
                    time.sleep(1.0)
                    self.start(name)
                elif name == 'fusion_node':
                    self.say('fusion_node is gone: stopping everything')
                    self.failed = True
                    self.stopping = True
                else:
                    del self.procs[name]
                    self.say(f'continuing without {name} (use --respawn to restart it)')
            time.sleep(0.1)
        return self.stop()

    def stop(self) -> int:
        """Stop all children: SIGINT, then SIGTERM, then SIGKILL; return the exit code."""
        alive = {n: p for n, p in self.procs.items() if p.poll() is None}
        for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGKILL):
            for name, proc in alive.items():
                if proc.poll() is None:
                    try:
                        proc.send_signal(sig)
                    except ProcessLookupError:
                        pass
            deadline = time.monotonic() + (self.stop_timeout if sig != signal.SIGKILL else 5.0)
            while time.monotonic() < deadline and any(p.poll() is None for p in alive.values()):
                time.sleep(0.05)
            alive = {n: p for n, p in alive.items() if p.poll() is None}
            if not alive:
                break
            self.say(f'{", ".join(alive)} still running: sending '
                     f'{signal.Signals(sig).name} was not enough')
        bad = {n: p.returncode for n, p in self.procs.items()
               if p.returncode not in (0, -signal.SIGINT, 130)}
        if bad:
            self.say(f'exit codes: {bad}')
        else:
            self.say('all nodes stopped cleanly')
        return 1 if self.failed or bad else 0


def build_parser() -> argparse.ArgumentParser:
    """Return the command-line parser of ``bringup``."""
    p = argparse.ArgumentParser(
        prog='bringup', description='Start one pose2d_node per camera plus fusion_node.',
        epilog='Example: bringup --rig config/rigs/my_rig.yaml --image-topic '
               "'/{camera}/image_raw' --pose2d-param model.name:=yolo11n-pose")
    p.add_argument('--rig', help='rig calibration file (default: fusion_node rig_config of '
                   'the params files)')
    p.add_argument('--cameras', nargs='+', help='camera ids (default: camera_ids, else all '
                   'rig cameras)')
    p.add_argument('--params-file', action='append', help='ROS params file(s) for all nodes '
                   f'(default: {" ".join(DEFAULT_PARAMS)})')
    p.add_argument('--namespace', default='/{camera}', help='namespace of each camera '
                   "(default '/{camera}'); pose2d publishes <namespace>/persons_2d")
    p.add_argument('--image-topic', help="image topic per camera, e.g. '/{camera}/image_raw' "
                   '(default: <namespace>/image)')
    p.add_argument('--pose2d-param', action='append', metavar='NAME:=VALUE',
                   help='override a pose2d_node parameter (repeatable)')
    p.add_argument('--fusion-param', action='append', metavar='NAME:=VALUE',
                   help='override a fusion_node parameter (repeatable)')
    p.add_argument('--use-sim-time', action='store_true', help='use_sim_time for all nodes')
    p.add_argument('--no-pose2d', action='store_true', help='start fusion_node only (2D poses '
                   'come from elsewhere, e.g. a bag)')
    p.add_argument('--respawn', action='store_true', help='restart nodes that exit')
    p.add_argument('--stop-timeout', type=float, default=10.0,
                   help='seconds to wait after SIGINT before SIGTERM (default 10)')
    p.add_argument('--dry-run', action='store_true', help='print the commands and the '
                   'override file, start nothing')
    return p


def main(argv: Optional[List[str]] = None) -> int:
    """Entry point of the ``bringup`` console script."""
    args = build_parser().parse_args(sys.argv[1:] if argv is None else argv)
    plan = Plan(args)
    fd, override_file = tempfile.mkstemp(prefix='mv3dpose_bringup_', suffix='.yaml')
    try:
        with os.fdopen(fd, 'w', encoding='utf-8') as f:
            f.write('# generated by bringup: overrides passed after the params files\n')
            yaml.safe_dump(plan.overrides, f, sort_keys=False)
        commands = plan.commands(override_file)
        if args.dry_run:
            for name, argv_ in commands.items():
                print(f'{name}: {" ".join(shlex.quote(a) for a in argv_)}')
            print('# generated override params file (passed last):')
            print(yaml.safe_dump(plan.overrides, sort_keys=False), end='')
            return 0
        sup = Supervisor(commands, args.respawn, args.stop_timeout)
        signal.signal(signal.SIGINT, sup.request_stop)
        signal.signal(signal.SIGTERM, sup.request_stop)
        sup.say(f'rig {plan.rig_path}: cameras {", ".join(plan.cameras)}')
        return sup.run()
    finally:
        try:
            os.unlink(override_file)
        except OSError:
            pass


if __name__ == '__main__':
    sys.exit(main())
