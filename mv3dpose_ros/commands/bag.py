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
``mv3dpose bag record | play | info``: rosbag2 tools for machines without ``ros2 bag``.

record  subscribes with ``raw=True`` (no decoding cost) and writes the CDR bytes as they arrive,
        MCAP by default; the publishers' QoS is stored as ``offered_qos_profiles`` so that a
        replay offers the same QoS. Stops on ``--duration``, ``--count``, ``--idle-timeout``,
        Ctrl-C or SIGTERM and always finishes a valid bag. Every ``--checkpoint`` seconds
        (default 1) the pending chunk is closed and flushed, so a recorder killed with SIGKILL
        (or a power cut after the OS wrote it) loses at most the messages of its last
        second: ``bag recover`` turns the hidden ``.NAME.partial-PID`` folder into a bag.
        ``--overwrite`` replaces an existing bag only, never another file or folder.
play    publishes the raw bytes at the recorded pace (``--rate``), each preceded by a
        ``rosgraph_msgs/Clock`` carrying the message's bag time, so nodes with ``use_sim_time``
        follow the bag; ``--loop`` makes the clock jump back, which the fusion node treats as
        a reset. ``--wait-for-subscribers`` waits for the topics the pipeline reads
        (``ros.subscribers``: every played topic of a type that has a subscriber, or
        ``--wait-topics``), and says what it still waits for.
info    prints topics, types, counts, QoS, duration and storage, after checking every chunk
        CRC and decoding every message (``--no-verify`` skips that).
recover salvages interrupted recordings (``.NAME.partial-PID`` of dead writers: the writer's
        lock is free) into bags; ``record`` warns about those only.
