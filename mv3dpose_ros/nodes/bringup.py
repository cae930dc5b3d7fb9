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

The processes, their names, remappings and parameters come from ``nodes.processes``, the
list ``launch/mv3dpose.launch.py`` starts too. Each node runs as a child process with the same
``--ros-args`` a launch file or ``ros2 run`` would give it (``-r __ns:=/<camera>``, the params
files, then a generated override file).
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
SIGKILL. Child output is forwarded line by line. A child that dies stops everything and
bringup exits 1 with a last line naming the node, its exit code and the last error line of its
output (a rig with a silently missing camera is worse than a clear stop), unless ``--respawn``
restarts it: after 1 s, and after twice the last delay (up to 30 s) while it keeps exiting
within 30 s of its start, so a node that cannot start does not restart in a tight loop; the
others are watched meanwhile. Before starting the nodes, and before each restart, it removes
the Fast DDS shared-memory files in /dev/shm of processes that are gone (``ros/system/shm.py``;
64 MB per killed process that published images), unless ``--keep-shm``.

Names: ``{camera}`` in ``--namespace`` and ``--image-topic`` is the camera's ROS name
(``ros/names.py``: ``00_03`` -> ``cam00_03``); both are validated before anything starts. The
children get the Fast DDS profile ``config/fastdds_shm.xml`` (HD images over shared memory)
unless ``FASTRTPS_DEFAULT_PROFILES_FILE`` or ``--dds-profile`` says otherwise.
``--calibrate`` starts the pose2d nodes alone, calibrates the rig from the people into
``--save-rig`` (``nodes/calibration_phase.py``), then starts fusion_node on it.
"""

import argparse
import collections
import os
import shlex
import signal
import subprocess
import sys
import tempfile
import threading
import time
from typing import Any, Deque, Dict, List, Optional, Sequence, Tuple

from mv3dpose_ros.nodes.calibration_phase import end, recorded_topics, run_phase
from mv3dpose_ros.nodes.processes import (DEFAULT_IMAGE_TOPIC, DEFAULT_NAMESPACE,
                                          DEFAULT_PARAMS, parse_assignments, PlanError,
                                          ProcessSpec, rig_processes)
from mv3dpose_ros.ros.params import package_search_dirs, resolve_path
from mv3dpose_ros.ros.system.memory import with_hugepages
from mv3dpose_ros.ros.system.shm import clean_stale_files, SHM_DIR, uses_fast_dds
import yaml

DDS_PROFILE = 'config/fastdds_shm.xml'
PROFILE_VARS = ('FASTRTPS_DEFAULT_PROFILES_FILE', 'FASTDDS_DEFAULT_PROFILES_FILE')
#: --respawn: first restart delay, its cap, and the uptime after which a node counts as stable
RESPAWN_DELAY_S = 1.0
RESPAWN_MAX_DELAY_S = 30.0
RESPAWN_STABLE_S = 30.0
#: --calibrate: pose2d settings of the calibration phase (keypoint quality over latency: on a
#: 2-core host the auto size is the smallest; measured in docs/calibrate.md)
CALIBRATE_POSE2D = ('model.min_input_side:=640', 'inference_rate_hz:=5.0')


def _executable(spec: ProcessSpec) -> List[str]:
    """Return the command of the process's console script (falls back to ``python -m``)."""
    here = os.path.dirname(os.path.abspath(sys.argv[0] or ''))
    for base in (here, *os.environ.get('PATH', '').split(os.pathsep)):
        path = os.path.join(base, spec.executable)
        if base and os.path.isfile(path) and os.access(path, os.X_OK):
            return [path]
    return [sys.executable, '-m', spec.module]


class Plan:
    """The processes to start (``nodes.processes``), their commands and their environment."""

    def __init__(self, args: argparse.Namespace) -> None:
        try:
            self.rig = rig_processes(
                args.params_file or DEFAULT_PARAMS, args.rig, args.cameras, args.namespace,
                args.image_topic, parse_assignments(args.pose2d_param or [], '--pose2d-param'),
                {**parse_assignments(args.fusion_param or [], '--fusion-param'),
                 **({'save_rig': os.path.abspath(args.save_rig)} if args.save_rig else {})},
                pose2d=not args.no_pose2d, fusion=not args.no_fusion,
                foxglove_port=args.foxglove, use_sim_time=args.use_sim_time)
        except PlanError as exc:
            raise SystemExit(f'bringup: {exc}')
        self.rig_path, self.cameras = self.rig.rig_path, self.rig.cameras
        self.params_files = self.rig.params_files
        self.overrides = self.rig.overrides()
        self.env, self.dds_profile = _dds_env(args.dds_profile,
                                              [os.getcwd()] + package_search_dirs())

    def commands(self, override_file: str) -> Dict[str, List[str]]:
        """Return ``{process name: argv}``."""
        files = self.params_files + [override_file]
        return {p.name: _executable(p) + p.ros_args(files) for p in self.rig.processes}


