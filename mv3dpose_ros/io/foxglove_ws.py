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
A minimal client of the Foxglove WebSocket protocol that decodes with the advertised schemas.

It speaks what the Foxglove app speaks to ``foxglove_view`` (subprotocol ``foxglove.sdk.v1``;
JSON ``serverInfo`` / ``advertise`` / ``subscribe``, binary ``MessageData`` frames: opcode 1,
uint32 subscription id, uint64 log time, payload), and decodes every payload from the schema the
server advertised alone, as a client without this package would:

- ``protobuf`` schemas (a base64 ``FileDescriptorSet``) with ``google.protobuf``;
- ``ros2msg`` schemas (the concatenated ``.msg`` definitions) with ``cdr`` messages by a
  ``rosbags`` typestore built from that text only;
- ``jsonschema`` / ``json`` with ``json``.

Used by the tests and from the command line to check a running server and draw what it sends::

    python -m mv3dpose_ros.io.foxglove_ws ws://127.0.0.1:8765 --seconds 3 --png scene.png
"""

import argparse
import asyncio
import base64
from dataclasses import dataclass
import json
import struct
import sys
import time
from typing import Any, Callable, Dict, List, Optional, Sequence

SUBPROTOCOL = 'foxglove.sdk.v1'
MESSAGE_DATA = 1
_HEADER = struct.Struct('<BIQ')


class ProtocolError(RuntimeError):
    """The server broke the protocol or a payload does not decode with its schema."""


@dataclass
class Received:
    """One message: topic, schema name, log time and arrival [ns], payload, decoded value."""

    topic: str
    schema_name: str
    log_time: int
    payload: bytes
    decoded: Any
    received_ns: int = 0           # wall clock (time.time_ns) when the frame arrived


def _protobuf_decoder(name: str, schema_b64: str) -> Callable[[bytes], Any]:
    from google.protobuf import descriptor_pb2, descriptor_pool, json_format, message_factory
    fds = descriptor_pb2.FileDescriptorSet.FromString(base64.b64decode(schema_b64))
    pool = descriptor_pool.DescriptorPool()
    for fd in fds.file:
        pool.Add(fd)
    cls = message_factory.GetMessageClass(pool.FindMessageTypeByName(name))

    def decode(payload: bytes) -> Any:
        return json_format.MessageToDict(cls.FromString(payload),
                                         preserving_proto_field_name=True)
    return decode


def _ros2msg_decoder(name: str, schema: str) -> Callable[[bytes], Any]:
    from rosbags.typesys import get_types_from_msg, get_typestore, Stores
    store = get_typestore(Stores.EMPTY)
    types: Dict[str, Any] = {}
    blocks = schema.split('\n' + '=' * 80 + '\n')
    for i, block in enumerate(blocks):
        typename = name
        if i > 0:
            first, _, block = block.partition('\n')
            if not first.startswith('MSG: '):
                raise ProtocolError(f'ros2msg schema {name}: block {i} does not start with MSG:')
            pkg, _, msg = first[5:].strip().partition('/')
            typename = f'{pkg}/msg/{msg}'
        types.update(get_types_from_msg(block, typename))
    store.register(types)

    def decode(payload: bytes) -> Any:
        return store.deserialize_cdr(payload, name)
    return decode


def decoder(channel: Dict[str, Any]) -> Callable[[bytes], Any]:
    """Return the payload decoder of an advertised channel (ProtocolError if unsupported)."""
    enc, schema_enc = channel.get('encoding'), channel.get('schemaEncoding')
    name, schema = channel.get('schemaName', ''), channel.get('schema', '')
    if enc == 'protobuf' and schema_enc == 'protobuf':
        return _protobuf_decoder(name, schema)
    if enc == 'cdr' and schema_enc == 'ros2msg':
        return _ros2msg_decoder(name, schema)
    if enc == 'json':
        return lambda payload: json.loads(payload)
    raise ProtocolError(f'channel {channel.get("topic")}: encoding {enc!r} with schema '
                        f'encoding {schema_enc!r} is not supported by this client')


class FoxgloveClient:
    """An asyncio client: connect, learn the channels, subscribe, receive decoded messages."""

    def __init__(self, url: str) -> None:
        self.url = url
        self.server_info: Dict[str, Any] = {}
        self.channels: Dict[int, Dict[str, Any]] = {}       # id -> advertised channel
        self.advertisements: List[List[str]] = []            # the topics of each advertise
        self.statuses: List[Dict[str, Any]] = []             # the server's status messages
        self._subscriptions: Dict[int, int] = {}            # subscription id -> channel id
        self._decoders: Dict[int, Callable[[bytes], Any]] = {}
        self._ws = None

    async def __aenter__(self) -> 'FoxgloveClient':
        """Connect with the Foxglove subprotocol."""
        import websockets
        self._ws = await websockets.connect(self.url, subprotocols=[SUBPROTOCOL],
                                            max_size=None)
        return self

    async def __aexit__(self, *exc: Any) -> None:
        """Close the connection."""
        await self._ws.close()

    def _control(self, text: str) -> None:
        msg = json.loads(text)
        op = msg.get('op')
        if op == 'serverInfo':
            self.server_info = msg
        elif op == 'advertise':
            for ch in msg['channels']:
                self.channels[int(ch['id'])] = ch
            self.advertisements.append([ch['topic'] for ch in msg['channels']])
        elif op == 'status':
            self.statuses.append(msg)
        elif op == 'unadvertise':
            for cid in msg['channelIds']:
                self.channels.pop(int(cid), None)

    def topics(self) -> Dict[str, Dict[str, Any]]:
        """Return the advertised channels by topic."""
        return {ch['topic']: ch for ch in self.channels.values()}

    async def wait_for_topics(self, topics: Sequence[str], timeout: float) -> None:
        """Read control messages until every topic is advertised (ProtocolError on timeout)."""
        deadline = time.monotonic() + timeout
        while not set(topics) <= set(self.topics()):
            left = deadline - time.monotonic()
            if left <= 0:
                raise ProtocolError(f'not advertised within {timeout} s: '
                                    f'{sorted(set(topics) - set(self.topics()))} (advertised: '
                                    f'{sorted(self.topics())})')
            try:
                frame = await asyncio.wait_for(self._ws.recv(), left)
            except asyncio.TimeoutError:
                continue
            if isinstance(frame, str):
                self._control(frame)

    async def subscribe(self, topics: Sequence[str]) -> None:
        """Subscribe to advertised topics; their decoders are built from the schemas now."""
        subs = []
        by_topic = self.topics()
        for topic in topics:
            ch = by_topic[topic]
            sid = len(self._subscriptions) + 1
            self._subscriptions[sid] = int(ch['id'])
            self._decoders[sid] = decoder(ch)
            subs.append({'id': sid, 'channelId': int(ch['id'])})
        await self._ws.send(json.dumps({'op': 'subscribe', 'subscriptions': subs}))

    async def receive(self, seconds: float,
                      until: Optional[Callable[[List[Received]], bool]] = None
                      ) -> List[Received]:
        """Collect decoded messages for ``seconds`` (or until ``until(messages)`` holds)."""
        out: List[Received] = []
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline and not (until and until(out)):
            try:
                frame = await asyncio.wait_for(self._ws.recv(), deadline - time.monotonic())
            except asyncio.TimeoutError:
                break
            arrived = time.time_ns()
            if isinstance(frame, str):
                self._control(frame)
                continue
            if not frame or frame[0] != MESSAGE_DATA:
                continue
            if len(frame) < _HEADER.size:
                raise ProtocolError(f'MessageData frame of {len(frame)} bytes')
            _, sid, log_time = _HEADER.unpack_from(frame)
            if sid not in self._subscriptions:
                raise ProtocolError(f'message for unknown subscription {sid}')
            ch = self.channels[self._subscriptions[sid]]
            payload = bytes(frame[_HEADER.size:])
            try:
                value = self._decoders[sid](payload)
            except Exception as exc:  # noqa: B902 - decoders raise many types
                raise ProtocolError(f'{ch["topic"]}: payload of {len(payload)} bytes does not '
                                    f'decode with schema {ch["schemaName"]}: {exc}') from exc
            out.append(Received(ch['topic'], ch['schemaName'], log_time, payload, value,
                                arrived))
        return out


def record(url: str, topics: Optional[Sequence[str]], seconds: float,
           wait_s: float = 10.0) -> Dict[str, List[Received]]:
    """Connect, subscribe to ``topics`` (None = all advertised), return messages per topic."""
    async def run() -> Dict[str, List[Received]]:
        async with FoxgloveClient(url) as client:
            await client.wait_for_topics(topics or [], wait_s)
            if topics is None:
                await client.receive(0.5)            # let the advertisements arrive
            chosen = list(topics) if topics is not None else sorted(client.topics())
            await client.subscribe(chosen)
            got = await client.receive(seconds)
            out: Dict[str, List[Received]] = {t: [] for t in chosen}
            for m in got:
                out[m.topic].append(m)
            return out
    return asyncio.run(run())


@dataclass
class StartupWatch:
    """What one client saw of a server it was waiting for (``watch_startup``)."""

    advertisements: List[List[str]]      # the topics of each ``advertise``, in order
    subscribed: List[str]                # every topic subscribed, at its advertisement
    received: Dict[str, int]             # messages per subscribed topic
    errors: List[str]                    # the server's warning/error status messages


async def watch_startup(url: str, seconds: float, connect_timeout: float = 60.0
                        ) -> StartupWatch:
    """
    Connect the moment ``url`` accepts and subscribe to each channel as it is advertised.

    This is what the Foxglove app does when it reconnects to a restarting server: a
    subscription that reaches the server between a channel's advertisement and its
    registration is refused ("Unknown channel ID", a status message) and silently lost.
    """
    deadline = time.monotonic() + connect_timeout
    while True:
        client = FoxgloveClient(url)
        try:
            await client.__aenter__()
            break
        except Exception as exc:  # noqa: B902 - refused, reset, or a handshake cut short
            if time.monotonic() > deadline:
                raise ProtocolError(f'{url}: no server within {connect_timeout} s: {exc}')
            await asyncio.sleep(0.01)
    subscribed: List[str] = []
    received: Dict[str, int] = {}
    try:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            new = [t for t in sorted(client.topics()) if t not in received]
            if new:
                await client.subscribe(new)
                subscribed += new
                received.update(dict.fromkeys(new, 0))
            for m in await client.receive(0.02):
                received[m.topic] += 1
    finally:
        await client.__aexit__()
    errors = [str(m.get('message')) for m in client.statuses if int(m.get('level', 0)) >= 1]
    return StartupWatch(client.advertisements, subscribed, received, errors)


def main(argv: Optional[List[str]] = None) -> int:
    """Print what a Foxglove server sends; optionally draw its 3D scene."""
    parser = argparse.ArgumentParser(prog='python -m mv3dpose_ros.io.foxglove_ws',
                                     description=main.__doc__)
    parser.add_argument('url', nargs='?', default='ws://127.0.0.1:8765')
    parser.add_argument('--seconds', type=float, default=3.0)
    parser.add_argument('--png', help='draw the received SceneUpdate channels into this file')
    args = parser.parse_args(argv)
    try:
        got = record(args.url, None, args.seconds)
    except (OSError, ProtocolError) as exc:
        print(f'foxglove_ws: {args.url}: {exc}', file=sys.stderr)
        return 1
    for topic, msgs in got.items():
        schema = msgs[0].schema_name if msgs else '-'
        print(f'{topic:40s} {len(msgs):5d} messages  {schema}')
    if args.png:
        from mv3dpose_ros.viz.pictures import write_png
        from mv3dpose_ros.viz.scene import latest_entities, render_scene
        updates = [m.decoded for msgs in got.values() for m in msgs
                   if m.schema_name == 'foxglove.SceneUpdate']
        write_png(render_scene(latest_entities(updates),
                               f'received from {args.url}'), args.png)
        print(f'wrote {args.png}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