"""

import argparse
import importlib
import json
from pathlib import Path
import re
import shutil
import signal
import sys
import time
from typing import Dict, Iterable, List, Optional, Sequence

from mv3dpose_ros.io.bag import BagError, BagReader, BagWriter, check_bag, DEFAULT_STORAGE
from mv3dpose_ros.io.bag import partial_dirs
from mv3dpose_ros.io.bag import salvage, STORAGES, verify_bag, writer_alive
from mv3dpose_ros.ros.subscribers import SETTLE_S, SubscriberWait
from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability
from rosbags.interfaces import QosTime
from tqdm import tqdm

# Topics that ``record`` without topic names leaves out (ros2 bag record -a does the same for
# the hidden ones; /clock would feed a replayed clock back into itself).
EXCLUDED_BY_DEFAULT = ('/rosout', '/parameter_events', '/clock')
#: How ``play`` tells where to go from a wait for subscribers (``ros.subscribers``).
WAIT_HINT = ('Ctrl-C stops; to start sooner, rerun with --wait-topics TOPIC ... naming the '
             'topics to wait for')
#: How long a played reliable topic waits at the end for its readers to acknowledge it all.
ACK_TIMEOUT_S = 5.0


# ------------------------------------------------------------------------------------ helpers

def import_msg_class(msgtype: str):
    """Return the rclpy message class of ``pkg/msg/Type`` (or ``pkg/Type``)."""
    parts = msgtype.split('/')
    if len(parts) not in (2, 3):
        raise ValueError(f'message type {msgtype!r} is not of the form pkg/msg/Type')
    pkg, name = parts[0], parts[-1]
    try:
        return getattr(importlib.import_module(f'{pkg}.msg'), name)
    except (ImportError, AttributeError) as exc:
        raise BagError(f'message type {msgtype} is not available in this ROS environment '
                       f'(is {pkg} installed and sourced?): {exc}') from exc


def qos_to_rclpy(profiles: Sequence[Qos]):
    """
    Turn recorded offered QoS profiles into the rclpy profile a player offers.

    No recorded profile gives rosbag2's default (RELIABLE, VOLATILE, KEEP_LAST 10). With several
    publishers recorded, the weakest reliability and durability are offered so that every
    original subscriber still matches.
    """
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    if not profiles:
        return QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.VOLATILE, history=HistoryPolicy.KEEP_LAST)
    best_effort = any(p.reliability == QosReliability.BEST_EFFORT for p in profiles)
    transient = all(p.durability == QosDurability.TRANSIENT_LOCAL for p in profiles)
    depth = max(int(p.depth) for p in profiles) or 10
    keep_all = any(p.history == QosHistory.KEEP_ALL for p in profiles)
    return QoSProfile(
        depth=depth,
        history=HistoryPolicy.KEEP_ALL if keep_all else HistoryPolicy.KEEP_LAST,
        reliability=ReliabilityPolicy.BEST_EFFORT if best_effort else ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if transient else DurabilityPolicy.VOLATILE)


def qos_from_rclpy(profile) -> Qos:
    """Convert an rclpy ``QoSProfile`` (as discovered on a publisher) to a rosbags ``Qos``."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, ReliabilityPolicy

    def duration(d) -> QosTime:
        ns = int(getattr(d, 'nanoseconds', 0) or 0)
        if ns <= 0 or ns >= 2 ** 63 - 1:
            return QosTime(0, 0)
        return QosTime(ns // 10 ** 9, ns % 10 ** 9)

    reliability = {ReliabilityPolicy.RELIABLE: QosReliability.RELIABLE,
                   ReliabilityPolicy.BEST_EFFORT: QosReliability.BEST_EFFORT}
    durability = {DurabilityPolicy.TRANSIENT_LOCAL: QosDurability.TRANSIENT_LOCAL,
                  DurabilityPolicy.VOLATILE: QosDurability.VOLATILE}
    history = {HistoryPolicy.KEEP_LAST: QosHistory.KEEP_LAST,
               HistoryPolicy.KEEP_ALL: QosHistory.KEEP_ALL}
    return Qos(
        history=history.get(profile.history, QosHistory.KEEP_LAST),
        depth=int(profile.depth),
        reliability=reliability.get(profile.reliability, QosReliability.RELIABLE),
        durability=durability.get(profile.durability, QosDurability.VOLATILE),
        deadline=duration(profile.deadline), lifespan=duration(profile.lifespan),
        liveliness=QosLiveliness.AUTOMATIC,
        liveliness_lease_duration=duration(profile.liveliness_lease_duration),
        avoid_ros_namespace_conventions=False)


def _subscription_qos(offered: List[Qos]):
    """Subscribe so that every discovered publisher matches (best effort if any offers it)."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    best_effort = any(q.reliability == QosReliability.BEST_EFFORT for q in offered)
    transient = bool(offered) and all(
        q.durability == QosDurability.TRANSIENT_LOCAL for q in offered)
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST, depth=100,
        reliability=ReliabilityPolicy.BEST_EFFORT if best_effort else ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if transient else DurabilityPolicy.VOLATILE)


class _StopFlag:
    """SIGINT / SIGTERM set a flag instead of killing the process, so bags close cleanly."""

    def __init__(self):
        self.stop = False
        self._old = {}

    def __enter__(self) -> '_StopFlag':
        for sig in (signal.SIGINT, signal.SIGTERM):
            try:
                self._old[sig] = signal.signal(sig, self._handle)
            except ValueError:  # not the main thread: rely on the caller's own stop logic
                pass
        return self

    def _handle(self, signum, frame) -> None:
        self.stop = True

    def __exit__(self, *exc) -> None:
        for sig, old in self._old.items():
            signal.signal(sig, old)


def _stderr(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


def _progress(total: Optional[int], desc: str, unit: str = 'msg', disable: Optional[bool] = None):
    # disable=None: tqdm shows the bar only on a terminal, so logs and tests stay clean
    return tqdm(total=total, desc=desc, unit=unit, disable=disable, leave=False,
                file=sys.stderr, dynamic_ncols=True)


def _init_rclpy(args_ros: Optional[List[str]] = None):
    import rclpy
    from rclpy.signals import SignalHandlerOptions
    context = rclpy.Context()
    rclpy.init(args=args_ros, context=context, signal_handler_options=SignalHandlerOptions.NO)
    return context


# ------------------------------------------------------------------------------------ record

def record(output: str, topics: Optional[Iterable[str]] = None, storage: str = DEFAULT_STORAGE,
           duration: Optional[float] = None, count: Optional[int] = None,
           idle_timeout: Optional[float] = None, discovery_interval: float = 0.5,
           overwrite: bool = False, use_sim_time: bool = False, quiet: bool = False,
           context=None, checkpoint: float = 1.0) -> Dict[str, int]:
    """
    Record ``topics`` (all discovered ones when empty) into a bag at ``output``.

    Stops after ``duration`` seconds, ``count`` messages, ``idle_timeout`` seconds without a
    message (once one arrived), or on SIGINT / SIGTERM. Every ``checkpoint`` seconds what was
    recorded is made crash-safe (``BagWriter.checkpoint``). Returns messages per topic.
    """
    if not checkpoint > 0:
        raise ValueError(f'--checkpoint must be > 0 s, got {checkpoint}')
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.parameter import Parameter

    wanted = list(topics or [])
    writer = BagWriter(output, storage=storage, overwrite=overwrite)   # fails before any DDS
    stale = partial_dirs(output)
    if stale and not quiet:
        print(f'warning: interrupted recording(s) of {output} found: '
              f'{", ".join(str(d) for d in stale)}; run `mv3dpose bag recover {output}` '
              'to salvage them', file=sys.stderr)
    own_context = context is None
    if own_context:
        context = _init_rclpy()
    node = Node('mv3dpose_bag_recorder', context=context,
                parameter_overrides=[Parameter('use_sim_time', value=use_sim_time)])
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    subs = {}
    state = {'total': 0, 'last': None}
    bar = _progress(None, f'recording {output}', disable=True if quiet else None)
    log = node.get_logger()

    def make_callback(topic: str):
        def callback(data: bytes) -> None:
            stamp = node.get_clock().now().nanoseconds if use_sim_time else time.time_ns()
            writer.write(topic, stamp, data)
            state['total'] += 1
            state['last'] = time.monotonic()
            bar.update(1)
        return callback

    def discover() -> None:
        for topic, types in node.get_topic_names_and_types():
            if topic in subs or not types:
                continue
            if wanted and topic not in wanted:
                continue
            if not wanted and topic in EXCLUDED_BY_DEFAULT:
                continue
            msgtype = types[0]
            try:
                msg_class = import_msg_class(msgtype)
            except BagError as exc:
                log.warning(f'not recording {topic}: {exc}')
                subs[topic] = None
                continue
            infos = node.get_publishers_info_by_topic(topic)
            offered = [qos_from_rclpy(i.qos_profile) for i in infos]
            if not offered:
                continue  # only subscribers so far: wait for a publisher to learn its QoS
            writer.add_topic(topic, msgtype, offered)
            subs[topic] = node.create_subscription(
                msg_class, topic, make_callback(topic), _subscription_qos(offered), raw=True)
            log.info(f'recording {topic} [{msgtype}]')

    start = time.monotonic()
    next_discovery = start
    next_checkpoint = start + checkpoint
    try:
        with _StopFlag() as flag:
            while not flag.stop and context.ok():
                now = time.monotonic()
                if now >= next_checkpoint:
                    writer.checkpoint()
                    next_checkpoint = now + checkpoint
                if duration is not None and now - start >= duration:
                    break
                if count is not None and state['total'] >= count:
                    break
                if (idle_timeout is not None and state['last'] is not None
                        and now - state['last'] >= idle_timeout):
                    break
                if now >= next_discovery:
                    discover()
                    next_discovery = now + discovery_interval
                executor.spin_once(timeout_sec=0.05)
    except BaseException:
        bar.close()
        writer.abort()
        raise
    finally:
        executor.shutdown(timeout_sec=1.0)
        node.destroy_node()
        if own_context:
            context.try_shutdown()
    bar.close()
    missing = [t for t in wanted if subs.get(t) is None]
    if missing and not quiet:
        print(f'warning: never saw a publisher on {", ".join(missing)}', file=sys.stderr)
    writer.close()
    return dict(writer.counts)


# ------------------------------------------------------------------------------------ play

class _Pacer:
    """Counts messages on pace topics so the player can wait for slow downstream nodes."""

    def __init__(self, node, topics: Sequence[str], known: Dict[str, str], timeout: float):
        self.node, self.timeout = node, timeout
        self.topics = list(topics)
        self.known = dict(known)
        self.counts = dict.fromkeys(self.topics, 0)
        self.subs = {}
        self.timeouts = 0

    def subscribe_ready(self) -> bool:
        """Subscribe to every pace topic whose type is known; tell if all are subscribed."""
        from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
        graph = dict(self.node.get_topic_names_and_types())
        for topic in self.topics:
            if topic in self.subs:
                continue
            msgtype = self.known.get(topic) or (graph.get(topic) or [None])[0]
            if msgtype is None:
                continue
            qos = QoSProfile(depth=100, history=HistoryPolicy.KEEP_LAST,
                             reliability=ReliabilityPolicy.BEST_EFFORT)

            def count(_data, t=topic):
                self.counts[t] += 1
            self.subs[topic] = self.node.create_subscription(
                import_msg_class(msgtype), topic, count, qos, raw=True)
        return len(self.subs) == len(self.topics)

    def wait(self, executor, target: int, stopped) -> float:
        """Spin until every pace topic saw ``target`` messages (or the timeout); return wait."""
        t0 = time.monotonic()
        while not stopped() and time.monotonic() - t0 < self.timeout:
            if all(c >= target for c in self.counts.values()):
                break
            executor.spin_once(timeout_sec=0.01)
        else:
            if not stopped():
                self.timeouts += 1
                late = [t for t, c in self.counts.items() if c < target]
                self.node.get_logger().warning(
                    f'pace: no message on {", ".join(late)} within {self.timeout:g} s; '
                    'continuing')
                for t in late:
                    self.counts[t] = target   # do not wait for this one twice
        return time.monotonic() - t0


def play(path: str, rate: float = 1.0, loop: bool = False, topics: Optional[Iterable[str]] = None,
         start_offset: float = 0.0, clock: bool = True, wait_for_subscribers: float = 0.0,
         delay: float = 0.0, quiet: bool = False, context=None, stop=None,
         pace_topics: Optional[Sequence[str]] = None, pace_timeout: float = 30.0,
         on_publish=None, wait_topics: Optional[Sequence[str]] = None) -> int:
    """
    Publish the messages of the bag at ``path``; return how many were published.

    ``rate`` scales the pace (2 = twice as fast, 0 = as fast as possible); ``start_offset``
    skips the first seconds; ``wait_for_subscribers`` waits up to that many seconds until the
    played topics of every message type that has a subscriber (or each of ``wait_topics``)
    have one, and this held for ``ros.subscribers.SETTLE_S`` (the subscribers see the player
    too; nothing is lost to discovery), saying on stderr what it waits for; ``stop`` is an optional
    callable polled between messages. ``pace_topics``: after each time point (the messages
    sharing one bag timestamp), wait until every pace topic delivered one more message (at
    most ``pace_timeout`` s), so slow nodes that keep only the newest input lose nothing.
    ``on_publish(topic, timestamp_ns)`` is called after each publication.
    """
    from rclpy.duration import Duration
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    from rosgraph_msgs.msg import Clock

    if rate < 0:
        raise ValueError(f'--rate must be >= 0, got {rate}')
    reader = BagReader(path)
    summary = reader.topics()
    chosen = list(summary) if not topics else list(topics)
    unknown = [t for t in chosen if t not in summary]
    if unknown:
        reader.close()
        raise BagError(f'{path}: no topic {", ".join(unknown)} in the bag '
                       f'(it has {", ".join(summary) or "none"})')
    unplayed = [t for t in wait_topics or () if t not in chosen]
    if unplayed:
        reader.close()
        raise BagError(f'{path}: --wait-topics {", ".join(unplayed)}: not played (the played '
                       f'topics are {", ".join(chosen)})')
    own_context = context is None
    if own_context:
        context = _init_rclpy()
    node = Node('mv3dpose_bag_player', context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    published = 0
    try:
        pubs = {}
        for topic in chosen:
            info = summary[topic]
            pubs[topic] = node.create_publisher(import_msg_class(info.msgtype), topic,
                                                qos_to_rclpy(info.qos))
        clock_pub = None
        if clock:
            clock_pub = node.create_publisher(
                Clock, '/clock', QoSProfile(depth=100, history=HistoryPolicy.KEEP_LAST,
                                            reliability=ReliabilityPolicy.RELIABLE))
        pacer = None
        if pace_topics:
            pacer = _Pacer(node, pace_topics, {t: s.msgtype for t, s in summary.items()},
                           pace_timeout)
        with _StopFlag() as flag:
            def stopped() -> bool:
                return flag.stop or not context.ok() or bool(stop and stop())

            def pace_missing() -> List[str]:
                if pacer is None or pacer.subscribe_ready():
                    return []
                return [f'pace topic {t} (--pace-on) to appear' for t in pacer.topics
                        if t not in pacer.subs]

            SubscriberWait(
                {t: summary[t].msgtype for t in chosen},
                lambda t: pubs[t].get_subscription_count(), named=wait_topics,
                say=None if quiet else _stderr, prefix='bag play: ', hint=WAIT_HINT,
            ).wait(executor, wait_for_subscribers, stopped, also=pace_missing,
                   also_timeout=pace_timeout if pacer is not None else 0.0)
            if pacer is not None and len(pacer.subs) < len(pacer.topics):
                missing = [t for t in pacer.topics if t not in pacer.subs]
                raise BagError(f'pace topic {", ".join(missing)} never appeared')
            if delay > 0:
                time.sleep(delay)
            start_ns = reader.start_ns + int(round(start_offset * 1e9))
            total = sum(summary[t].count for t in chosen)
            bar = _progress(total if not loop else None, f'playing {path}',
                            disable=True if quiet else None)
            groups = 0
            try:
                while not stopped():
                    wall0 = time.monotonic()
                    group_stamp = None
                    for m in reader.messages(chosen, start_ns=start_ns if start_offset else None):
                        if stopped():
                            break
                        if pacer is not None and group_stamp is not None \
                                and m.timestamp != group_stamp:
                            groups += 1
                            wall0 += pacer.wait(executor, groups, stopped)
                        group_stamp = m.timestamp
                        if rate > 0:
                            due = wall0 + (m.timestamp - start_ns) * 1e-9 / rate
                            while not stopped():
                                wait = due - time.monotonic()
                                if wait <= 0:
                                    break
                                time.sleep(min(wait, 0.1))
                        if clock_pub is not None:
                            msg = Clock()
                            msg.clock.sec, msg.clock.nanosec = divmod(m.timestamp, 10 ** 9)
                            clock_pub.publish(msg)
                        pubs[m.topic].publish(m.data)
                        published += 1
                        if on_publish is not None:
                            on_publish(m.topic, m.timestamp)
                        bar.update(1)
                    if pacer is not None and group_stamp is not None and not stopped():
                        groups += 1
                        pacer.wait(executor, groups, stopped)
                    if not loop:
                        break
            finally:
                bar.close()
            # give reliable readers the chance to fetch the tail before the process exits
            for pub in list(pubs.values()) + ([clock_pub] if clock_pub else []):
                pub.wait_for_all_acked(Duration(seconds=ACK_TIMEOUT_S))
    finally:
        reader.close()
        executor.shutdown(timeout_sec=1.0)
        node.destroy_node()
        if own_context:
            context.try_shutdown()
    return published


# ------------------------------------------------------------------------------------ info

def _qos_text(profiles: Sequence[Qos]) -> str:
    if not profiles:
        return 'default'
    return ', '.join(sorted({f'{p.reliability.name.lower()}/{p.durability.name.lower()}'
                             f'/{p.history.name.lower()}({p.depth})' for p in profiles}))


def info(path: str, verify: bool = False) -> dict:
    """
    Return a summary of the bag at ``path`` (what ``mv3dpose bag info`` prints).

    ``verify`` also checks every chunk / message CRC and decodes every message (reads the
    whole bag once).
    """
    integrity = 'not verified (--no-verify)'
    if verify:
        integrity = f'{verify_bag(path)}; {check_bag(path)} messages decode'
    with BagReader(path) as reader:
        return {
            'integrity': integrity,
            'path': str(path),
            'storage': reader.storage,
            'messages': reader.message_count,
            'duration_s': reader.duration_s,
            'start_ns': reader.start_ns,
            'end_ns': reader.end_ns,
            'topics': {t: {'type': s.msgtype, 'count': s.count, 'qos': _qos_text(s.qos)}
                       for t, s in reader.topics().items()},
        }


def _ns_text(ns: int) -> str:
    return f'{ns // 10 ** 9}.{ns % 10 ** 9:09d}'


def format_info(summary: dict) -> str:
    """Render an ``info`` summary as text."""
    lines = [f'bag:       {summary["path"]}',
             f'storage:   {summary["storage"]}',
             f'duration:  {summary["duration_s"]:.3f} s',
             f'start:     {_ns_text(summary["start_ns"])} s',
             f'end:       {_ns_text(summary["end_ns"])} s',
             f'messages:  {summary["messages"]}',
             f'integrity: {summary.get("integrity", "not verified")}',
             f'topics:    {len(summary["topics"])}']
    width = max([len(t) for t in summary['topics']] + [5])
    tw = max([len(v['type']) for v in summary['topics'].values()] + [4])
    for topic, v in summary['topics'].items():
        lines.append(f'  {topic:<{width}}  {v["type"]:<{tw}}  {v["count"]:>7}  qos {v["qos"]}')
    return '\n'.join(lines)


# ------------------------------------------------------------------------------------ recover

def recover(path: str, output: Optional[str] = None, overwrite: bool = False,
            keep: bool = False) -> List[dict]:
    """
    Salvage interrupted recordings into bags; return one summary per recovered folder.

    ``path`` is a ``.NAME.partial-PID`` folder, or the bag path ``NAME`` the recorder was
    writing, whose partial folders of dead processes are then all recovered. The bag goes to
    ``output`` (default ``NAME``; with several folders ``NAME.recovered-PID``). The partial
    folder is removed afterwards unless ``keep``.
    """
    src = Path(path.rstrip('/'))
    match = re.match(r'^\.(.+)\.partial-(\d+)$', src.name)
    if match and src.is_dir():
        if writer_alive(src):
            raise BagError(f'{path}: its writer (process {match.group(2)}) is still recording; '
                           'stop it first (Ctrl-C or SIGTERM finish the bag themselves)')
        sources, target = [src], src.parent / match.group(1)
    else:
        sources, target = partial_dirs(src), src
        if not sources:
            live = [d.name for d in src.parent.glob(f'.{src.name}.partial-*')
                    if d.is_dir() and writer_alive(d)]
            raise BagError(f'{path}: no interrupted recording to recover (no '
                           f'.{src.name}.partial-PID folder of a dead process beside it'
                           + (f'; {", ".join(live)} belong to running recorders'
                              if live else '') + ')')
    results = []
    for d in sources:
        pid = d.name.rsplit('-', 1)[-1]
        out = Path(output) if output else target
        if len(sources) > 1 and not output:
            out = target.parent / f'{target.name}.recovered-{pid}'
        elif len(sources) > 1:
            out = Path(f'{output}.{pid}')
        report = salvage(d, out, overwrite=overwrite)
        if not keep:
            shutil.rmtree(d, ignore_errors=True)
        results.append({'source': str(d), 'output': str(report.output),
                        'messages': report.messages, 'topics': report.topics,
                        'lost_tail_bytes': report.lost_tail_bytes, 'note': report.note})
    return results


# ------------------------------------------------------------------------------------ CLI

def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the ``record``, ``play`` and ``info`` subcommands."""
    sub = parser.add_subparsers(dest='bag_command', metavar='{record,play,info,recover}')
    sub.required = True
    rec = sub.add_parser('record', help='record topics into a rosbag2 bag (MCAP by default)')
    rec.add_argument('topics', nargs='*',
                     help='topics to record (default: every discovered topic except '
                          f'{", ".join(EXCLUDED_BY_DEFAULT)})')
    rec.add_argument('-o', '--output', required=True, help='output bag directory (must not exist)')
    rec.add_argument('--storage', choices=STORAGES, default=DEFAULT_STORAGE)
    rec.add_argument('--duration', type=float, help='stop after this many seconds')
    rec.add_argument('--count', type=int, help='stop after this many messages in total')
    rec.add_argument('--idle-timeout', type=float,
                     help='stop when no message arrived for this many seconds (after the first)')
    rec.add_argument('--use-sim-time', action='store_true',
                     help='stamp messages with /clock time instead of the system time')
    rec.add_argument('--overwrite', action='store_true',
                     help='replace an existing bag at the output (never another file or folder)')
    rec.add_argument('--checkpoint', type=float, default=1.0, metavar='SECONDS',
                     help='make the recording crash-safe this often: a recorder killed with '
                          'SIGKILL loses at most the last interval (default 1 s)')
    rec.add_argument('-q', '--quiet', action='store_true')

    ply = sub.add_parser('play', help='publish the messages of a bag with /clock')
    ply.add_argument('bag', help='bag directory or .mcap / .db3 file')
    ply.add_argument('--rate', type=float, default=1.0,
                     help='playback speed factor (0 = as fast as possible)')
    ply.add_argument('--loop', action='store_true', help='start again at the end')
    ply.add_argument('--topics', nargs='+', help='play only these topics')
    ply.add_argument('--start-offset', type=float, default=0.0,
                     help='skip the first seconds of the bag')
    ply.add_argument('--no-clock', dest='clock', action='store_false',
                     help='do not publish /clock')
    ply.add_argument('--wait-for-subscribers', type=float, default=0.0, metavar='SECONDS',
                     help='wait up to this long (then play anyway) for the pipeline to '
                          'subscribe: for every played topic of a message type that has a '
                          "subscriber on one of the played topics (one camera's image_raw "
                          "subscribed: every camera's; camera_info that nothing reads: not), "
                          f'and until that held for {SETTLE_S:g} s; says on stderr what it '
                          'still waits for')
    ply.add_argument('--wait-topics', nargs='+', metavar='TOPIC',
                     help='with --wait-for-subscribers: wait for these played topics instead '
                          '(each must have a subscriber)')
    ply.add_argument('--delay', type=float, default=0.0, help='sleep before playing [s]')
    ply.add_argument('--pace-on', nargs='+', metavar='TOPIC',
                     help='after each time point wait until every TOPIC delivered one more '
                          'message (replay at the speed of the slowest node, dropping nothing)')
    ply.add_argument('--pace-timeout', type=float, default=30.0,
                     help='longest wait for a pace topic [s]')
    ply.add_argument('-q', '--quiet', action='store_true')

    inf = sub.add_parser('info', help='print topics, types, counts, duration and storage')
    inf.add_argument('bag', help='bag directory or .mcap / .db3 file')
    inf.add_argument('--json', action='store_true', help='print JSON instead of text')
    inf.add_argument('--no-verify', dest='verify', action='store_false',
                     help='skip checking the CRC and decoding of every message (fast on huge '
                          'bags)')

    rcv = sub.add_parser('recover', help='salvage an interrupted recording (.NAME.partial-PID) '
                                         'into a bag')
    rcv.add_argument('bag', help='the bag path the recorder wrote to, or its .NAME.partial-PID '
                                 'folder')
    rcv.add_argument('-o', '--output', help='where to write the bag (default: the bag path)')
    rcv.add_argument('--overwrite', action='store_true', help='replace an existing bag')
    rcv.add_argument('--keep', action='store_true', help='keep the partial folder')


def run(args: argparse.Namespace) -> int:
    """Run ``mv3dpose bag <record|play|info>``."""
    try:
        if args.bag_command == 'info':
            summary = info(args.bag, verify=args.verify)
            print(json.dumps(summary, indent=2) if args.json else format_info(summary))
            return 0
        if args.bag_command == 'record':
            counts = record(args.output, args.topics, storage=args.storage,
                            duration=args.duration, count=args.count,
                            idle_timeout=args.idle_timeout, overwrite=args.overwrite,
                            use_sim_time=args.use_sim_time, quiet=args.quiet,
                            checkpoint=args.checkpoint)
            total = sum(counts.values())
            print(f'wrote {args.output}: {total} messages on {len(counts)} topics'
                  + ''.join(f'\n  {t}: {n}' for t, n in sorted(counts.items())))
            return 0
        if args.bag_command == 'play':
            n = play(args.bag, rate=args.rate, loop=args.loop, topics=args.topics,
                     start_offset=args.start_offset, clock=args.clock,
                     wait_for_subscribers=args.wait_for_subscribers,
                     wait_topics=args.wait_topics, delay=args.delay,
                     quiet=args.quiet, pace_topics=args.pace_on,
                     pace_timeout=args.pace_timeout)
            if not args.quiet:
                print(f'played {n} messages from {args.bag}')
            return 0
        if args.bag_command == 'recover':
            for r in recover(args.bag, args.output, args.overwrite, args.keep):
                print(f'recovered {r["messages"]} messages from {r["source"]} into '
                      f'{r["output"]} ({r["note"]})'
                      + ''.join(f'\n  {t}: {n}' for t, n in sorted(r['topics'].items())))
            return 0
    except (BagError, ValueError, OSError) as exc:
        print(f'error: {exc}', file=sys.stderr)
        return 1
    return 2


__all__ = ['add_arguments', 'run', 'record', 'play', 'info', 'recover', 'format_info',
           'import_msg_class', 'qos_to_rclpy', 'qos_from_rclpy']
