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
The parts pose2d_node is wired from, without a node: config, mailbox, thread, rates, sizes.

The node's DDS tests (``test_pose2d_node``, ``_model``, ``_rate``) run them together; these
pin each part's own behaviour: the parameter table the config declares, what the mailbox
counts and when it dozes, the inference thread's loop, the rate in use with a rig, auto mode's
steps along the size ladder, and the estimator cache on crafted ONNX files.
"""

import os
import threading
import time

from mv3dpose_ros.pose2d import models
from mv3dpose_ros.pose2d.auto_rate import GridRate, RIG_RATE_TTL_S
from mv3dpose_ros.pose2d.config import ModelConfig, parameter_error, Pose2DConfig
from mv3dpose_ros.pose2d.estimator import open_estimator
from mv3dpose_ros.pose2d.intake import (header_stamp_ns, ImageMailbox, InferenceThread,
                                        skipped_before)
from mv3dpose_ros.pose2d.scheduling import (AUTO_RATES_HZ, doze_s, frame_period_ns,
                                            missed_windows, parse_inference_rate)
from mv3dpose_ros.pose2d.sizing import EstimatorCache
import numpy as np
from pose2d_models import fake_cache   # crafted yolo11n-pose files in a cache
import pytest

NS = 1_000_000_000
MS = 1_000_000


def _cdr(stamp_ns, little=True):
    """Return the first bytes of a serialised Image: encapsulation header, then the stamp."""
    order = '<' if little else '>'
    return bytes([0, 1 if little else 0, 0, 0]) + np.array(
        [stamp_ns // NS, stamp_ns % NS], dtype=f'{order}i4').tobytes() + b'\0' * 8


# -- config ---------------------------------------------------------------------------------------
def test_config_declares_every_parameter_with_its_comment_and_dynamic_flag():
    from mv3dpose_ros.ros import params as P
    rows = {r['name']: r for r in P.config_parameters(Pose2DConfig)}
    assert list(rows)[:3] == ['camera_id', 'model.name', 'model.path']
    assert len(rows) == 26 and rows['image_qos.reliability']['default'] == 'best_effort'
    assert rows['output_qos.depth']['default'] == 10
    assert rows['model.min_input_side']['type'] is int
    dynamic = {n for n, r in rows.items() if r['dynamic']}
    assert dynamic == {'score_threshold', 'keypoint_threshold', 'nms_iou', 'max_people',
                       'debug_min_confidence', 'min_rate_hz', 'no_input_timeout_s',
                       'inference_rate_hz'}
    assert {n for n, r in rows.items() if r['dynamic_typing']} == {'inference_rate_hz'}
    # a comment over several lines is one description, joined with single spaces
    text = rows['model.input_size']['description']
    assert text.startswith('auto: of the fetched sizes') and text.endswith('it sets the size')
    assert '  ' not in text and '#' not in text
    desc = P.descriptor(rows['nms_iou']['description'], dynamic=True)
    assert desc.description.startswith('[DYNAMIC] IoU above which')


@pytest.mark.parametrize('name, value, refused', [
    ('nms_iou', 0.5, False), ('nms_iou', 1.5, True), ('keypoint_threshold', -0.1, True),
    ('debug_min_confidence', 1.0, False), ('max_people', 0, True), ('max_people', 1, False),
    ('inference_rate_hz', 'auto', False), ('inference_rate_hz', 'often', True),
    ('inference_rate_hz', 2000.0, True), ('score_threshold', -1.0, False)])
def test_parameter_error_names_what_is_refused(name, value, refused):
    reason = parameter_error(name, value)
    assert bool(reason) == refused
    if refused:
        assert name in reason


# -- intake ---------------------------------------------------------------------------------------
def test_header_stamp_is_read_from_cdr_of_either_byte_order():
    stamp = 1234 * NS + 567
    assert header_stamp_ns(_cdr(stamp)) == stamp
    assert header_stamp_ns(_cdr(stamp, little=False)) == stamp
    assert header_stamp_ns(b'\0\1\0\0') is None


def test_skip_notice_only_when_an_image_does_not_follow_the_last_published():
    assert not skipped_before(None, 0, None, 5)             # no sequence numbers: never
    assert skipped_before(None, 0, 7, 5)                    # nothing published yet
    assert not skipped_before(6, 4, 7, 5)                   # the next one
    assert skipped_before(5, 4, 7, 5)                       # one between
    assert not skipped_before(5, 6, 7, 5)                   # not newer than the last published


def test_arrival_counts_camera_images_from_the_sequence_numbers():
    mailbox = ImageMailbox(GridRate(shared=False))
    assert mailbox.arrival(None) == (1, None, None)
    assert mailbox.arrival({'publication_sequence_number': 10,
                            'received_timestamp': 99}) == (1, 99, 10)
    assert mailbox.arrival({'publication_sequence_number': 14}) == (4, None, 14)
    assert mailbox.arrival({'publication_sequence_number': 3}) == (1, None, 3)   # new publisher
    assert mailbox.arrival({'publication_sequence_number': 300_000})[0] == 1
    mailbox.start()                                         # activation forgets the last one
    assert mailbox.arrival({'publication_sequence_number': 300_005})[0] == 1


def test_mailbox_keeps_the_newest_image_and_counts_the_replaced_as_dropped():
    rate = GridRate(shared=False)
    rate.use(-1.0)                                          # auto: learns the replacements
    mailbox = ImageMailbox(rate)
    for k in range(3):
        assert mailbox.offer(_cdr(1000 * NS + k * 100 * MS), 1, k, k + 1, float(k))
    assert (mailbox.received, mailbox.taken, mailbox.dropped, mailbox.skipped) == (3, 3, 2, 0)
    assert mailbox.offer(_cdr(1000 * NS + 500 * MS), 3, 7, 6, 3.0)   # 2 never taken
    assert (mailbox.received, mailbox.dropped) == (6, 5)
    assert rate.auto.loss == pytest.approx(5 / 6)
    assert mailbox.pop() == (_cdr(1000 * NS + 500 * MS), 7, 6)
    assert mailbox.pop() is None
    mailbox.offer(_cdr(1001 * NS), 1, 8, 7, 4.0)
    mailbox.close()                                         # deactivation empties it
    assert mailbox.pending is None and mailbox.closed


def test_mailbox_on_a_grid_skips_within_a_window_and_drops_a_lost_window():
    rate = GridRate(shared=False)
    rate.use(2.5)                                           # 400 ms windows, 10 Hz camera
    mailbox = ImageMailbox(rate)
    for k in range(8):
        mailbox.offer(_cdr(1000 * NS + k * 100 * MS), 1, k, None, 0.0)
    assert (mailbox.skipped, mailbox.dropped) == (6, 1)
    assert mailbox.grid_stamp == 1000 * NS + 400 * MS
    assert mailbox.rate_label() == 2.5
    mailbox.pop()                                           # the model took it
    # images 8-15 never taken: the windows of 8-11 and 12-15 lost (one image each that would
    # have been inferred: dropped; the other 6 skipped), 16 opens the next one
    mailbox.offer(_cdr(1000 * NS + 1600 * MS), 9, 16, None, 0.0)
    assert (mailbox.skipped, mailbox.dropped) == (12, 3)
    assert mailbox.grid_stamp == 1000 * NS + 1600 * MS
    mailbox.offer(_cdr(1000 * NS + 1700 * MS), 1, 17, None, 0.0)    # same window: skipped
    assert (mailbox.skipped, mailbox.dropped) == (13, 3)


def test_grid_no_faster_than_the_camera_infers_every_image():
    """A grid at the camera's own rate selects nothing: jittered stamps never skip a frame."""
    rate = GridRate(shared=False)
    rate.use(parse_inference_rate(10.0))
    mailbox = ImageMailbox(rate)
    jitter = (4, -3, 2, -4, 3, -2, 4, -3, 1, -4) * 3          # ms, around the window boundary

    def offer(k):                                               # 10 Hz camera, 10 Hz grid
        stamp = 1000 * NS + k * 100 * MS + jitter[k % 10] * MS
        mailbox.offer(_cdr(stamp), 1, time.time_ns(), None, time.monotonic())

    for k in range(len(jitter)):
        offer(k)
    assert frame_period_ns(mailbox.takes) == pytest.approx(100 * MS, rel=0.1)
    # the first image opens a window, every later one reaches the mailbox too (on the
    # grid, the +4 / -3 ms pairs would share a window and the next one would be empty)
    assert mailbox.skipped == 0 and mailbox.dropped == len(jitter) - 1
    assert mailbox.doze_s() == 0.0
    assert mailbox.rate_label() == '10: every image (camera not faster)'   # /diagnostics
    rate.use(parse_inference_rate(5.0))                          # half: selects
    for k in range(30, 40):
        offer(k)
    assert mailbox.skipped == 5 and mailbox.rate_label() == 5.0


