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
pose2d_node's ``/diagnostics``: one status per camera with its image path figures.

``Pose2DStatus`` keeps the counters and windows the node's image path feeds (input and output
rates, header stamps, inference, whole-path and per-stage latency, rejects) and builds the
status from them, from the mailbox's counts (``pose2d.intake.ImageMailbox``) and from the
values the inference rate and the model in use report. The benches and tests read its keys;
``Pose2DStats`` is the same counts as numbers, for whoever runs the node in-process.
"""

from dataclasses import dataclass
import math
import threading
import time
from typing import Any, Dict, Optional, Tuple

from mv3dpose_ros.core.diagnostic_keys import Pose2DKeys as K
from mv3dpose_ros.pose2d.intake import header_stamp_ns
from mv3dpose_ros.ros.diagnostics import (ERROR, FrequencyStats, level_value, make_status, OK,
                                          TimestampStats, WARN, WindowStats)

#: Per-image stages timed in /diagnostics (medians): capture stamp -> receipt, receipt ->
#: worker start (waiting behind the previous inference), CDR parse + numpy, letterbox,
#: onnxruntime, NMS + inversion, message build + publish.
STAGES = ('transport', 'wait', 'decode', 'pre', 'inference', 'post', 'publish')


@dataclass(frozen=True)
class Pose2DStats:
    """One camera's image counts and inference rate at one moment (``Pose2DNode.stats``)."""

    received: int                #: camera images, counted from the sequence numbers
    taken: int                   #: copied out of DDS
    dropped: int                 #: replaced by a newer image before the model took them
    skipped: int                 #: left out by the inference_rate_hz grid
    processed: int               #: whose persons were published
    failed: int                  #: inference failures
    rejected_encoding: int       #: images of an encoding or size the model cannot take
    rejected_stamp: int          #: images with a zero header stamp
    skips_announced: int         #: SkippedImages sent on persons_2d/skipped
    inference_rate_hz: float     #: the grid rate in use (0: every image; auto: its choice)
    rate_mode: str               #: 'auto', 'fixed' or 'every image'
    waiting_stamp_ns: Optional[int]   #: header stamp of the image waiting for the model


