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
Images as the nodes receive them.

Messages with row padding, CDR read in place, folders and videos as frame sources (a video
indexed like a folder).
"""

import cv2
import numpy as np
import pytest


def test_image_messages_with_row_padding_and_bad_sizes():
    from mv3dpose_ros.ros.images import image_to_numpy, ImageError, numpy_to_image
    img = np.arange(4 * 5 * 3, dtype=np.uint8).reshape(4, 5, 3)
    msg = numpy_to_image(img, encoding='rgb8')
    arr, order = image_to_numpy(msg)
    assert order == 'rgb' and np.array_equal(arr, img)
    padded = np.zeros((4, 20), np.uint8)                 # step 20 > 5 x 3
    padded[:, :15] = img.reshape(4, 15)
    msg.step, msg.data = 20, padded.tobytes()
    assert np.array_equal(image_to_numpy(msg)[0], img)
    msg.data = padded.tobytes()[:-1]
    with pytest.raises(ImageError, match='expected height 4 x step 20'):
        image_to_numpy(msg)
    msg.encoding = 'bayer_rggb8'
    with pytest.raises(ImageError, match='unsupported image encoding'):
        image_to_numpy(msg)
    with pytest.raises(ImageError, match='does not fit'):
        numpy_to_image(img, encoding='mono8')


def test_frame_source_reads_folders_and_videos(tmp_path):
    from mv3dpose_ros.io.media import FrameSource
    frames = [np.full((48, 64, 3), 40 * i, np.uint8) for i in range(4)]
    folder = tmp_path / 'imgs'
    folder.mkdir()
    for i, f in enumerate(frames):
        cv2.imwrite(str(folder / f'{i:02d}.png'), f)
    (folder / 'notes.txt').write_text('not an image')
    src = FrameSource(str(folder), preload=True)
    got = [src.read_next() for _ in range(5)]
    assert got[4] is None and all(np.array_equal(g, f) for g, f in zip(got, frames))
    src.rewind()
    assert np.array_equal(src.read_next(), frames[0])
    video = str(tmp_path / 'clip.avi')
    writer = cv2.VideoWriter(video, cv2.VideoWriter_fourcc(*'MJPG'), 10, (64, 48))
    for f in frames:
        writer.write(f)
    writer.release()
    src = FrameSource(video)
    count = 0
    while (frame := src.read_next()) is not None:
        assert frame.shape == (48, 64, 3) and abs(int(frame.mean()) - 40 * count) <= 3
        count += 1
    assert count == 4
    with pytest.raises(ValueError, match='source not found'):
        FrameSource(str(tmp_path / 'missing'))
    with pytest.raises(ValueError, match='no images'):
        FrameSource(str(tmp_path))


def test_image_cdr_is_read_in_place():
    from builtin_interfaces.msg import Time
    from mv3dpose_ros.ros.images import image_to_numpy, ImageError, numpy_to_image, parse_image_cdr
    from rclpy.serialization import serialize_message
    from std_msgs.msg import Header
    rng = np.random.default_rng(3)
    for shape, enc in (((7, 5, 3), 'rgb8'), ((3, 9), 'mono8')):
        arr = rng.integers(0, 255, size=shape, dtype=np.uint8)
        for frame_id in ('', 'a', 'ab', 'abc', 'cam0_optical_frame'):
            msg = numpy_to_image(arr, Header(stamp=Time(sec=17, nanosec=99),
                                             frame_id=frame_id), enc)
            wire = serialize_message(msg)
            parsed, data = parse_image_cdr(wire)
            got, order = image_to_numpy(parsed, data)
            assert parsed.header == msg.header and parsed.encoding == enc
            assert np.array_equal(got, arr) and order == ('rgb' if enc == 'rgb8' else 'gray')
            assert np.shares_memory(got, np.frombuffer(wire, np.uint8))     # no pixel copy
    with pytest.raises(ImageError, match='declares'):
        parse_image_cdr(wire[:-3])
    with pytest.raises(ImageError, match='plain CDR'):
        parse_image_cdr(b'\x00\x07\x00\x00' + wire[4:])


def test_a_video_is_indexed_like_a_folder(tmp_path, monkeypatch):
    """Looping publishers of a recorded rig show frame k of every camera at the same instant."""
    from mv3dpose_ros.io import media
    from mv3dpose_ros.io.media import FrameSource, VIDEO_SEEK_FRAMES
    video = str(tmp_path / 'clip.avi')
    n = VIDEO_SEEK_FRAMES + 20
    writer = cv2.VideoWriter(video, cv2.VideoWriter_fourcc(*'MJPG'), 10, (64, 48))
    for i in range(n):
        writer.write(np.full((48, 64, 3), 3 * i, np.uint8))
    writer.release()
    src = FrameSource(video)
    assert src.seekable and src.length == n

    def shown(frame):
        return round(frame.mean() / 3)

    # forward by stepping, backward and far ahead by seeking, the wrap of a loop
    for k in (0, 5, 6, 3, VIDEO_SEEK_FRAMES + 10, 2, n - 1, 0):
        assert shown(src.frame_at(k)) == k
        assert src.position == k + 1
    assert src.skip() and shown(src.read_next()) == 2       # in order after an index
    src.frame_at(n - 1)
    assert not src.skip() and src.read_next() is None        # the end
    src.rewind()
    assert shown(src.read_next()) == 0
    opened = media.VideoReader.__init__

    def counts_too_many(reader, path):           # a container that counts too many frames
        opened(reader, path)
        reader.frame_count += 5

    monkeypatch.setattr(media.VideoReader, '__init__', counts_too_many)
    src = FrameSource(video)
    assert shown(src.frame_at(n + 2)) == 0 and src.length == n + 2
