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
What a multi-host rig puts on the wire, how late its tracks are, and what a slow link does.

The rig of test/test_multi_host.py (docs/multi-host.md's blocks as typed, four network
namespaces on one bridge: camera hosts A and B with two Pose2Sim videos each at 10 Hz, a
fusion host, a planner host recording ``/fusion_node/tracks``), then the same four cameras on
one host. Prints (no assertions):

1. discovery: bytes each host sent and received from start until the nodes were up with no
   image yet, and per second while idle (DDS announcements, no data);
2. steady state: bytes/s on each host's wire, the ``persons_2d`` payload per camera (its
   serialized size, measured on the camera host itself) and of ``/fusion_node/tracks``;
   capture -> tracks latency p50 / p95 at the planner;
3. camera host B's uplink capped with ``tc tbf`` at each of ``--caps``: what B sends, how many
   of B's ``persons_2d`` fusion_node receives per second, the share of tracks with B's cameras
   and their latency;
4. the one-host rig (the same publishers and ``mv3dpose_bringup --rig RIG`` in one namespace):
   capture -> tracks latency p50 / p95;
5. on paper: the serialized ``Person2DArray`` at N persons x 17 joints.

Run as root: ``python bench/multi_host.py`` (about 5 minutes on 2 cores).
"""

import argparse
import os
import random
import shlex
import sys
import time
from typing import Dict, List

from mv3dpose_ros.core.diagnostic_keys import FusionKeys as K
from mv3dpose_ros.testing import netns
from mv3dpose_ros.testing.processes import NodeProcess, stop_all
from mv3dpose_ros.testing.remote_probe import cameras_of, Recording
from mv3dpose_ros.testing.stats import percentile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, 'test'))
from test_live_rig import readme_block  # noqa: E402  (the one reader of run-as-typed blocks)

DOC = 'docs/multi-host.md'
RIG = 'config/rigs/pose2sim_multiperson.yaml'
VIDEOS = os.path.join(os.path.dirname(ROOT), 'shared', 'data', 'pose2sim_singleperson', 'videos')
HOSTS = {'cam_a': ['cam_01', 'cam_02'], 'cam_b': ['cam_03', 'cam_04']}
CAMERAS = [c for cams in HOSTS.values() for c in cams]
NS = 1_000_000_000


def block(marker: str) -> str:
    """Return the docs/multi-host.md block ``multi-host-MARKER``."""
    return readme_block(f'multi-host-{marker}', DOC)


def publishers(cameras: List[str], rate: float) -> str:
    """Return the lines that play each camera's video as its driver (in the background)."""
    return ''.join(
        f'mv3dpose_image_publisher {shlex.quote(os.path.join(VIDEOS, c.replace("_", "")))}'
        f'.mp4 --camera {c} --rate {rate:g} --bounce --preload --calibration $RIG &\n'
        for c in cameras)


def person2d_bytes(persons: int, joints: int = 17) -> int:
    """Return the serialized size of a Person2DArray of ``persons`` x ``joints``."""
    from mv3dpose_msgs.msg import Keypoint2D, Person2D, Person2DArray
    from rclpy.serialization import serialize_message
    msg = Person2DArray(camera_id='cam_01', image_width=1920, image_height=1080,
                        layout='coco17')
    msg.header.frame_id = 'cam_01'
    msg.persons = [Person2D(score=0.9, keypoints=[Keypoint2D() for _ in range(joints)])
                   for _ in range(persons)]
    return len(serialize_message(msg))


def tracks_bytes(tracks: int, joints: int = 17, cameras: int = 4) -> int:
    """Return the serialized size of a TrackedSkeletonArray of ``tracks`` skeletons."""
    from mv3dpose_msgs.msg import Joint3D, TrackedSkeleton, TrackedSkeletonArray
    from rclpy.serialization import serialize_message
    msg = TrackedSkeletonArray(layout='coco17')
    msg.header.frame_id = 'world'
    msg.skeletons = [TrackedSkeleton(joints=[Joint3D() for _ in range(joints)],
                                     source_cameras=[f'cam_0{i}' for i in range(cameras)])
                     for _ in range(tracks)]
    return len(serialize_message(msg))


def latency(messages: List[dict]) -> str:
    """Return 'p50 / p95 ms' of capture -> arrival of tracks messages."""
    lat = [(m['t'] - m['stamp']) / 1e6 for m in messages]
    return f'p50 {percentile(lat, 50):.0f} / p95 {percentile(lat, 95):.0f} ms ({len(lat)} msgs)'


def received(rec: Recording, cam: str, until_ns: int) -> int:
    """Return fusion_node's 'received' count of ``cam`` in the last status before ``until``."""
    st = rec.status(f'fusion_node: {cam} input', 0, until_ns)
    return int(st[-1]['values'][K.RECEIVED]) if st else 0


def kbps(nbytes: float, seconds: float) -> str:
    """Return bytes over seconds as kB/s text."""
    return f'{nbytes / seconds / 1e3:.1f} kB/s'