class Pose2DStatus:
    """One camera's image path statistics (``lock`` guards the windows), and its status."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.processed = self.skips_announced = self.people_last = 0
        self.rejected_encoding = self.rejected_stamp = self.failed = 0
        self.in_freq, self.out_freq = FrequencyStats(), FrequencyStats()
        self.stamps = TimestampStats()
        self.infer_ms, self.path_ms = WindowStats(), WindowStats()
        self.stage_ms = {stage: WindowStats() for stage in STAGES}
        self.capture_ms = WindowStats()          # header stamp -> persons_2d published
        self.last_input_ns: Optional[int] = None
        self._rejects_reported = 0

    def stats(self, mailbox: Any, rate: Any) -> Pose2DStats:
        """Return the counts now, with the mailbox's and the inference rate's (``GridRate``)."""
        with mailbox.cv:
            counts = (mailbox.received, mailbox.taken, mailbox.dropped, mailbox.skipped)
            waiting = mailbox.pending
        with self.lock:
            own = (self.processed, self.failed, self.rejected_encoding, self.rejected_stamp,
                   self.skips_announced)
        return Pose2DStats(*counts, *own, rate.hz, rate.mode,
                           None if waiting is None else header_stamp_ns(waiting))

    def received(self, frames: int, now_ns: int) -> None:
        """Count ``frames`` camera images up to one taken at ``now_ns`` (node clock)."""
        self.last_input_ns = now_ns
        with self.lock:
            self.in_freq.tick(frames)

    def stamp(self, stamp_ns: int, now_ns: int) -> None:
        """Record the header stamp of an image about to be processed."""
        with self.lock:
            self.stamps.record(stamp_ns, now_ns)

    def published(self, people: int, timing: Any, marks: Tuple[float, float, float, float],
                  stamp_ns: int, arrived_ns: Optional[int], started_ns: int) -> None:
        """
        Record one image whose persons were published, and the time of each stage.

        ``timing``: the estimator's (pre, inference, post [ms]); ``marks``: ``perf_counter``
        at the start, decoded, inferred and published; ``arrived_ns`` (when DDS received it,
        None when unknown) and ``started_ns`` (the path began) on the wall clock.
        """
        t0, t_decoded, t_inferred, t_end = marks
        capture_ms = (time.time_ns() - stamp_ns) / 1e6
        stages = {'decode': (t_decoded - t0) * 1e3, 'pre': timing.pre_ms,
                  'inference': timing.infer_ms, 'post': timing.post_ms,
                  'publish': (t_end - t_inferred) * 1e3}
        if arrived_ns is not None:
            # Capture stamp -> receipt; meaningful when the camera stamps with this clock.
            stages['transport'] = (arrived_ns - stamp_ns) / 1e6
            stages['wait'] = (started_ns - arrived_ns) / 1e6
        with self.lock:
            self.processed += 1
            self.people_last = people
            self.out_freq.tick()
            self.infer_ms.add(timing.infer_ms)
            self.path_ms.add((t_end - t0) * 1e3)
            for name, ms in stages.items():
                self.stage_ms[name].add(ms)
            self.capture_ms.add(capture_ms)

    def status(self, name: str, camera_id: str, now: int, mailbox: Any,
               rate_values: Dict[str, Any], model_values: Dict[str, Any], timeout_s: float,
               min_rate_hz: float, topic: str, reliability: str) -> Any:
        """
        Return the camera's ``DiagnosticStatus`` at ``now`` (node clock).

        ERROR on bad stamps or new rejects, WARN without input on ``topic`` for ``timeout_s``
        (naming the subscription's ``reliability``) or below ``min_rate_hz``; images dropped
        before inference are named. ``mailbox``: received, taken, dropped and skipped counts.
        """
        with self.lock:
            out_level, out_text, values = self.out_freq.sample(now)
            _, _, in_values = self.in_freq.sample(now)
            ts_level, ts_text, ts_values = self.stamps.sample()
            infer50, infer95 = self.infer_ms.percentile(50), self.infer_ms.percentile(95)
            path50 = self.path_ms.percentile(50)
            stage50 = {K.STAGE_MEDIAN_MS.format(stage): st.percentile(50)
                       for stage, st in self.stage_ms.items()}
            stage50[K.CAPTURE_TO_PUBLISH_MEDIAN_MS] = self.capture_ms.percentile(50)
            stage50[K.CAPTURE_TO_PUBLISH_P95_MS] = self.capture_ms.percentile(95)
        received, dropped = mailbox.received, mailbox.dropped
        values = {'Input frequency (Hz)': in_values['Actual frequency (Hz)'], **values,
                  **ts_values, 'Inference latency median (ms)': infer50,
                  'Inference latency p95 (ms)': infer95, 'Whole path median (ms)': path50,
                  **stage50, K.IMAGES_RECEIVED: received,
                  'Images taken from DDS (copied)': mailbox.taken,
                  'Images processed': self.processed,
                  K.DROPPED_NEWER: dropped,
                  'Skipped (inference_rate_hz grid)': mailbox.skipped,
                  'Skips announced (persons_2d/skipped)': self.skips_announced, **rate_values,
                  'Rejected (encoding/size)': self.rejected_encoding,
                  'Rejected (zero stamp)': self.rejected_stamp, 'Inference failures': self.failed,
                  'People in last image': self.people_last, **model_values}
        level, text = OK, out_text
        rejects = self.rejected_encoding + self.failed
        if level_value(ts_level) >= level_value(ERROR):
            level, text = ERROR, ts_text
        if rejects > self._rejects_reported:
            level, text = ERROR, 'images rejected (see the log for why)'
            self._rejects_reported = rejects
        elif self.last_input_ns is None or now - self.last_input_ns > timeout_s * 1e9:
            if level_value(level) < level_value(WARN):
                level = WARN
                text = (f'no input on {topic} for {timeout_s:g} s (check the remapping, and the '
                        f'QoS: the publisher must be compatible with {reliability})')
        elif (min_rate_hz > 0 and math.isfinite(values['Actual frequency (Hz)'])
              and values['Actual frequency (Hz)'] < min_rate_hz
              and level_value(level) == level_value(OK)):
            level, text = WARN, f'output rate below {min_rate_hz:g} Hz'
        elif dropped and level_value(level) == level_value(OK):
            share = 100.0 * dropped / max(1, received)
            text = (f'{out_text}; inference slower than the input: {dropped} of {received} '
                    f'images ({share:.0f} %) dropped before inference, newest kept')
        return make_status(name, level, text, hardware_id=camera_id, values=values)