def _dds_env(profile: Optional[str], search: Sequence[str]) -> Tuple[Dict[str, str], str]:
    """Return the children's environment with the Fast DDS profile applied, and its path."""
    env = with_hugepages(os.environ)       # 6 MB images, 2 MiB page faults (ros/system/memory.py)
    env['PYTHONUNBUFFERED'] = '1'          # child output is forwarded line by line
    if profile is None:
        profile = next((env[v] for v in PROFILE_VARS if env.get(v)), DDS_PROFILE)
    if profile.strip().lower() == 'none':
        for var in PROFILE_VARS:
            env.pop(var, None)
        return env, ''
    path = os.path.abspath(resolve_path(profile, search))
    if not os.path.isfile(path):
        raise SystemExit(f'bringup: Fast DDS profile {path!r} not found (--dds-profile)')
    env[PROFILE_VARS[0]] = path
    return env, path


def _reason(lines: Sequence[str]) -> str:
    """Return the line of a dead child's output that says why (last error, else last line)."""
    lines = [ln.strip() for ln in lines if ln.strip()]
    for marker in ('[FATAL]', '[ERROR]', 'Error', 'error:'):
        hits = [ln for ln in lines if marker in ln]
        if hits:
            return hits[-1]
    return lines[-1] if lines else 'no output'


class Supervisor:
    """Start, watch and stop the child processes; forward their output."""

    def __init__(self, commands: Dict[str, List[str]], respawn: bool, stop_timeout: float,
                 log: Any = sys.stderr, env: Optional[Dict[str, str]] = None,
                 clean_shm: bool = False) -> None:
        self.commands = commands
        self.respawn = respawn
        self.clean_shm = clean_shm
        self.stop_timeout = stop_timeout
        self.log = log
        self.env = env
        self.procs: Dict[str, subprocess.Popen] = {}
        self.started_at: Dict[str, float] = {}
        self.quick_exits: Dict[str, int] = {}       # exits in a row within RESPAWN_STABLE_S
        self.tails: Dict[str, Deque[str]] = {}
        self._readers: Dict[str, threading.Thread] = {}
        self._log_lock = threading.Lock()
        self.stopping = False
        self.failed = False
        self.died: Dict[str, str] = {}

    def say(self, text: str) -> None:
        """Print one bringup status line."""
        with self._log_lock:
            print(f'[bringup] {text}', file=self.log, flush=True)

    def _forward(self, name: str, stream: Any) -> None:
        """Copy a child's output to our log line by line, keeping the last lines."""
        tail = self.tails[name]
        for line in iter(stream.readline, ''):
            tail.append(line)
            with self._log_lock:
                self.log.write(line)
                self.log.flush()
        stream.close()

    def start(self, name: str) -> None:
        """Start (or restart) process ``name`` in its own session (we deliver the signals)."""
        proc = subprocess.Popen(self.commands[name], start_new_session=True, env=self.env,
                                stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                errors='replace', bufsize=1)
        self.procs[name] = proc
        self.started_at[name] = time.monotonic()
        self.tails[name] = collections.deque(maxlen=40)
        self._readers[name] = threading.Thread(target=self._forward, args=(name, proc.stdout),
                                               daemon=True)
        self._readers[name].start()
        self.say(f'started {name} (pid {proc.pid}): '
                 f'{" ".join(shlex.quote(a) for a in self.commands[name])}')

    def remove_stale_shm(self) -> None:
        """Remove Fast DDS shared memory left by killed processes (``ros.system.shm``); say so."""
        if not self.clean_shm:
            return
        removed, freed = clean_stale_files()
        if removed:
            self.say(f'removed {removed} Fast DDS shared-memory files ({freed / 2**20:.0f} MB) '
                     f'in {SHM_DIR} left by processes that are gone (--keep-shm keeps them)')

    def respawn_delay(self, name: str) -> float:
        """Return how long to wait before restarting ``name``, which has just exited."""
        lived = time.monotonic() - self.started_at.get(name, 0.0)
        quick = self.quick_exits.get(name, 0) + 1 if lived < RESPAWN_STABLE_S else 0
        self.quick_exits[name] = quick
        return min(RESPAWN_MAX_DELAY_S, RESPAWN_DELAY_S * 2 ** max(0, quick - 1))

    def _exit_text(self, name: str, code: int) -> str:
        self._readers[name].join(timeout=2.0)     # the output up to the exit
        how = (f'killed by {signal.Signals(-code).name}' if code < 0 else f'exit code {code}')
        return f'{name} died ({how}): {_reason(self.tails[name])}'

    def request_stop(self, signum: int = signal.SIGINT, frame: Any = None) -> None:
        """Signal handler: begin a clean shutdown."""
        self.stopping = True

    def run(self) -> int:
        """Start everything, supervise until a stop request, then stop; return the exit code."""
        self.remove_stale_shm()
        for name in self.commands:
            if name not in self.procs:       # --calibrate started the pose2d nodes before
                self.start(name)
        restart_at: Dict[str, float] = {}
        while not self.stopping:
            for name, due in list(restart_at.items()):
                if time.monotonic() >= due and not self.stopping:
                    del restart_at[name]
                    self.remove_stale_shm()              # a crash leaves its segment behind
                    self.start(name)
            for name, proc in list(self.procs.items()):
                code = proc.poll()
                if code is None or self.stopping or name in restart_at:
                    continue
                text = self._exit_text(name, code)
                self.say(text)
                if self.respawn:
                    delay = self.respawn_delay(name)
                    restart_at[name] = time.monotonic() + delay
                    self.say(f'restarting {name} in {delay:g} s (--respawn)')
                else:
                    self.died[name] = text
                    self.say(f'stopping everything because {name} is gone (--respawn restarts '
                             'nodes that exit)')
                    self.failed = True
                    self.stopping = True
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
        for text in self.died.values():
            self.say(f'exiting with 1 because {text}')
        return 1 if self.failed or bad else 0