def multi_host(args, env: Dict[str, str], tmp: str) -> None:
    """Print figures 1-3 (the multi-host rig)."""
    rec = Recording(os.path.join(tmp, 'planner.jsonl'))
    sizes = {h: Recording(os.path.join(tmp, f'sizes_{h}.jsonl')) for h in HOSTS}
    diag = Recording(os.path.join(tmp, 'diagnostics.jsonl'))
    procs: Dict[str, NodeProcess] = {}
    with netns.Network(['cam_a', 'cam_b', 'fusion', 'planner']) as net:
        def start(host: str, script: str, name: str, **extra) -> NodeProcess:
            procs[name] = NodeProcess(net.shell(host, script), os.path.join(tmp, f'{name}.log'),
                                      name=name, cwd=ROOT, shell=True, env=dict(env, **extra))
            return procs[name]

        pre = 'source env.sh\nexport ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET\n'
        try:
            t0 = time.time_ns()
            start('planner', block('planner-host') + f'exec python -m mv3dpose_ros.testing.'
                  f'remote_probe {shlex.quote(rec.path)} --tracks\n', 'planner')
            start('fusion', block('fusion-host'), 'fusion')
            # fusion_node's /diagnostics, read on its own host: the probe's discovery range is
            # env.sh's LOCALHOST, so no other host learns of it and nothing of it is on the wire.
            start('fusion', f'source env.sh\nexec python -m mv3dpose_ros.testing.remote_probe '
                  f'{shlex.quote(diag.path)} --diagnostics\n', 'diagnostics')
            for host, cams in HOSTS.items():
                start(host, block('camera-host'), host, CAMERAS=' '.join(cams))
                topics = ' '.join(f'/{c}/persons_2d' for c in cams)
                start(host, pre + f'exec python -m mv3dpose_ros.testing.remote_probe '
                      f'{shlex.quote(sizes[host].path)} --sizes {topics}\n', f'sizes_{host}')
            # 1. Discovery: everything up, no image yet.
            time.sleep(args.idle_warmup)
            c0 = net.all_counters()
            time.sleep(args.measure)
            c1 = net.all_counters()
            print(f'== discovery ({len(CAMERAS)} pose2d_node, fusion_node, the planner probe, '
                  'a persons_2d size probe per camera host; no image)')
            for h in net.hosts:
                print(f'  {h}: first {args.idle_warmup:g} s sent {c0[h]["tx_bytes"] / 1e3:.0f} '
                      f'kB, received {c0[h]["rx_bytes"] / 1e3:.0f} kB; idle after: sent '
                      f'{kbps(c1[h]["tx_bytes"] - c0[h]["tx_bytes"], args.measure)}, received '
                      f'{kbps(c1[h]["rx_bytes"] - c0[h]["rx_bytes"], args.measure)}')
            # 2. Steady state.
            for host, cams in HOSTS.items():
                start(host, pre + publishers(cams, args.rate) + 'wait\n', f'publishers_{host}')
            ok = rec.wait(lambda: cameras_of(rec.tracks[-20:]) >= set(CAMERAS), 180,
                          list(procs.values()))
            print(f'== steady state ({len(CAMERAS)} cameras x {args.rate:g} Hz, every camera in '
                  f'the tracks at the planner: {ok}, {(time.time_ns() - t0) / NS:.0f} s after '
                  f'start; load {os.getloadavg()[0]:.1f})')
            time.sleep(3.0)
            a, ta = net.all_counters(), time.time_ns()
            time.sleep(args.measure)
            b, tb = net.all_counters(), time.time_ns()
            span = (tb - ta) / NS
            for h in net.hosts:
                print(f'  {h}: sent {kbps(b[h]["tx_bytes"] - a[h]["tx_bytes"], span)}, '
                      f'received {kbps(b[h]["rx_bytes"] - a[h]["rx_bytes"], span)} '
                      f'({(b[h]["tx_packets"] - a[h]["tx_packets"]) / span:.0f} packets/s out)')
            for host, cams in HOSTS.items():
                sizes[host].poll()
                for c in cams:
                    got = [s['bytes'] for s in sizes[host].sizes
                           if s['topic'] == f'/{c}/persons_2d' and ta <= s['t'] <= tb]
                    print(f'  {c} persons_2d: {len(got) / span:.1f} Hz x median '
                          f'{percentile(got, 50):.0f} B = {kbps(sum(got), span)}')
            rec.poll()
            steady = rec.tracks_between(ta, tb)
            print(f'  /fusion_node/tracks at the planner: {len(steady) / span:.1f} Hz x median '
                  f'{percentile([m["bytes"] for m in steady], 50):.0f} B = '
                  f'{kbps(sum(m["bytes"] for m in steady), span)}')
            print(f'  capture -> tracks at the planner: {latency(steady)}')
            # 3. Camera host B's uplink capped; fusion_node's input counts from /diagnostics.
            seen = diag.wait(lambda: diag.status('fusion_node: cam_01 input'), 20, [])
            print('== camera host B capped (tc tbf on its eth0, burst 32 kB, latency 200 ms; '
                  f'fusion_node /diagnostics read on its host: {seen})')
            for rate in args.caps:
                net.cap('cam_b', rate)
                time.sleep(3.0)
                diag.poll()
                a, ta = net.all_counters()['cam_b'], time.time_ns()
                n0 = {c: received(diag, c, ta) for c in CAMERAS}
                time.sleep(args.measure)
                diag.poll()
                rec.poll()
                b, tb = net.all_counters()['cam_b'], time.time_ns()
                span = (tb - ta) / NS
                n1 = {c: received(diag, c, tb) for c in CAMERAS}
                window = rec.tracks_between(ta + 2 * NS, tb)
                with_b = [m for m in window if cameras_of([m]) & set(HOSTS['cam_b'])]
                counts = ', '.join(f'{c} {(n1[c] - n0[c]) / span:.1f}' for c in CAMERAS)
                print(f'  {rate}: cam_b sent {kbps(b["tx_bytes"] - a["tx_bytes"], span)}; '
                      f'fusion_node received per s {counts}; tracks {len(window) / span:.1f} Hz, '
                      f'{len(with_b)} with cam_b cameras ({latency(with_b)})')
            net.cap('cam_b', None)
        finally:
            stop_all(list(procs.values()))


