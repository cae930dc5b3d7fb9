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
Soak and fault bench of fusion_node: memory, latency and counts over time.

Starts ``fusion_node`` as its own process (shipped ``config/fusion.yaml``, ``use_sim_time``)
and feeds it over DDS from this process: a simulated rig of ``--cameras`` cameras and
``--people`` people at ``--rate`` Hz, on a /clock this process publishes. Faults on the way:

* camera 1 runs at half rate for the whole run;
* every ``--glitch-every`` seconds one message is stamped +1 s or -1 s (alternating);
* from ``--stall-at`` for ``--stall-s`` seconds /clock stops (messages keep coming).

Every ``--every`` seconds one line: elapsed s, node RSS MB, track sets received, capture ->
tracks latency p50 / p95 ms (sim time), distinct track ids seen so far, node resets, outlier
stamps dropped, frames lost upstream, the /diagnostics clock status. The run ends with the
per-stage drop counts of the synchroniser status.

Usage: ``python bench/soak.py [--seconds 600] [--cameras 4] [--people 3] [--rate 30]``
"""

import argparse
import os
import sys
import tempfile
import time

from diagnostic_msgs.msg import DiagnosticArray
from mv3dpose_msgs.msg import Person2DArray, TrackedSkeletonArray
from mv3dpose_ros.core.diagnostic_keys import FusionStatusNames as N
from mv3dpose_ros.core.geometry.calibration import save_rig_yaml
from mv3dpose_ros.ros.messages import ns_to_stamp, numpy_to_person2d_array, stamp_to_ns
from mv3dpose_ros.ros.qos import reliable_qos
from mv3dpose_ros.sim import make_scene
from mv3dpose_ros.testing.probe import all_matched, Probe
from mv3dpose_ros.testing.processes import NodeProcess
from mv3dpose_ros.testing.stats import percentile
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Header

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
NS = 1_000_000_000


def rss_mb(pid: int) -> float:
    """Return the resident set size of ``pid`` in MB (NaN when gone)."""
    try:
        with open(f'/proc/{pid}/status') as f:
            for line in f:
                if line.startswith('VmRSS:'):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return float('nan')


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    ap.add_argument('--seconds', type=float, default=120.0)
    ap.add_argument('--cameras', type=int, default=4)
    ap.add_argument('--people', type=int, default=3)
    ap.add_argument('--rate', type=float, default=30.0)
    ap.add_argument('--glitch-every', type=float, default=10.0)
    ap.add_argument('--stall-at', type=float, default=None,
                    help='start of the /clock stall [s] (default: half the run)')
    ap.add_argument('--stall-s', type=float, default=5.0)
    ap.add_argument('--every', type=float, default=10.0)
    args = ap.parse_args()
    stall_at = args.seconds / 2 if args.stall_at is None else args.stall_at
    loop = int(20 * args.rate)                       # 20 s of scene, replayed in a loop
    scene = make_scene(num_cameras=args.cameras, num_people=args.people, num_frames=loop,
                       fps=args.rate, seed=3)
    tmp = tempfile.mkdtemp(prefix='mv3dpose_soak_')
    rig = os.path.join(tmp, 'rig.yaml')
    save_rig_yaml(scene.cameras, rig)
    cams = list(scene.cameras)
    half = cams[1]
    proc = NodeProcess(['fusion_node', '--ros-args', '--params-file',
                        os.path.join(ROOT, 'config', 'fusion.yaml'), '-p', f'rig_config:={rig}',
                        '-p', 'use_sim_time:=true'], os.path.join(tmp, 'fusion_node.log'))
    probe = Probe('soak_feeder')
    node, ex = probe.node, probe.executor
    lat, ids, diag = [], set(), {}
    sets = [0]
    sim_now = [0]

    def on_tracks(msg):
        sets[0] += 1
        lat.append((sim_now[0] - stamp_to_ns(msg.header.stamp)) / 1e6)
        ids.update(s.track_id for s in msg.skeletons)

    def on_diag(arr):
        for st in arr.status:
            values = {kv.key: kv.value for kv in st.values}
            diag[st.name.split(': ', 1)[-1]] = (st.level[0], st.message, values)

    node.create_subscription(TrackedSkeletonArray, '/fusion_node/tracks', on_tracks,
                             reliable_qos(1000))
    node.create_subscription(DiagnosticArray, '/diagnostics', on_diag, reliable_qos(50))
    pubs = probe.camera_publishers(Person2DArray, cams)
    clock = node.create_publisher(Clock, '/clock', 10)
    probe.spin_until(lambda: all_matched(pubs.values()), 30, step=0.05)
    base = 1_000 * NS
    start = time.monotonic()
    next_print = args.every
    glitch_sign = 1
    next_glitch = args.glitch_every
    print(f'soak: {args.cameras} cameras ({half} at half rate) x {args.people} people at '
          f'{args.rate:g} Hz for {args.seconds:g} s; +-1 s stamp glitch every '
          f'{args.glitch_every:g} s; /clock stalled {stall_at:g}-{stall_at + args.stall_s:g} s')
    print('   t s | RSS MB | sets  | latency p50/p95 ms | ids | resets | outliers | lost | '
          'clock')
    f = 0
    try:
        while True:
            t = f / args.rate
            if t >= args.seconds:
                break
            while time.monotonic() < start + t:
                ex.spin_once(timeout_sec=max(0.0, start + t - time.monotonic()))
            stamp = base + int(t * NS)
            if not stall_at <= t < stall_at + args.stall_s:
                sim_now[0] = stamp + 5_000_000
                clock.publish(Clock(clock=ns_to_stamp(sim_now[0])))
            for c in cams:
                if c == half and f % 2:
                    continue
                s = stamp
                if c == cams[-1] and t >= next_glitch:
                    s += glitch_sign * NS
                    glitch_sign, next_glitch = -glitch_sign, next_glitch + args.glitch_every
                cam = scene.cameras[c]
                pubs[c].publish(numpy_to_person2d_array(
                    scene.views[f % loop][c], Header(stamp=ns_to_stamp(s), frame_id=c), c,
                    cam.width, cam.height, scene.layout))
            f += 1
            if t >= next_print:
                next_print += args.every
                sync = diag.get(N.SYNCHRONIZER, (0, '', {}))[2]
                clk = diag.get(N.CLOCK, (0, 'n/a', {}))
                recent = lat[-int(args.every * args.rate):] or [float('nan')]
                print(f'{t:6.0f} | {rss_mb(proc.pid):6.1f} | {sets[0]:5d} | '
                      f'{percentile(recent, 50):7.1f} / {percentile(recent, 95):7.1f} | '
                      f'{len(ids):3d} | {sync.get("resets", "?"):>6} | '
                      f'{sync.get("dropped in sync: outlier stamps", "?"):>8} | '
                      f'{sync.get("lost upstream (stamp gaps)", "?"):>4} | '
                      f'{"OK" if clk[0] == 0 else "ERROR"} {clk[1][:60]}', flush=True)
        probe.spin_for(3)
        sync = diag.get(N.SYNCHRONIZER, (0, '', {}))[2]
        print('synchronizer:', ', '.join(f'{k}={v}' for k, v in sync.items()))
    finally:
        proc.interrupt(10)
        probe.close()
    return 0


if __name__ == '__main__':
    sys.exit(main())