def build_parser() -> argparse.ArgumentParser:
    """Return the command-line parser of ``bringup``."""
    p = argparse.ArgumentParser(
        prog='mv3dpose_bringup', description='Start one pose2d_node per camera plus '
        'fusion_node.', epilog='Example: mv3dpose_bringup --rig config/rigs/my_rig.yaml '
        '--pose2d-param model.name:=yolo11n-pose')
    p.add_argument('--rig', help='rig calibration file (default: fusion_node rig_config of '
                   'the params files)')
    p.add_argument('--cameras', nargs='+', help='camera ids (default: camera_ids, else all '
                   'rig cameras)')
    p.add_argument('--params-file', action='append', help='ROS params file(s) for all nodes '
                   f'(default: {" ".join(DEFAULT_PARAMS)})')
    p.add_argument('--namespace', default=DEFAULT_NAMESPACE, help='namespace of each camera '
                   "(default '/{camera}'); pose2d publishes <namespace>/persons_2d. {camera} is "
                   'the camera id, or cam<id> when the id is no valid ROS name (00_03 -> '
                   'cam00_03)')
    p.add_argument('--image-topic', default=DEFAULT_IMAGE_TOPIC,
                   help=f"image topic per camera (default '{DEFAULT_IMAGE_TOPIC}', where "
                   'mv3dpose_image_publisher --camera NAME publishes)')
    p.add_argument('--dds-profile', default=None, metavar='XML',
                   help='Fast DDS XML profile for the nodes (default: '
                   '$FASTRTPS_DEFAULT_PROFILES_FILE, else the shipped config/fastdds_shm.xml, '
                   "which carries HD images over shared memory); 'none' = Fast DDS defaults")
    p.add_argument('--pose2d-param', action='append', metavar='NAME:=VALUE',
                   help='override a pose2d_node parameter (repeatable)')
    p.add_argument('--fusion-param', action='append', metavar='NAME:=VALUE',
                   help='override a fusion_node parameter (repeatable)')
    p.add_argument('--save-rig', metavar='PATH', help='write the rig in use to PATH (rig '
                   'YAML) at start and whenever the calibration watch corrects a camera '
                   '(fusion_node save_rig)')
    p.add_argument('--calibrate', action='store_true', help='start from the intrinsics of '
                   '--rig: record the pose2d nodes while people walk, estimate the extrinsics '
                   'into --save-rig (mv3dpose calibrate), then start fusion_node on it')
    p.add_argument('--calibrate-s', type=float, default=60.0, metavar='S', help='--calibrate: '
                   'seconds of people walking to record per attempt (default 60)')
    p.add_argument('--calibrate-attempts', type=int, default=3, metavar='N', help='--calibrate:'
                   ' record again this many times in all while data is missing (default 3)')
    p.add_argument('--calibrate-pose2d-param', action='append', metavar='NAME:=VALUE',
                   help='--calibrate: a pose2d_node parameter for the calibration phase only '
                   '(repeatable; given ones replace the default '
                   f'{" ".join(CALIBRATE_POSE2D)}: the largest input at a lower rate); the '
                   'nodes restart with the tracking settings after')
    p.add_argument('--use-sim-time', action='store_true', help='use_sim_time for all nodes')
    p.add_argument('--no-pose2d', action='store_true', help='start fusion_node only (2D poses '
                   'come from elsewhere, e.g. a bag or other hosts)')
    p.add_argument('--no-fusion', action='store_true', help='start the pose2d_nodes only '
                   '(fusion_node runs on another host)')
    p.add_argument('--foxglove', type=int, nargs='?', const=8765, default=None,
                   metavar='PORT', help='also start the live web view (mv3dpose_foxglove_view) '
                   'on ws://127.0.0.1:PORT (default 8765)')
    p.add_argument('--respawn', action='store_true', help='restart nodes that exit (after 1 s, '
                   'doubling up to 30 s while a node keeps exiting within 30 s)')
    p.add_argument('--keep-shm', action='store_true', help='do not remove the Fast DDS '
                   f'shared-memory files in {SHM_DIR} of processes that are gone (removed by '
                   'default at start and before each respawn)')
    p.add_argument('--stop-timeout', type=float, default=10.0,
                   help='seconds to wait after SIGINT before SIGTERM (default 10)')
    p.add_argument('--dry-run', action='store_true', help='print the commands and the '
                   'override file, start nothing')
    return p