def one_host(args, env: Dict[str, str], tmp: str) -> None:
    """Print figure 4 (the same cameras, rates and nodes on one host)."""
    rec = Recording(os.path.join(tmp, 'one_host.jsonl'))
    procs: List[NodeProcess] = []
    with netns.Network(['rig']) as net:
        try:
            script = ('source env.sh\n' + publishers(CAMERAS, args.rate)
                      + 'mv3dpose_bringup --rig $RIG\n')
            procs.append(NodeProcess(net.shell('rig', script), os.path.join(tmp, 'rig.log'),
                                     cwd=ROOT, shell=True, env=env))
            procs.append(NodeProcess(net.shell('rig', 'source env.sh\nexec python -m mv3dpose_ros.'
                                               f'testing.remote_probe {shlex.quote(rec.path)} '
                                               '--tracks\n'), os.path.join(tmp, 'probe.log'),
                                     cwd=ROOT, shell=True, env=env))
            ok = rec.wait(lambda: cameras_of(rec.tracks[-20:]) >= set(CAMERAS), 180, procs)
            time.sleep(3.0)
            ta = time.time_ns()
            time.sleep(args.measure)
            rec.poll()
            window = rec.tracks_between(ta, time.time_ns())
            print(f'== one host ({len(CAMERAS)} cameras x {args.rate:g} Hz; every camera in the '
                  f'tracks: {ok}; load {os.getloadavg()[0]:.1f}): tracks '
                  f'{len(window) / args.measure:.1f} Hz, capture -> tracks {latency(window)}')
        finally:
            stop_all(procs)


def main() -> int:
    """Run the multi-host rig, then the one-host rig, and print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--rate', type=float, default=10.0, help='camera rate [Hz]')
    parser.add_argument('--measure', type=float, default=15.0, help='seconds per figure')
    parser.add_argument('--idle-warmup', type=float, default=20.0,
                        help='seconds from start to the idle measurement (nodes up, no image)')
    parser.add_argument('--caps', nargs='*',
                        default=['1mbit', '256kbit', '128kbit', '64kbit', '16kbit'],
                        help='tc tbf rates for camera host B')
    parser.add_argument('--skip-one-host', action='store_true')
    args = parser.parse_args()
    ok, why = netns.available()
    if not ok:
        print(f'multi_host: skipped, {why}')
        return 0
    if not os.path.isdir(VIDEOS):
        print(f'multi_host: skipped, no videos at {VIDEOS}')
        return 0
    netns.sweep_stale()
    import tempfile
    tmp = tempfile.mkdtemp(prefix='multi_host_')
    env = dict(os.environ, RIG=RIG, ROS_DOMAIN_ID=os.environ.get(
        'ROS_DOMAIN_ID', str(random.randint(100, 199))))
    print(f'multi_host: {os.cpu_count()} CPUs, load {os.getloadavg()[0]:.1f}; logs in {tmp}')
    print('== on paper: serialized Person2DArray (coco17): ' + ', '.join(
        f'{n} persons {person2d_bytes(n)} B' for n in (0, 1, 2, 4, 8)))
    print('== on paper: serialized TrackedSkeletonArray (coco17, 4 cameras each): ' + ', '.join(
        f'{n} tracks {tracks_bytes(n)} B' for n in (0, 1, 2, 4, 8)))
    multi_host(args, env, tmp)
    if not args.skip_one_host:
        one_host(args, env, tmp)
    return 0


if __name__ == '__main__':
    sys.exit(main())
