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
Bag fault figures: a SIGKILLed recorder, and randomly corrupted bags.

kill     ``mv3dpose bag record`` (a real process, real DDS) records ``--topics`` topics at
         ``--rate`` Hz from a publisher process (1.3 kB messages carrying a sequence number,
         the size of a 6-person Person2DArray) and is SIGKILLed after ``--seconds``;
         ``mv3dpose bag recover`` salvages it. Prints how many of the messages published from
         the first recorded one up to the kill the recovered bag holds.
corrupt  writes a bag of real-sized messages, flips one random byte anywhere in its storage
         file ``--count`` times per storage, and reads each back: rejected with an error,
         read back identical (a byte nothing reads), or read back with wrong values (must be
         0).

    python bench/bench_bag_faults.py kill --seconds 30
    python bench/bench_bag_faults.py corrupt --count 200
"""

import argparse
import os
from pathlib import Path
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import time

PUBLISHER = """
import sys, time
import rclpy
from rclpy.signals import SignalHandlerOptions
from std_msgs.msg import String
topics, rate = int(sys.argv[1]), float(sys.argv[2])
rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
node = rclpy.create_node('fault_pub')
pubs = [node.create_publisher(String, f'/cam{i}/persons', 100) for i in range(topics)]
pad = 'x' * 1300
n, t0 = 0, time.monotonic()
try:
    while True:
        for pub in pubs:
            pub.publish(String(data=f'{n} {pad}'))
            print(time.monotonic(), n, flush=True)
            n += 1
        t0 += 1.0 / rate
        time.sleep(max(0.0, t0 - time.monotonic()))
except KeyboardInterrupt:
    pass
"""


def kill(args) -> None:
    """Measure what a SIGKILLed recorder keeps."""
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
               ROS_DOMAIN_ID=str(random.randint(120, 200)))
    work = Path(tempfile.mkdtemp(prefix='bag_kill_'))
    out = work / 'rec'
    mv3dpose = [sys.executable, '-m', 'mv3dpose_ros.cli']
    log = open(work / 'published.txt', 'w')     # a file: a full pipe would block the publisher
    pub = subprocess.Popen([sys.executable, '-c', PUBLISHER, str(args.topics), str(args.rate)],
                           stdout=log, stderr=subprocess.DEVNULL, text=True, env=env)
    rec = subprocess.Popen(mv3dpose + ['bag', 'record', '-o', str(out), '-q', '--checkpoint',
                                       str(args.checkpoint)]
                           + [f'/cam{i}/persons' for i in range(args.topics)],
                           stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            if any(p.stat().st_size > 4096 for p in work.glob('.rec.partial-*/rec/*.mcap')):
                break
            time.sleep(0.1)
        else:
            raise SystemExit('the recorder wrote nothing within 120 s')
        time.sleep(args.seconds)
        rec.send_signal(signal.SIGKILL)
        rec.wait()
        killed_at = time.monotonic()
    finally:
        pub.send_signal(signal.SIGINT)
        pub.wait(timeout=30)
        log.close()
        pout = (work / 'published.txt').read_text()
        if rec.poll() is None:
            rec.kill()
    published = [(float(t), int(n)) for t, n in
                 (line.split() for line in pout.splitlines() if line.strip())]
    t0 = time.perf_counter()
    proc = subprocess.run(mv3dpose + ['bag', 'recover', str(out)], capture_output=True,
                          text=True, env=env)
    recover_s = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(f'recover failed: {proc.stderr}')
    from mv3dpose_ros.io.bag import BagReader
    with BagReader(out) as reader:
        seqs = sorted(int(m.data.split()[0]) for _, _, m in reader.decoded())
    sent = [n for t, n in published if seqs[0] <= n and t <= killed_at]
    print(f'recorder SIGKILLed after {args.seconds:g} s ({args.topics} topics x {args.rate:g} '
          f'Hz, checkpoint {args.checkpoint:g} s)')
    print(f'published from the first recorded message to the kill: {len(sent)}')
    print(f'recovered: {len(seqs)} ({100.0 * len(seqs) / len(sent):.2f} %), missing inside '
          f'the recovered range: {seqs[-1] - seqs[0] + 1 - len(seqs)}, recover took '
          f'{recover_s:.2f} s')
    print(proc.stdout.strip().splitlines()[0])
    shutil.rmtree(work, ignore_errors=True)


def corrupt(args) -> None:
    """Flip one random byte of a bag's storage file, many times; classify the outcomes."""
    from mv3dpose_ros.io.bag import BagError, BagReader, BagWriter, get_typestore
    string = get_typestore().types['std_msgs/msg/String']
    rng = random.Random(args.seed)
    work = Path(tempfile.mkdtemp(prefix='bag_corrupt_'))
    for storage in ('mcap', 'sqlite3'):
        good = work / f'good_{storage}'
        with BagWriter(good, storage=storage) as w:
            for i in range(args.messages):
                w.write_msg(f'/cam{i % 4}/persons', 1_700_000_000 * 10 ** 9 + i * 10 ** 7,
                            string(data=f'{i} ' + 'x' * 1300), 'std_msgs/msg/String')
        with BagReader(good) as r:
            want = [(t, s, m.data) for t, s, m in r.decoded()]
        store = next(p for p in good.iterdir() if p.suffix in ('.mcap', '.db3'))
        raw = store.read_bytes()
        rejected = identical = wrong = 0
        for k in range(args.count):
            bad = work / f'bad_{storage}_{k}'
            shutil.copytree(good, bad)
            data = bytearray(raw)
            pos = rng.randrange(len(data))
            data[pos] ^= 1 << rng.randrange(8)
            (bad / store.name).write_bytes(bytes(data))
            try:
                with BagReader(bad) as r:
                    got = [(t, s, m.data) for t, s, m in r.decoded()]
            except BagError:
                rejected += 1
            else:
                if got == want:
                    identical += 1
                else:
                    wrong += 1
            shutil.rmtree(bad)
        print(f'{storage}: {args.count} bags with one random byte flipped ({len(raw)} bytes, '
              f'{args.messages} messages): {rejected} rejected with an error, {identical} read '
              f'back identical (the byte is not read), {wrong} read back with wrong values')
    shutil.rmtree(work, ignore_errors=True)


def main() -> None:
    """Parse the arguments and run one benchmark."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    sub = parser.add_subparsers(dest='what', required=True)
    k = sub.add_parser('kill')
    k.add_argument('--seconds', type=float, default=30.0)
    k.add_argument('--topics', type=int, default=16)
    k.add_argument('--rate', type=float, default=30.0)
    k.add_argument('--checkpoint', type=float, default=1.0)
    c = sub.add_parser('corrupt')
    c.add_argument('--count', type=int, default=200)
    c.add_argument('--messages', type=int, default=2000)
    c.add_argument('--seed', type=int, default=1)
    args = parser.parse_args()
    kill(args) if args.what == 'kill' else corrupt(args)


if __name__ == '__main__':
    main()