def test_grid_mode_dozes_until_the_next_window_is_due():
    """Between windows the inference thread takes nothing; it wakes half a frame early."""
    rate = GridRate(shared=False)
    rate.use(parse_inference_rate(2.0))
    mailbox = ImageMailbox(rate)

    def history(speed):
        now = time.time_ns()
        window = 1000 * NS                      # a 500 ms window opened at 1000 s
        mailbox.grid_stamp = window
        mailbox.takes.clear()
        for k in range(-24, 3):                 # 20 Hz camera, up to 100 ms into it
            # the last image arrives now; stamps run at ``speed`` x the wall clock
            mailbox.takes.append((now - int((100 - 50 * k) * MS / speed), window + k * 50 * MS,
                                  1))
        return now

    def dozes(expected_s, now):
        """Tell whether the doze is ``expected_s`` less the wall time since ``now``."""
        before = (time.time_ns() - now) / 1e9
        doze = mailbox.doze_s()
        after = (time.time_ns() - now) / 1e9
        return expected_s - after - 0.01 <= doze <= expected_s - before + 0.01
    # next window at +500 ms of stamps, due 400 ms after the last one; wake 25 ms early
    assert dozes(0.375, history(1.0))
    assert dozes(0.1875, history(2.0))          # a replay at twice real time
    mailbox.grid_stamp = 1000 * NS + 10 * NS    # stamps far ahead: at most one window
    assert mailbox.doze_s() <= 0.25 + 1e-6
    rate.use(parse_inference_rate(0.0))
    assert mailbox.doze_s() == 0.0               # every image: never dozes