def main(argv: Optional[List[str]] = None) -> int:
    """Entry point of the ``bringup`` console script."""
    parser = build_parser()
    args = parser.parse_args(sys.argv[1:] if argv is None else argv)
    if args.no_pose2d and args.no_fusion:
        parser.error('--no-pose2d and --no-fusion together start nothing')
    if args.calibrate and (not args.save_rig or args.no_pose2d or args.no_fusion):
        parser.error('--calibrate needs --save-rig RIG and both the pose2d and fusion nodes')
    if args.calibrate_pose2d_param is None:
        args.calibrate_pose2d_param = list(CALIBRATE_POSE2D)
    restart = bool(args.calibrate and args.calibrate_pose2d_param)
    track = argparse.Namespace(**{**vars(args), 'rig': args.save_rig, 'no_pose2d': not restart})
    if args.calibrate:              # the pose2d nodes first, fusion_node on the new rig after
        args.no_fusion, args.foxglove = True, None
        args.pose2d_param = [*(args.pose2d_param or []), *(args.calibrate_pose2d_param or [])]
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
            print(f'# Fast DDS profile: {plan.dds_profile or "none (Fast DDS defaults)"}')
            if args.calibrate:
                print(f'# --calibrate: then mv3dpose bag record ({args.calibrate_s:g} s), '
                      f'mv3dpose calibrate -o {args.save_rig}, fusion_node on it')
            return 0
        sup = Supervisor(commands, args.respawn, args.stop_timeout, env=plan.env,
                         clean_shm=not args.keep_shm and uses_fast_dds(plan.env))
        signal.signal(signal.SIGINT, sup.request_stop)
        signal.signal(signal.SIGTERM, sup.request_stop)
        sup.say(f'rig {plan.rig_path}: cameras {", ".join(plan.cameras)}; Fast DDS profile '
                f'{plan.dds_profile or "none"}')
        if args.calibrate:
            if not _calibrate(args, plan, sup):
                return sup.stop() or (1 if sup.failed else 0)
            track_plan = Plan(track)
            with open(override_file + '.track', 'w', encoding='utf-8') as f:
                yaml.safe_dump(track_plan.overrides, f, sort_keys=False)
            if restart:             # the pose2d nodes again, with the tracking settings
                sup.say('restarting the pose2d nodes with the tracking settings')
                for name in list(sup.procs):
                    end(sup.procs.pop(name), args.stop_timeout)
            sup.commands.update(track_plan.commands(override_file + '.track'))
        return sup.run()
    finally:
        for path in (override_file, override_file + '.track'):
            try:
                os.unlink(path)
            except OSError:
                pass


def _calibrate(args: argparse.Namespace, plan: Plan, sup: Supervisor) -> bool:
    """Run the calibration phase (``nodes.calibration_phase``); False if it failed."""
    cli = _executable(ProcessSpec('mv3dpose', 'mv3dpose', 'mv3dpose', 'mv3dpose_ros.cli'))
    return run_phase(sup, sup.start, pose2d=list(sup.commands), mv3dpose=cli,
                     topics=recorded_topics(plan.cameras, args.namespace, args.image_topic),
                     intrinsics=plan.rig_path, rig=os.path.abspath(args.save_rig),
                     seconds=args.calibrate_s, attempts=args.calibrate_attempts, env=plan.env)


if __name__ == '__main__':
    sys.exit(main())
