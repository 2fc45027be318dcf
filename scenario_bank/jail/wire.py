"""The messages between the user's process and a jailed worker: data only.

A message is a JSON document plus raw array buffers::

    b"DV2S" | u32 header length | u32 buffer count | u64 length of each buffer
    | header (UTF-8 JSON) | buffers

Arrays appear in the JSON as ``{"__nd__": index, "dtype": "<f4", "shape": [...]}``
and travel as raw bytes of a plain numeric dtype. Nothing is ever unpickled:
what a worker sends can only become ``None``, ``bool``, ``int``, ``float``,
``str``, ``list``, ``dict`` (string keys) and numeric :class:`numpy.ndarray`.
:func:`read_message` checks every size before reading and every array before
building it, so a hostile worker can make a message fail, never make the
reader allocate more than the limit or run anything.
"""

from __future__ import annotations

import json
import math
import struct
from typing import Any, BinaryIO, Dict, List, Tuple

import numpy as np

from scenario_bank.jail.errors import JailProtocolError

__all__ = ["encode", "decode", "write_message", "read_message", "MAX_DEPTH", "PREFIX"]

MAGIC = b"DV2S"
MAX_DEPTH = 64
MAX_BUFFERS = 4096
# JSON becomes Python objects up to ~20x its size ("[[],[],...]"): the header gets its own, smaller cap;
# bulk data travels in the array buffers, which cost their size and no more
MAX_HEADER_BYTES = 8 * 2**20
_ALLOWED_KINDS = "biuf"  # bool, signed and unsigned integers, floats
PREFIX = struct.Struct("<4sII")
"""The fixed start of every message: :data:`MAGIC`, the header's size, the number of array buffers."""


def _encode(value: Any, buffers: List[bytes], depth: int) -> Any:
    if depth > MAX_DEPTH:
        raise JailProtocolError(f"message nested deeper than {MAX_DEPTH} levels")
    if value is None or isinstance(value, (bool, str)):
        return value
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value)
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, np.ndarray):
        if value.dtype.kind not in _ALLOWED_KINDS:
            raise JailProtocolError(f"arrays of dtype {value.dtype} cannot be sent")
        array = np.ascontiguousarray(value)
        buffers.append(array.tobytes())
        return {"__nd__": len(buffers) - 1, "dtype": array.dtype.str, "shape": list(array.shape)}
    if isinstance(value, dict):
        out = {}
        for key, item in value.items():
            if not isinstance(key, str):
                key = str(key)
            out[key] = _encode(item, buffers, depth + 1)
        return out
    if isinstance(value, (list, tuple)):
        return [_encode(item, buffers, depth + 1) for item in value]
    raise JailProtocolError(f"a {type(value).__name__} cannot be sent between processes; send data")


def encode(value: Any) -> Tuple[bytes, List[bytes]]:
    """``value`` as a JSON header and its array buffers."""
    buffers: List[bytes] = []
    tree = _encode(value, buffers, 0)
    return json.dumps(tree, separators=(",", ":")).encode("utf-8"), buffers


def _decode(value: Any, buffers: List[bytes], used: set, depth: int) -> Any:
    if depth > MAX_DEPTH:
        raise JailProtocolError(f"message nested deeper than {MAX_DEPTH} levels")
    if isinstance(value, list):
        return [_decode(item, buffers, used, depth + 1) for item in value]
    if isinstance(value, dict):
        if "__nd__" in value:
            return _array(value, buffers, used)
        return {key: _decode(item, buffers, used, depth + 1) for key, item in value.items()}
    if isinstance(value, float) and not math.isfinite(value):
        return value
    return value


def _array(spec: Dict[str, Any], buffers: List[bytes], used: set) -> np.ndarray:
    index, dtype, shape = spec.get("__nd__"), spec.get("dtype"), spec.get("shape")
    if not (isinstance(index, int) and not isinstance(index, bool) and 0 <= index < len(buffers)) or index in used:
        raise JailProtocolError("array refers to a missing or reused buffer")
    if not isinstance(dtype, str) or len(dtype) > 8:
        raise JailProtocolError("array has no valid dtype")
    try:
        kind = np.dtype(dtype)
    except TypeError:
        raise JailProtocolError(f"array dtype {dtype!r} is not a numpy dtype") from None
    if kind.kind not in _ALLOWED_KINDS or kind.hasobject or kind.fields is not None or kind.subdtype is not None:
        raise JailProtocolError(f"array dtype {dtype!r} is not a plain numeric dtype")
    if not (isinstance(shape, list) and len(shape) <= 8
            and all(isinstance(n, int) and not isinstance(n, bool) and 0 <= n < 2**31 for n in shape)):
        raise JailProtocolError("array shape is not a list of at most 8 sizes")
    count = math.prod(shape)
    data = buffers[index]
    if count * kind.itemsize != len(data):
        raise JailProtocolError("array shape and buffer size disagree")
    used.add(index)
    try:
        return np.frombuffer(data, dtype=kind).reshape(shape).copy()
    except (ValueError, OverflowError) as error:
        raise JailProtocolError(f"array cannot be built: {error}") from None


def decode(header: bytes, buffers: List[bytes]) -> Any:
    """The value :func:`encode` encoded; raises :class:`JailProtocolError` on anything else."""
    try:
        tree = json.loads(header.decode("utf-8"))
    except (UnicodeDecodeError, ValueError, RecursionError) as error:
        raise JailProtocolError(f"message is not valid JSON: {type(error).__name__}") from None
    return _decode(tree, buffers, set(), 0)


def write_message(stream: BinaryIO, value: Any) -> None:
    """Write ``value`` as one message and flush."""
    header, buffers = encode(value)
    parts = [PREFIX.pack(MAGIC, len(header), len(buffers))]
    parts.append(struct.pack(f"<{len(buffers)}Q", *(len(b) for b in buffers)))
    parts.append(header)
    parts.extend(buffers)
    stream.write(b"".join(parts))
    stream.flush()


def _read_exactly(stream: BinaryIO, size: int) -> bytes:
    chunks, left = [], size
    while left:
        chunk = stream.read(left)
        if not chunk:
            raise EOFError("the other side closed the channel")
        chunks.append(chunk)
        left -= len(chunk)
    return b"".join(chunks)


def read_message(stream: BinaryIO, max_bytes: int) -> Any:
    """Read one message of at most ``max_bytes``; raises :class:`EOFError` when the stream ends."""
    magic, header_size, count = PREFIX.unpack(_read_exactly(stream, PREFIX.size))
    if magic != MAGIC:
        raise JailProtocolError("the worker sent something that is not a message")
    if header_size > min(max_bytes, MAX_HEADER_BYTES):
        raise JailProtocolError(f"message header of {header_size} bytes is over the "
                                f"{min(max_bytes, MAX_HEADER_BYTES)}-byte limit (bulk data goes in arrays)")
    if count > MAX_BUFFERS:
        raise JailProtocolError(f"message has {count} buffers (at most {MAX_BUFFERS})")
    sizes = struct.unpack(f"<{count}Q", _read_exactly(stream, 8 * count)) if count else ()
    total = header_size + sum(sizes)
    if total > max_bytes:
        raise JailProtocolError(f"message of {total} bytes is over the {max_bytes}-byte limit")
    header = _read_exactly(stream, header_size)
    buffers = [_read_exactly(stream, n) for n in sizes]
    return decode(header, buffers)