def test_missed_windows_and_doze_are_grid_arithmetic():
    period = 400 * MS
    assert missed_windows(1000 * NS + 1600 * MS, 1000 * NS + 400 * MS, 8, period) == 2
    assert missed_windows(1000 * NS + 1600 * MS, 1000 * NS + 400 * MS, 1, period) == 1
    assert missed_windows(1000 * NS + 500 * MS, 1000 * NS + 400 * MS, 0, period) == 0
    assert missed_windows(1000 * NS, None, 5, period) == 0
    # a 20 Hz camera, a 500 ms window opened at 1000 s; the last image (+100 ms) arrives now,
    # 5 ms after its stamp: the next window's first image is due in 400 ms, wake 25 ms early
    now = 2000 * NS
    takes = [(now - (100 - 50 * k) * MS, 1000 * NS + k * 50 * MS, 1) for k in range(-24, 3)]
    assert doze_s(2.0, 1000 * NS, takes, now) == pytest.approx(0.375)
    faster = [(now - (100 - 50 * k) * MS // 2, s, f) for (_, s, f), k in zip(takes, range(-24, 3))]
    assert doze_s(2.0, 1000 * NS, faster, now) == pytest.approx(0.1875)     # replay at 2x
    assert doze_s(0.0, 1000 * NS, takes, now) == 0.0                        # every image
    assert doze_s(2.0, 1010 * NS, takes, now) <= 0.5                        # at most a window


def test_inference_thread_processes_reports_and_stops():
    mailbox = ImageMailbox(GridRate(shared=False))
    seen, done, trouble, took = [], [], [], threading.Event()

    def process(msg, arrived, seq):
        if msg == b'bad':
            raise RuntimeError('bad image')
        seen.append((msg, arrived, seq))
        return None if msg == b'empty' else msg

    def take(timeout_s):
        took.set()
        return False                                        # no intake: wait on the mailbox

    thread = InferenceThread(mailbox, 'test-inference', 0, take, process, done.append,
                             lambda what, exc: trouble.append((what, str(exc))))
    thread.start()
    try:
        assert took.wait(10)
        for msg in (b'bad', b'empty', _cdr(1000 * NS)):
            mailbox.offer(msg, 1, 5, 9, 0.0)
            deadline = time.monotonic() + 10
            while mailbox.pending is not None:
                assert time.monotonic() < deadline
                time.sleep(0.01)
        deadline = time.monotonic() + 10
        while len(seen) < 2:
            assert time.monotonic() < deadline
            time.sleep(0.01)
    finally:
        mailbox.close()
        thread.join(10)
    assert not thread.is_alive()
    assert trouble == [('failed', 'bad image')]
    assert [m for m, _, _ in seen] == [b'empty', _cdr(1000 * NS)] and seen[1][1:] == (5, 9)
    assert len(done) == 1 and done[0] >= 0                  # only the published one


# -- rates ----------------------------------------------------------------------------------------
def test_grid_rate_follows_the_slowest_camera_of_the_rig_until_it_expires():
    rate = GridRate(shared=True)
    assert rate.share(0.0) == '' and rate.mode == 'every image'
    rate.use(1.0)
    assert rate.mode == 'fixed' and rate.share(0.0) == '' and rate.hz == 1.0   # the user's
    assert rate.adapt(0.1, 0.0) is None
    rate.use(-1.0)
    assert rate.mode == 'auto' and rate.hz == 0.0
    assert not rate.hear(float('nan'), 0.0) and rate.hear(2.5, 0.0)
    text = rate.share(0.5, '/rig')
    assert rate.hz == 2.5 and 'slowest camera of the rig on /rig' in text
    assert rate.share(1.0, '/rig') == ''                    # no change, nothing to say
    values = rate.values(None, 1.0)
    assert values['Inference rate (Hz)'] == 2.5 and values['Inference rate mode'] == 'auto'
    assert values['Inference rate, own choice (auto)'] == 'every image'
    assert rate.values(1.0 * NS, 1.0)['Inference rate (Hz)'] == \
        '2.5: every image (camera not faster)'
    assert rate.share(1.0 + RIG_RATE_TTL_S + 0.1, '/rig') == 'inference rate every image: ' \
        'its own choice'
    solo = GridRate(shared=False)
    assert solo.rates == AUTO_RATES_HZ and len(rate.rates) > len(solo.rates)


def test_grid_rate_adapt_says_what_auto_mode_changed():
    rate = GridRate(shared=False)
    rate.use(-1.0, [(384, 640), (288, 512)])
    change, clock = None, 0.0
    for _ in range(80):                                     # 10 Hz camera, 100 ms per image
        clock += 0.1
        rate.auto.add_stamp(int(clock * NS))
        rate.auto.add_replaced()
        change = rate.adapt(0.1, clock)
        if change is not None:
            break
    announce, notes = change
    assert not announce and rate.size == (288, 512)        # a smaller input first, same rate
    assert notes == [f'model.input_size auto: 288x512 (was 384x640; steps 384x640, 288x512): '
                     f'{rate.auto.reason}']


# -- sizes ----------------------------------------------------------------------------------------
def test_estimator_cache_fits_the_first_image_and_opens_each_size_once(tmp_path):
    cache = fake_cache(tmp_path, [(640, 640), (384, 640), (288, 512), (192, 320)])
    opened, ladders = [], []

    def open_file(path, hw):
        opened.append(path)
        return open_estimator(path, threads=1, input_size=hw)

    sizes = EstimatorCache(ModelConfig(cache_dir=cache, threads=1), open_file, lambda: True,
                           ladders.append)
    assert sizes.load().input_size == (640, 640) and sizes.fit_pending
    sizes.set_value('score_threshold', 0.5)
    notes = sizes.follow((1080, 1920), lambda: None)
    assert tuple(sizes.estimator.input_size) == (384, 640) and not sizes.fit_pending
    assert ladders == [[(384, 640), (288, 512), (192, 320)]]
    assert notes == [('info', 'input size 384x640 for 1920x1080 images (model.input_size '
                              'auto); under load inference_rate_hz auto may step down to '
                              '288x512, 192x320')]
    fitted = sizes.estimator
    assert sizes.follow((1080, 1920), lambda: None) is None          # nothing to do
    assert sizes.follow((1080, 1920), lambda: (288, 512)) == []      # auto mode's choice
    assert sizes.estimator.score_threshold == 0.5                    # carried over
    sizes.follow((1080, 1920), lambda: None)                         # back to the fitted one
    assert sizes.estimator is fitted and len(opened) == 3            # each size opened once
    sizes.set_value('max_people', 3)
    sizes.set_value('score_threshold', -1.0)                         # the family default
    assert (sizes.estimator.max_people, sizes.estimator.score_threshold) == (3, 0.25)
    values = sizes.values()
    assert values['Input size steps (auto)'] == '384x640, 288x512, 192x320'
    assert values['Intra-op threads'] == 1
    # a size whose file went missing: the one in use is kept, the ladder shrinks to it
    os.remove(models.model_file('yolo11n-pose', (192, 320), cache))
    notes = sizes.follow((1080, 1920), lambda: (192, 320))
    assert notes[0][0] == 'warning' and 'keeping input size 384x640' in notes[0][1]
    assert sizes.ladder == [(384, 640)] and ladders[-1] == [(384, 640)]


def test_estimator_cache_names_the_size_that_would_fit_better(tmp_path):
    cache = fake_cache(tmp_path, [(640, 640)])
    sizes = EstimatorCache(ModelConfig(cache_dir=cache, threads=1),
                           lambda path, hw: open_estimator(path, threads=1, input_size=hw),
                           lambda: True, lambda ladder: None)
    sizes.load()
    notes = sizes.follow((1080, 1920), lambda: None)
    assert notes[0][0] == 'warning' and '--size 384x640' in notes[0][1]
    assert sizes.ladder == [(640, 640)] and sizes.values()['Input size steps (auto)'] == \
        '640x640'
    fixed = EstimatorCache(ModelConfig(cache_dir=cache, input_size='640', threads=1),
                           lambda path, hw: open_estimator(path, threads=1, input_size=hw),
                           lambda: True, lambda ladder: None)
    assert fixed.load().input_size == (640, 640) and not fixed.fit_pending
    assert fixed.follow((1080, 1920), lambda: None) is None and fixed.values()[
        'Input size steps (auto)'] == 'fixed'


def test_precision_auto_lists_int8_twins_on_the_cpu_and_fp32_on_a_gpu(tmp_path):
    """model.precision auto (default): a size's int8 twin where fetched, on the CPU only."""
    cache = fake_cache(tmp_path, [(384, 640), (192, 320)], int8=[(288, 512), (192, 320)])
    on_cpu = [True]
    sizes = EstimatorCache(ModelConfig(cache_dir=cache, threads=1),
                           lambda path, hw: open_estimator(path, threads=1, input_size=hw),
                           lambda: on_cpu[0], lambda ladder: None)
    assert sizes.config.precision == 'auto'
    assert sizes.fetched_sizes() == [(384, 640), (288, 512), (192, 320)]
    for size, precision in (((192, 320), 'int8'), ((288, 512), 'int8'),
                            ((384, 640), 'fp32')):
        path = sizes.path(size)
        assert path == models.model_file('yolo11n-pose', size, cache, precision)
        assert open_estimator(path, threads=1).precision == precision
    on_cpu[0] = False                                    # the model runs on a GPU
    assert sizes.fetched_sizes() == [(384, 640), (192, 320)]     # fp32 only on a GPU
    assert sizes.path((192, 320)) == models.model_file('yolo11n-pose', (192, 320), cache)


def test_auto_mode_steps_the_model_down_the_ladder_and_back(tmp_path):
    """Under load, inference_rate_hz auto moves the camera to the next fetched smaller input."""
    sizes_hw = [(640, 640), (384, 640), (288, 512), (224, 384), (192, 320)]
    cache = fake_cache(tmp_path, sizes_hw)      # 192x320: not a registry size, still used
    rate = GridRate(shared=False)
    rate.use(parse_inference_rate('auto'))      # the default
    # wired as pose2d_node wires them: each new ladder goes to auto mode
    sizes = EstimatorCache(ModelConfig(cache_dir=cache, threads=1, min_input_side=320),
                           lambda path, hw: open_estimator(path, threads=1, input_size=hw),
                           lambda: True, rate.set_sizes)
    sizes.load()
    sizes.set_value('score_threshold', 0.5)
    image = np.zeros((1080, 1920, 3), np.uint8)

    def frame():                                # what the node does with each image
        sizes.follow(image.shape[:2], lambda: rate.size)
        return sizes.estimator.infer(image, 'bgr')

    assert len(frame()) == 1
    assert tuple(sizes.estimator.input_size) == (384, 640)
    assert sizes.ladder == [(384, 640), (288, 512), (224, 384), (192, 320)]
    # A camera at 10 Hz, 100 ms per image and images replaced: one step down per dwell
    # (0.6 of the pixels is estimated to fit at most 0.7 of the frame period).
    auto, clock = rate.auto, 0.0
    for expected in [(288, 512), (224, 384), (192, 320)]:
        for _ in range(40):
            clock += 0.1
            auto.add_stamp(int(clock * NS))
            auto.add_replaced()
            auto.add_processing(0.1)
            if auto.update(clock):
                break
        people = frame()
        assert tuple(sizes.estimator.input_size) == expected
        assert sizes.estimator.path == models.model_file('yolo11n-pose', expected, cache)
        assert sizes.estimator.score_threshold == 0.5      # dynamic values carried over
        assert len(people) == 1
    values = sizes.values()                     # the node's /diagnostics has them
    assert values['Input size (HxW)'] == '192x320'
    assert values['Input size steps (auto)'] == '384x640, 288x512, 224x384, 192x320'
    # Leaving auto mode goes back to the size fitted to the camera.
    rate.use(parse_inference_rate(0), sizes.ladder)
    frame()
    assert tuple(sizes.estimator.input_size) == (384, 640)
