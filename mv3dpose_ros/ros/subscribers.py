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
Waiting for subscribers before publishing: which topics to wait for, and saying so meanwhile.

The one rule of the package (``awaited``), used by ``mv3dpose bag play --wait-for-subscribers``,
the demo and the test harness:

- topics named by the caller (``--wait-topics``): exactly those;
- otherwise every topic whose message type has a subscriber on at least one of the topics. One
  camera's ``image_raw`` subscribed stands for every camera's (the other pose nodes are still
  loading their model); ``camera_info`` that no node of the pipeline reads is not waited for.

The wait is over when at least one topic is awaited, each has a subscriber, and this held for
``SETTLE_S`` with the awaited set unchanged: a consumer's endpoints of another type, discovered
a moment later, still join, and the subscribers have time to discover the publisher too (each
side of a DDS match is discovered on its own; a reader that has not seen the writer yet drops
or delays the first messages). ``SubscriberWait`` says what it waits for after
``FIRST_NOTE_S`` and then every ``NOTE_EVERY_S``, and at a timeout names the topics that never
got a subscriber.
"""

import math
import sys
import time
from typing import Callable, Collection, Iterable, List, Mapping, Optional, Sequence

#: How long the awaited topics must all have had a subscriber before the wait ends [s].
SETTLE_S = 1.0
#: The first note about the wait comes after this long [s] (a quick match says nothing) ...
FIRST_NOTE_S = 1.5
#: ... and the next ones this often [s].
NOTE_EVERY_S = 5.0
#: Topic names a note lists at most (then "and N more").
NOTE_TOPICS = 6


def awaited(types: Mapping[str, str], subscribed: Collection[str],
            named: Optional[Sequence[str]] = None) -> List[str]:
    """
    Return the topics of ``types`` (topic -> message type) to wait for (the module's rule).

    ``subscribed`` are the topics that have a subscriber now; ``named``, when given, are the
    topics to wait for whatever is subscribed.
    """
    if named:
        return list(dict.fromkeys(named))
    hit = {types[t] for t in subscribed if t in types}
    return [t for t in types if types[t] in hit]


def unsubscribed(publishers: Iterable) -> List[str]:
    """Return the topics of the rclpy ``publishers`` that have no matched subscriber yet."""
    return [p.topic_name for p in publishers if p.get_subscription_count() == 0]


def _names(topics: Sequence[str]) -> str:
    shown = ', '.join(topics[:NOTE_TOPICS])
    more = len(topics) - NOTE_TOPICS
    return shown + (f' and {more} more' if more > 0 else '')


def _stderr(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


class SubscriberWait:
    """
    Wait until the awaited topics (``awaited``) have subscribers, saying what is missing.

    ``types`` maps each topic that may be waited for to its message type; ``count(topic)``
    returns its subscriber count (a publisher's ``get_subscription_count``: matched readers,
    QoS-compatible ones only); ``named``: the topics to wait for instead of the rule's.
    ``say`` gets each note (stderr by default; None is silent), prefixed by ``prefix``;
    ``hint`` ends the notes: how to start sooner.
    """

    def __init__(self, types: Mapping[str, str], count: Callable[[str], int],
                 named: Optional[Sequence[str]] = None, say: Optional[Callable] = _stderr,
                 prefix: str = '', hint: str = '', settle_s: float = SETTLE_S) -> None:
        """Prepare the wait (nothing is checked before ``wait`` or ``check``)."""
        self.types = dict(types)
        self.count = count
        self.named = list(named) if named else None
        self.say = say
        self.prefix, self.hint, self.settle_s = prefix, hint, settle_s
        self.subscribed: List[str] = []
        self.awaited: List[str] = []
        self.missing: List[str] = []
        self.complete = False

    def check(self) -> bool:
        """Look at the graph once; tell whether every awaited topic (one at least) is matched."""
        topics = list(self.types) + [t for t in self.named or () if t not in self.types]
        self.subscribed = [t for t in topics if self.count(t) > 0]
        self.awaited = awaited(self.types, self.subscribed, self.named)
        self.missing = [t for t in self.awaited if t not in self.subscribed]
        self.complete = bool(self.awaited) and not self.missing
        return self.complete

    def _note(self, text: str) -> None:
        if self.say is not None:
            self.say(f'{self.prefix}{text}')

    def _status(self, left_s: float, others: Sequence[str]) -> str:
        if not self.awaited:
            text = (f'no subscriber yet on any of the {len(self.types)} topics '
                    f'({_names(list(self.types))})')
        elif self.missing:
            text = f'no subscriber yet on {_names(self.missing)}'
        else:
            text = 'every awaited topic has a subscriber'
        if others:
            text += ('; ' if self.missing or not self.awaited else ', but ') + \
                'still waiting for ' + ', '.join(others)
        ignored = [t for t in self.types if t not in self.awaited]
        if self.awaited and ignored and not self.named:
            text += (f'; not waiting for {_names(ignored)} (no subscriber on any topic of '
                     'their type)')
        return f'waiting up to {math.ceil(max(left_s, 0.0)):d} s more: {text}' + (
            f'. {self.hint}' if self.hint else '')

    def wait(self, executor, timeout: float, stopped: Callable[[], bool] = lambda: False,
             also: Optional[Callable[[], List[str]]] = None,
             also_timeout: float = 0.0) -> bool:
        """
        Spin ``executor`` until the awaited topics are matched and settled; return whether.

        Gives up on the subscribers after ``timeout`` s (naming the topics never subscribed).
        ``also()`` lists further things still missing (e.g. ``a publisher on /x``); the wait
        goes on for them up to ``max(timeout, also_timeout)``. Returns True when every awaited
        topic was matched and ``also()`` is empty at the end.
        """
        start = time.monotonic()
        sub_deadline = start + max(timeout, 0.0)
        deadline = start + max(timeout, also_timeout, 0.0)
        next_note = start + FIRST_NOTE_S
        stable_since, stable_set = None, None
        others: List[str] = []
        timed_out = noted = False
        while not stopped():
            now = time.monotonic()
            complete = self.check() if timeout > 0 else True
            others = also() if also is not None else []
            if complete and self.awaited != stable_set:
                stable_since, stable_set = now, list(self.awaited)
            elif not complete:
                stable_since, stable_set = None, None
            settled = timeout <= 0 or (
                stable_since is not None and now - stable_since >= self.settle_s)
            if now >= sub_deadline and not settled and not timed_out:
                timed_out = True
                if not complete:
                    self._timed_out(timeout)
            if (settled or timed_out) and not others:
                if settled and timeout > 0:
                    self._done(now - start, noted)
                break
            if now >= deadline:
                break
            if now >= next_note:
                left = (sub_deadline if not timed_out else deadline) - now
                self._note(self._status(left, others))
                noted = True
                next_note = now + NOTE_EVERY_S
            executor.spin_once(timeout_sec=0.05)
        return (timeout <= 0 or self.complete) and not others

    def _done(self, waited_s: float, noted: bool) -> None:
        ignored = [t for t in self.types if t not in self.awaited]
        if not noted and (self.named or not ignored):
            return
        text = f'{len(self.awaited)} topic(s) subscribed after {waited_s:.1f} s'
        if ignored and not self.named:
            text += (f'; not waiting for {_names(ignored)} (no subscriber on any topic of '
                     'their type)')
        self._note(text)

    def _timed_out(self, timeout: float) -> None:
        if not self.awaited:
            never = list(self.types) + [t for t in self.named or () if t not in self.types]
        else:
            never = self.missing
        self._note(f'no subscriber on {", ".join(never)} after {timeout:g} s; '
                   'going on without them')


__all__ = ['awaited', 'FIRST_NOTE_S', 'NOTE_EVERY_S', 'SETTLE_S', 'SubscriberWait',
           'unsubscribed']
