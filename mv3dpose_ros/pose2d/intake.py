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
How a camera's images reach the model: the mailbox and the inference thread (no ROS here).

Only the newest image is inferred. ``ImageMailbox`` holds it and counts what became of the
others (replaced while the model was busy: dropped; outside the ``inference_rate_hz`` grid:
skipped); ``InferenceThread`` runs the model on it and, when none waits, takes the next image
from DDS itself (the node passes how), so images the grid skips or that a newer one replaces
are never copied out of DDS's shared memory. The node supplies the ROS parts as callables.
"""

from collections import deque
import os
import struct
import threading
import time
from typing import Any, Callable, Deque, Dict, Optional, Tuple

from mv3dpose_ros.core.types import NS_PER_S
from mv3dpose_ros.pose2d.auto_rate import GridRate
from mv3dpose_ros.pose2d.scheduling import (doze_s, frame_period_ns, grid_period_ns, grid_selects,
                                            missed_windows, on_new_window)

_STAMP = {True: struct.Struct('<iI'), False: struct.Struct('>iI')}


def header_stamp_ns(msg: Any) -> Optional[int]:
    """
    Return the header stamp of an image message or of its serialised CDR bytes.

    In CDR the stamp follows the 4-byte encapsulation header (byte 1 = 1: little endian), so
    the raw subscription reads it without parsing the image. None when too short.
    """
    if isinstance(msg, (bytes, bytearray, memoryview)):
        buf = memoryview(msg)
        if len(buf) < 12:
            return None
        sec, nanosec = _STAMP[buf[1] == 1].unpack_from(buf, 4)
        return sec * NS_PER_S + nanosec
    return int(msg.header.stamp.sec) * NS_PER_S + int(msg.header.stamp.nanosec)


def skipped_before(last_seq: Optional[int], last_stamp: int, seq: Optional[int],
                   stamp: int) -> bool:
    """
    Tell whether no persons will come for images before this one (``seq``, ``stamp``).

    True when it does not follow the last image published (``last_seq``, ``last_stamp``) by
    the camera's publication sequence numbers: the ones between were replaced while the model
    was busy, skipped by the grid, rejected or failed, and the fusion node need not wait for
    them. Never without sequence numbers, nor for an image not newer than the last published.
    """
    return seq is not None and (last_seq is None or seq != last_seq + 1) and stamp > last_stamp


class ImageMailbox:
    """
    The newest image of one camera, waiting for the inference thread, and the fate of the rest.

    ``offer`` keeps only the newest image (the one it replaces counts as dropped); on a grid
    (``rate``, see ``scheduling``) only the first image of each window of header stamps: the
    camera's other images count as skipped, those of a window none of whose images was taken
    as dropped. It feeds ``rate.auto`` the stamps and the images replaced. ``cv`` guards the
    mailbox (``rate`` has its own lock, taken after it).
    """

    def __init__(self, rate: GridRate) -> None:
        self.cv = threading.Condition()
        self.rate = rate
        self.pending: Any = None              # the newest image (message or CDR bytes)
        self.pending_arrived_ns = 0            # when it arrived (wall clock)
        self.pending_seq: Optional[int] = None  # its publication sequence number (DDS)
        self.closed = False                    # no inference thread may take from it
        self.grid_stamp: Optional[int] = None  # stamp of the image that opened the window
        self.last_seq: Optional[int] = None    # publication sequence number of the last take
        #: images taken: (arrival wall ns, stamp ns, camera images since the one before)
        self.takes: Deque[Tuple[int, int, int]] = deque(maxlen=32)
        self.received = self.taken = self.dropped = self.skipped = 0

    def start(self) -> None:
        """Let an inference thread take images (again); forget the last sequence number."""
        with self.cv:
            self.closed, self.last_seq = False, None

    def close(self) -> None:
        """Empty the mailbox and tell the inference thread to stop."""
        with self.cv:
            self.closed, self.pending = True, None
            self.cv.notify_all()

    def arrival(self, info: Any) -> Tuple[int, Optional[int], Optional[int]]:
        """
        Return (camera images since the last take, arrival wall ns, sequence number).

        From a raw take's message info (a dict; missing fields: 1 image, None, None). A jump of
        the sequence numbers of 100000 or more, or back, is a new publisher: one image.
        """
        info = info if isinstance(info, dict) else {}
        seq = info.get('publication_sequence_number')
        seq = seq if isinstance(seq, int) and seq > 0 else None
        frames = 1
        if seq is not None:
            last, self.last_seq = self.last_seq, seq
            if last is not None and 0 < seq - last < 100_000:
                frames = seq - last
        received = info.get('received_timestamp')
        return frames, received if isinstance(received, int) and received > 0 else None, seq

    def offer(self, msg: Any, frames: int, arrived_ns: int, seq: Optional[int],
              now_s: float) -> bool:
        """
        Keep ``msg`` as the newest image unless the grid skips it; count the ones before it.

        ``frames``: images the camera published since the last one taken (the ones between
        were never taken); ``arrived_ns``: when DDS received it (wall clock); ``seq``: its
        publication sequence number (None when DDS gives none); ``now_s``: steady clock.
        """
        untaken = max(0, frames - 1)
        with self.cv, self.rate.lock:
            stamp = header_stamp_ns(msg)
            auto = self.rate.auto
            if stamp is not None and stamp > 0:
                if auto is not None:
                    auto.add_stamp(stamp, frames, now_s)
                self.takes.append((arrived_ns, stamp, frames))
            self.received += frames
            self.taken += 1
            if grid_selects(self.rate.hz, frame_period_ns(self.takes)):
                period = grid_period_ns(self.rate.hz)
                missed = missed_windows(stamp, self.grid_stamp, untaken, period)
                self.skipped += untaken - missed
                self.dropped += missed
                if stamp is not None and stamp > 0:   # else rejected later, with the reason
                    if not on_new_window(stamp, self.grid_stamp, period):
                        self.skipped += 1             # same window, or slightly out of order
                        return False
                    self.grid_stamp = stamp
            else:
                self.dropped += untaken
                if auto is not None and untaken:
                    auto.add_replaced(untaken, now_s)
            if self.pending is not None:
                self.dropped += 1
                if auto is not None:
                    auto.add_replaced(1, now_s)
            self.pending, self.pending_arrived_ns, self.pending_seq = msg, arrived_ns, seq
            self.cv.notify()
            return True

    def pop(self) -> Optional[Tuple[Any, int, Optional[int]]]:
        """Return and remove the newest image, its arrival and sequence number (None: none)."""
        with self.cv:
            msg, self.pending = self.pending, None
            return None if msg is None else (msg, self.pending_arrived_ns, self.pending_seq)

    def wait(self, timeout_s: float) -> None:
        """Wait up to ``timeout_s`` for an image (or for ``close``)."""
        with self.cv:
            if not self.closed:
                self.cv.wait(timeout_s)

    def doze_s(self, now_ns: Optional[int] = None) -> float:
        """Return how long the inference thread may wait before taking (``scheduling``)."""
        with self.cv:
            rate, last, takes = self.rate.hz, self.grid_stamp, list(self.takes)
        return doze_s(rate, last, takes, time.time_ns() if now_ns is None else now_ns)

    def rate_values(self, now_s: Optional[float] = None) -> Dict[str, Any]:
        """Return the /diagnostics values of the inference rate (``GridRate.values``)."""
        with self.cv:
            frame_ns = frame_period_ns(self.takes)
        return self.rate.values(frame_ns, time.monotonic() if now_s is None else now_s)

    def rate_label(self) -> Any:
        """Return the grid rate in use for /diagnostics, or what replaces it."""
        return self.rate_values()['Inference rate (Hz)']


class InferenceThread(threading.Thread):
    """
    The thread that runs the model on the newest image, at a lower CPU priority (``nice``).

    When the mailbox is empty it dozes until the grid's next window is due, else calls
    ``take(timeout_s)`` (the node spins its intake once; False: no intake, so it waits on the
    mailbox). ``process(msg, arrived_ns, seq)`` runs the node's path and returns None when
    nothing was published, else ``done(seconds)`` hears how long it took (auto mode learns
    from it); ``report(what, exc)`` hears of 'nice' not applied, an 'intake' take that failed
    and an image whose inference 'failed' (one bad image never stops the thread).
    """

    def __init__(self, mailbox: ImageMailbox, name: str, nice: int,
                 take: Callable[[float], bool], process: Callable[[Any, int, Optional[int]], Any],
                 done: Callable[[float], None],
                 report: Callable[[str, BaseException], None]) -> None:
        super().__init__(name=name, daemon=True)
        self.mailbox, self.nice = mailbox, nice
        self._take, self._process, self._done, self._report = take, process, done, report

    def run(self) -> None:
        """Take and process images until the mailbox is closed."""
        if self.nice > 0 and hasattr(os, 'setpriority'):
            # Only this thread (and onnxruntime's work in it, with 1 intra-op thread): DDS
            # receipt, publishing and the fusion node then get a shared CPU first.
            try:
                os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), self.nice)
            except OSError as exc:
                self._report('nice', exc)
        while True:
            with self.mailbox.cv:
                if self.mailbox.closed:
                    return
                item = self.mailbox.pop()
            if item is None:
                self._wait_for_image()
                continue
            t0 = time.monotonic()
            try:
                out = self._process(*item)
            except Exception as exc:  # noqa: B902 - one bad frame must never stop the node
                self._report('failed', exc)
                continue
            if out is not None:
                self._done(time.monotonic() - t0)

    def _wait_for_image(self) -> None:
        """Doze until the next window is due, or take an image (waiting up to 0.1 s)."""
        doze = self.mailbox.doze_s(time.time_ns())
        if doze > 0.002:
            self.mailbox.wait(min(doze, 1.0))
            return
        try:
            if not self._take(0.1):
                self.mailbox.wait(0.1)
        except Exception as exc:  # noqa: B902 - e.g. shut down while deactivating
            if self.mailbox.closed:
                return
            self._report('intake', exc)
            time.sleep(0.1)
