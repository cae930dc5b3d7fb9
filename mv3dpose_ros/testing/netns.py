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
Hosts on one switch, on one machine: Linux network namespaces on a bridge with no way out.

A multi-host rig (camera hosts, a fusion host, a planner) is tested and measured here without
the computers: each host is a network namespace (``ip netns``) with its own loopback and one
``eth0``, a veth whose other end is on a bridge that has no address, no uplink and no route,
so traffic goes only between the namespaces of one ``Network`` (and to each one's loopback).
Fast DDS takes two participants for one host when the host name and the IPv4 addresses agree,
so processes in one namespace share images over shared memory and those of different
namespaces talk UDP over the bridge, as on real hosts.

Names carry the creating process's id and a counter (runs in parallel do not collide), and
``Network.close`` removes every namespace, veth and bridge it made, also after a failure
(use it as a context manager). ``sweep_stale`` removes what a killed run left behind: only
names of this module's pattern whose creating process is gone.

Needs root (CAP_NET_ADMIN); ``available`` says whether namespaces can be made here and why not.
"""

import itertools
import json
import os
import re
import shlex
import subprocess
from typing import Dict, List, Optional, Sequence, Tuple

PREFIX = 'mv3dns'                     # namespaces: mv3dns-<pid>-<n>-<host>
BRIDGE_PREFIX = 'mv3b'                # bridges: mv3b<pid>n<n>; veths: mv3v<pid>n<n>h<i>
SUBNET = '10.213'                     # 10.213.<network>.<host + 1>/24, no route beyond it
_counter = itertools.count()


def _ip(*args: str, check: bool = True) -> subprocess.CompletedProcess:
    return subprocess.run(['ip', *args], capture_output=True, text=True, check=check)


def available() -> Tuple[bool, str]:
    """Return whether network namespaces can be created here, and why not."""
    if os.geteuid() != 0:
        return False, 'network namespaces need root (CAP_NET_ADMIN); not root here'
    name = f'{PREFIX}-{os.getpid()}-probe{next(_counter)}'
    try:
        r = _ip('netns', 'add', name, check=False)
    except FileNotFoundError:
        return False, 'no `ip` command (iproute2)'
    if r.returncode != 0:
        return False, f'`ip netns add` failed: {r.stderr.strip()}'
    _ip('netns', 'del', name, check=False)
    return True, ''


def sweep_stale() -> List[str]:
    """Remove namespaces and bridges of this module whose creating process is gone."""
    removed = []

    def dead(pid: str) -> bool:
        return not os.path.exists(f'/proc/{pid}')

    for line in _ip('netns', 'list', check=False).stdout.splitlines():
        m = re.match(rf'({PREFIX}-(\d+)-\S+)', line)
        if m and dead(m.group(2)):
            _ip('netns', 'del', m.group(1), check=False)
            removed.append(m.group(1))
    for line in _ip('-o', 'link', 'show', 'type', 'bridge', check=False).stdout.splitlines():
        m = re.match(rf'\d+: ({BRIDGE_PREFIX}(\d+)n\d+)[:@]', line)
        if m and dead(m.group(2)):
            _ip('link', 'del', m.group(1), check=False)
            removed.append(m.group(1))
    return removed


class Network:
    """
    Namespaced hosts on one bridge: ``Network(['cam_a', 'fusion'])``, then ``run`` / ``cmd``.

    Every host gets ``eth0`` at ``10.213.<n>.<i + 1>/24`` plus a route for multicast (DDS
    discovery) on it, and ``lo``; nothing else. ``n`` differs between the networks of runs in
    parallel: Fast DDS tells hosts apart by host name and addresses, and all the namespaces
    share the host name and /dev/shm. ``multicast=False`` makes a switch that forwards no
    multicast between hosts (the bridge snoops IGMP, forgets every membership at once and
    floods no unknown group), as networks that block it: multicast still works within a host,
    and DDS finds other hosts only by unicast (``ROS_STATIC_PEERS``).
    """

    def __init__(self, hosts: Sequence[str], multicast: bool = True) -> None:
        """Create the bridge and one namespace per host; undo all of it on any failure."""
        self.tag = f'{os.getpid()}n{next(_counter)}'
        self.bridge = f'{BRIDGE_PREFIX}{self.tag}'
        self.hosts: Dict[str, str] = {}           # host -> namespace
        self.veths: Dict[str, str] = {}           # host -> bridge end of its veth
        self.addresses: Dict[str, str] = {}
        self._links: List[str] = []
        self.multicast = multicast
        self._octet = (os.getpid() * 31 + int(self.tag.split('n')[1])) % 250 + 1
        try:
            _ip('link', 'add', self.bridge, 'type', 'bridge')
            self._links.append(self.bridge)
            if not multicast:          # snooping, and every group membership forgotten at once
                _ip('link', 'set', self.bridge, 'type', 'bridge', 'mcast_snooping', '1',
                    'mcast_querier', '0', 'mcast_membership_interval', '1')
            _ip('link', 'set', self.bridge, 'up')
            for i, host in enumerate(hosts):
                self._add_host(i, host)
        except BaseException:
            self.close()
            raise

    def _add_host(self, i: int, host: str) -> None:
        ns = f'{PREFIX}-{self.tag.replace("n", "-")}-{host}'
        outer, inner = f'mv3v{self.tag}h{i}', f'mv3i{self.tag}h{i}'
        _ip('netns', 'add', ns)
        self.hosts[host] = ns
        _ip('link', 'add', outer, 'type', 'veth', 'peer', 'name', inner)
        self._links.append(outer)
        self.veths[host] = outer
        _ip('link', 'set', inner, 'netns', ns)
        _ip('link', 'set', outer, 'master', self.bridge)
        _ip('link', 'set', outer, 'up')
        addr = f'{SUBNET}.{self._octet}.{i + 1}'
        self.addresses[host] = addr
        steps = [['link', 'set', inner, 'name', 'eth0'],
                 ['addr', 'add', f'{addr}/24', 'dev', 'eth0'],
                 ['link', 'set', 'eth0', 'up'], ['link', 'set', 'lo', 'up'],
                 ['route', 'add', '224.0.0.0/4', 'dev', 'eth0']]
        for args in steps:
            _ip('-n', ns, *args)
        if not self.multicast:         # the switch floods no multicast to this port
            subprocess.run(['bridge', 'link', 'set', 'dev', outer, 'mcast_flood', 'off'],
                           capture_output=True, text=True, check=True)

    # ------------------------------------------------------------------ processes
    def cmd(self, host: str, argv: Sequence[str]) -> List[str]:
        """Return ``argv`` prefixed to run inside ``host``'s namespace."""
        return ['ip', 'netns', 'exec', self.hosts[host], *argv]

    def shell(self, host: str, script: str) -> str:
        """Return a bash command line that runs ``script`` inside ``host``'s namespace."""
        return (f'exec ip netns exec {shlex.quote(self.hosts[host])} bash -c '
                f'{shlex.quote(script)}')

    def run(self, host: str, argv: Sequence[str], **kwargs) -> subprocess.CompletedProcess:
        """Run ``argv`` inside ``host`` and wait (``subprocess.run`` keywords)."""
        return subprocess.run(self.cmd(host, argv), **kwargs)

    # ------------------------------------------------------------------ the wire
    def link(self, host: str, up: bool) -> None:
        """Unplug (``up=False``) or plug back ``host``'s cable: its veth on the bridge."""
        _ip('link', 'set', self.veths[host], 'up' if up else 'down')

    def cap(self, host: str, rate: Optional[str], burst: str = '32kb',
            latency: str = '200ms') -> None:
        """Cap what ``host`` sends to ``rate`` (``tc tbf``, e.g. '1mbit'); None removes it."""
        ns = self.hosts[host]
        subprocess.run(['tc', '-n', ns, 'qdisc', 'del', 'dev', 'eth0', 'root'],
                       capture_output=True)
        if rate is not None:
            subprocess.run(['tc', '-n', ns, 'qdisc', 'add', 'dev', 'eth0', 'root', 'tbf',
                            'rate', rate, 'burst', burst, 'latency', latency],
                           capture_output=True, text=True, check=True)

    def counters(self, host: str) -> Dict[str, int]:
        """Return bytes and packets ``host`` sent and received on the wire (its ``eth0``)."""
        r = subprocess.run(['ip', '-n', self.hosts[host], '-j', '-s', 'link', 'show', 'dev',
                            'eth0'], capture_output=True, text=True, check=True)
        stats = json.loads(r.stdout)[0]['stats64']
        return {'tx_bytes': stats['tx']['bytes'], 'rx_bytes': stats['rx']['bytes'],
                'tx_packets': stats['tx']['packets'], 'rx_packets': stats['rx']['packets']}

    def all_counters(self) -> Dict[str, Dict[str, int]]:
        """Return ``counters`` of every host."""
        return {h: self.counters(h) for h in self.hosts}

    # ------------------------------------------------------------------ teardown
    def close(self) -> None:
        """Remove every namespace, veth and the bridge (processes inside must be stopped)."""
        for ns in list(self.hosts.values()):
            _ip('netns', 'del', ns, check=False)
        for link in reversed(self._links):
            _ip('link', 'del', link, check=False)
        self.hosts.clear()
        self._links.clear()

    def __enter__(self) -> 'Network':
        """Use as ``with Network(hosts) as net:``."""
        return self

    def __exit__(self, *exc) -> None:
        """Remove everything, whatever happened."""
        self.close()
