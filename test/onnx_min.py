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
Write tiny ONNX models with crafted constant outputs, without the ``onnx`` package.

The project venv has onnxruntime but not ``onnx``, so this encodes the few ModelProto fields
needed (graph inputs/outputs with shapes, initializers, Identity nodes, metadata) directly in
the protobuf wire format (field numbers from onnx/onnx.proto). Each output is a constant, so a
test knows exactly what the "network" says and can check the pre/post-processing around it.
"""

from typing import Dict, Sequence, Tuple, Union

import numpy as np

ELEM = {np.dtype(np.float32): 1, np.dtype(np.uint8): 2, np.dtype(np.int32): 6}
Dim = Union[int, str]


def _varint(n: int) -> bytes:
    n &= (1 << 64) - 1
    out = bytearray()
    while True:
        b = n & 0x7F
        n >>= 7
        if n:
            out.append(b | 0x80)
        else:
            out.append(b)
            return bytes(out)


def _int(field: int, value: int) -> bytes:
    return _varint(field << 3) + _varint(value)


def _bytes(field: int, data: Union[bytes, str]) -> bytes:
    if isinstance(data, str):
        data = data.encode('utf-8')
    return _varint((field << 3) | 2) + _varint(len(data)) + data


def _value_info(name: str, dtype, dims: Sequence[Dim]) -> bytes:
    shape = b''.join(_bytes(1, _bytes(2, d) if isinstance(d, str) else _int(1, d))
                     for d in dims)
    tensor_type = _int(1, ELEM[np.dtype(dtype)]) + _bytes(2, shape)
    return _bytes(1, name) + _bytes(2, _bytes(1, tensor_type))


def _tensor(name: str, array: np.ndarray) -> bytes:
    array = np.ascontiguousarray(array)
    dims = b''.join(_int(1, d) for d in array.shape)
    return dims + _int(2, ELEM[array.dtype]) + _bytes(8, name) + _bytes(9, array.tobytes())


def make_constant_model(inputs: Sequence[Tuple[str, object, Sequence[Dim]]],
                        outputs: Dict[str, np.ndarray],
                        metadata: Dict[str, str] = None,
                        output_dims: Dict[str, Sequence[Dim]] = None) -> bytes:
    """
    Return ONNX bytes whose outputs are the given constant arrays, whatever the input.

    ``inputs`` are ``(name, dtype, dims)``; dims may be strings (dynamic). ``output_dims``
    optionally declares different (e.g. dynamic) output shapes than the constants'.
    """
    graph = b''
    for i, (name, value) in enumerate(outputs.items()):
        graph += _bytes(1, _bytes(1, f'const{i}') + _bytes(2, name) + _bytes(3, f'id{i}')
                        + _bytes(4, 'Identity'))
    graph += _bytes(2, 'crafted')
    for i, value in enumerate(outputs.values()):
        graph += _bytes(5, _tensor(f'const{i}', value))
    for name, dtype, dims in inputs:
        graph += _bytes(11, _value_info(name, dtype, dims))
    for name, value in outputs.items():
        dims = (output_dims or {}).get(name, value.shape)
        graph += _bytes(12, _value_info(name, value.dtype, dims))
    model = _int(1, 8) + _bytes(2, 'mv3dpose-test') + _bytes(7, graph)
    model += _bytes(8, _bytes(1, '') + _int(2, 17))
    for key, value in (metadata or {}).items():
        model += _bytes(14, _bytes(1, key) + _bytes(2, value))
    return model
