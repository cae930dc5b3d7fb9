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
fusion_node's ``/diagnostics``: camera inputs, synchroniser, tracking, calibration, clock.

One status per camera input, then the synchroniser, tracking, calibration and clock ones,
with the figures the node's tests and the benches read, and one per camera of the calibration
watch (``core.selfcal.watch``: OK / WARN / ERROR, drift, reprojection residual).

``FusionStatus`` reads the node's live core (``core.live.loop.LiveFusion``), its per-camera input
statistics (``.inputs.CameraInputStats``) and the output windows it keeps (latency,
processing, output rate); a WARN names what changed since the previous cycle.
"""

from collections import Counter
import math
from typing import Any, Callable, Dict, List, Sequence, Tuple

from mv3dpose_ros.core.diagnostic_keys import FusionKeys as K, FusionStatusNames as N
from mv3dpose_ros.core.live.loop import LiveFusion
from mv3dpose_ros.core.types import NS_PER_S, TrackState
from mv3dpose_ros.nodes.fusion.inputs import CameraInputStats
from mv3dpose_ros.ros.diagnostics import (ERROR, FrequencyStats, level_value, make_status, OK,
                                          WARN, WindowStats)


class FusionStatus:
    """Build fusion_node's diagnostic statuses; keeps the latency and rate windows."""

    def __init__(self, live: LiveFusion, cams: Dict[str, CameraInputStats],
                 camera_ids: Sequence[str], rig_path: str, name: Callable[[str], str],
                 start_ns: int, clock_ns: int) -> None:
        self.live, self.cams, self.camera_ids = live, cams, tuple(camera_ids)
        self.rig_path, self.name, self._start_ns = rig_path, name, start_ns
        self.latency = WindowStats()           # capture stamp -> ~/tracks publish [s]
        self.processing = WindowStats()        # Fusion.step per set [s]
        self.output_rate = FrequencyStats()
        self._drops_reported: Dict[str, int] = {}
        self._clock_seen: Tuple[int, int] = (clock_ns, start_ns)  # node clock, steady at change

    def _expected_rate_hz(self, cam: str) -> float:
        """Rate a camera should deliver: its own usual rate, or the rig's if that is higher."""
        stats = self.live.sync.stats
        usual = [r for r in (stats[c].usual_rate_hz for c in self.camera_ids)
                 if math.isfinite(r)]
        own = stats[cam].usual_rate_hz
        rig = sorted(usual)[len(usual) // 2] if usual else math.nan
        return max((r for r in (own, rig) if math.isfinite(r)), default=math.nan)

    def inputs(self, now: int, expected_rate_hz: float, silent_warn_ns: int) -> List[Any]:
        """Return one status per camera input (steady clock ``now``)."""
        out = []
        offsets = self.live.clocks.offsets.offsets_s()
        for cam in self.camera_ids:
            st = self.cams[cam]
            ss = self.live.sync.stats[cam]
            rate = st.freq
            rate.min_hz = expected_rate_hz
            rate.max_hz = expected_rate_hz if expected_rate_hz > 0 else math.inf
            f_level, f_msg, values = rate.sample(now)
            t_level, t_msg, t_values = st.stamps.sample()
            expected = self._expected_rate_hz(cam)
            values = {'topic': st.topic, **values, **t_values,
                      'rate from stamps (Hz)': ss.rate_hz,
                      'expected rate (Hz)': expected,
                      'lost upstream (stamp gaps)': ss.lost,
                      'skipped by pose2d (announced gaps)': ss.skipped,
                      K.RECEIVED: st.received, 'accepted': st.accepted,
                      'used in sets': ss.used, K.DROPPED_BY_SYNC: ss.dropped,
                      'late': ss.late, 'late, used (tracks updated at its stamp)':
                          st.late_used, 'outlier stamps': ss.outliers,
                      'missing from sets': ss.missing,
                      'skip notices (persons_2d/skipped)': st.skips,
                      'skip notices rejected': st.skips_rejected,
                      'offset mean (ms)': ss.offset_mean_s * 1e3,
                      'offset jitter (ms)': ss.offset_jitter_s * 1e3,
                      K.STAMP_OFFSET_MS: self.live.clocks.suspects.get(
                          cam, offsets.get(cam, math.nan)) * 1e3}
            for reason, n in sorted(ss.unmatched.items()):
                values[f'dropped by sync: {reason}'] = n
            for reason, n in sorted(st.rejected.items()):
                values[f'rejected: {reason}'] = n
            level, message = OK, 'receiving'
            since = now - (st.last_rx_ns if st.last_rx_ns is not None else self._start_ns)
            new_lost = ss.lost - st.lost_reported
            st.lost_reported = ss.lost
            if since > silent_warn_ns:
                level = WARN
                message = f'no input on {st.topic} for {since / NS_PER_S:.1f} s'
            elif st.calibration_problem:
                level, message = ERROR, st.calibration_problem
            elif level_value(t_level) > level_value(OK):
                level, message = t_level, t_msg
            elif cam in self.live.clocks.suspects:
                level = WARN
                message = (f'stamps {self.live.clocks.suspects[cam] * 1e3:+.1f} ms off the rest '
                           'of the rig (host clock? chrony / PTP)')
            elif level_value(f_level) > level_value(OK) and expected_rate_hz > 0:
                level, message = f_level, f_msg
            elif ss.rate_hz < 0.75 * expected:
                level, message = WARN, (f'{ss.rate_hz:.1f} Hz from the stamps, below the '
                                        f'usual {expected:.1f} Hz')
            new = st.rejected - st.rejected_reported
            st.rejected_reported = Counter(st.rejected)
            if level == OK and new:
                level = WARN
                message = 'dropped ' + ', '.join(f'{n} {r}' for r, n in sorted(new.items()))
            if level == OK and new_lost > 0:
                level = WARN
                message = (f'{new_lost} frames lost upstream (gaps in the stamps: '
                           'publisher, network or DDS queue)')
            out.append(make_status(self.name(cam + N.INPUT_SUFFIX), level, message,
                                   hardware_id=cam, values=values))
        return out

    def pipeline(self, now: int) -> List[Any]:
        """Return the synchroniser, tracking and calibration statuses."""
        s, cams, ids = self.live.sync, self.cams, self.camera_ids
        stats = [s.stats[c] for c in ids]
        counts = self.live.counts
        drops = {
            'lost upstream (stamp gaps)': sum(x.lost for x in stats),
            'dropped at input (validation)': sum(
                n for c in ids for r, n in cams[c].rejected.items() if r != 'late'),
            'dropped in sync: late': sum(x.late for x in stats) - sum(
                cams[c].late_used for c in ids),
            'dropped in sync: outlier stamps': sum(x.outliers for x in stats),
            'dropped in sync: too few views': sum(x.unmatched['too_few_views'] for x in stats),
            'dropped in sync: duplicates': sum(x.unmatched['duplicates'] for x in stats),
            'sets decided early (queue full)': s.counts.overflow_decisions}
        new = {k: v - self._drops_reported.get(k, 0) for k, v in drops.items()}
        self._drops_reported = drops
        sc = s.counts
        values = {K.SETS_EMITTED: sc.sets_emitted, K.PARTIAL_SETS: sc.partial_sets,
                  'incomplete sets decided on skip notices': sc.decisions['skipped (announced)'],
                  'pivots dropped (too few views)': sc.pivots_dropped,
                  'pending messages': s.pending(), 'held outlier messages': s.held_outliers,
                  'slop (ms)': s.slop_ns / 1e6,
                  'max_wait in use (ms)': s.max_wait_ns / 1e6,
                  'arrival spread p95 (ms)': s.spread_p95_s * 1e3,
                  'frame period (ms)': (s.frame_period_ns or math.nan) / 1e6,
                  'resets': counts['resets'],
                  'forward jumps (no reset)': sc.forward_jumps,
                  'idle steps (no input)': counts['idle_steps'], **drops}
        changed = {k: v for k, v in new.items() if v > 0}
        level = WARN if changed else OK
        message = f'{sc.sets_emitted} sets, {sc.partial_sets} partial'
        if changed:
            message += '; this cycle: ' + ', '.join(f'{v} {k}' for k, v in changed.items())
        sync_status = make_status(self.name(N.SYNCHRONIZER), level, message, values=values)
        tracks = self.live.last_tracks
        states = Counter(TrackState(t.state).name.lower() for t in tracks)
        f_level, f_msg, rate = self.output_rate.sample(now)
        values = {'active tracks': len(tracks),
                  'confirmed tracks': states.get('confirmed', 0),
                  'coasting tracks': states.get('coasting', 0),
                  'tentative tracks': states.get('tentative', 0),
                  'output frequency (Hz)': rate['Actual frequency (Hz)'],
                  K.LATENCY_MEDIAN_MS: self.latency.percentile(50) * 1e3,
                  K.LATENCY_P95_MS: self.latency.percentile(95) * 1e3,
                  K.PROCESSING_MEDIAN_MS: self.processing.percentile(50) * 1e3,
                  K.PROCESSING_P95_MS: self.processing.percentile(95) * 1e3,
                  'processing max (ms)': self.processing.percentile(100) * 1e3,
                  'fusion errors': counts['fusion_errors']}
        fusion = self.live.fusion
        if fusion is not None:
            fc = fusion.counts
            values.update({
                'tracks updated by single views': fc['view_updates'],
                'late messages used': fc['late_views_used'],
                'tracks recovered after a gap': fc['recovered'],
                'duplicate tracks merged': fc['merged_tracks']})
        level, message = OK, f'{len(tracks)} tracks'
        if fusion is None:
            level, message = WARN, 'waiting for calibration (CameraInfo)'
        elif counts['fusion_errors']:
            level, message = WARN, f'{counts["fusion_errors"]} fusion errors'
        track_status = make_status(self.name(N.TRACKING), level, message, values=values)
        problems = {c: cams[c].calibration_problem for c in ids if cams[c].calibration_problem}
        calib = make_status(
            self.name('calibration'), ERROR if problems else OK,
            '; '.join(f'{c}: {p}' for c, p in problems.items()) or
            f'{len(ids)} cameras from {self.rig_path}',
            values={'rig_config': self.rig_path, **{f'{c} problem': p
                                                    for c, p in problems.items()}})
        return [sync_status, track_status, calib] + self.watch()

    def watch(self) -> List[Any]:
        """Return one status per camera: how its pose agrees with the rig's people."""
        watch = self.live.watch
        if not watch.enabled or not watch.names:
            return []
        levels = {'OK': OK, 'WARN': WARN, 'ERROR': ERROR}
        out = []
        for cam in watch.names:
            st = watch.status[cam]
            if not math.isfinite(st.drift_deg):
                message = (f'learning its baseline ({st.points} joints in the window)'
                           if st.points else 'no person seen with the others yet')
            elif st.named:
                message = (f'turned {st.drift_deg:.2f} deg since its baseline ('
                           f'{watch.config.mode}: ' + ('left out' if cam in watch.excluded()
                                                       else 'named') + ')')
            else:
                message = f'agrees with the rig (drift {st.drift_deg:.2f} deg)'
            out.append(make_status(
                self.name(f'{cam} calibration watch'), levels[st.level], message,
                hardware_id=cam, values={
                    'calibration': st.level, 'mode': watch.config.mode,
                    'drift (deg)': st.drift_deg,
                    'drift about x, y, z (deg)': ', '.join(f'{v:.2f}'
                                                           for v in st.drift_axis_deg),
                    'drift threshold (deg)': st.threshold_deg,
                    'residual median (px)': st.residual_px,
                    'baseline residual median (px)': st.baseline_residual_px,
                    'joints in window': st.points, 'corrections': st.corrections}))
        return out

    def clock(self, node_now: int, steady: int, sim: bool, stall_ns: int) -> Any:
        """Node clock status: under use_sim_time, ERROR naming /clock when it stopped."""
        if node_now != self._clock_seen[0]:
            self._clock_seen = (node_now, steady)
        stalled = (steady - self._clock_seen[1]) / NS_PER_S
        values = {'use_sim_time': sim, 'node clock (s)': node_now / NS_PER_S,
                  'unchanged for (s, steady clock)': stalled}
        name = self.name(N.CLOCK)
        if not sim:
            return make_status(name, OK, 'system clock', values=values)
        if node_now == 0:
            return make_status(name, ERROR, f'no /clock received for {stalled:.1f} s '
                               '(use_sim_time is true: start the bag player with --clock)',
                               values=values)
        if stalled * NS_PER_S > stall_ns:
            return make_status(name, ERROR, f'/clock stalled at {node_now / NS_PER_S:.3f} s '
                               f'for {stalled:.1f} s: sim time does not advance (player paused '
                               'or gone), so inputs are judged against a stopped clock',
                               values=values)
        return make_status(name, OK, '/clock advancing', values=values)
