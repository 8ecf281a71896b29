"""The subset of MATLAB's level-5 MAT-file format trep's trajectory files use (written by
trep through scipy): named real double matrices and rows of strings (cell arrays of char),
read and written with numpy alone, so that trajectories move between trep and this layer.
Reads compressed elements and the small-element form too; writes uncompressed.
"""
from __future__ import annotations

import struct
import time
import zlib
from typing import Dict, List, Union

import numpy as np

Value = Union[np.ndarray, List[str]]

# Data types (MAT-file level 5) and array classes.
MI_INT8, MI_UINT8, MI_INT16, MI_UINT16, MI_INT32, MI_UINT32 = 1, 2, 3, 4, 5, 6
MI_SINGLE, MI_DOUBLE, MI_INT64, MI_UINT64 = 7, 9, 12, 13
MI_MATRIX, MI_COMPRESSED, MI_UTF8, MI_UTF16 = 14, 15, 16, 17
MX_CELL, MX_CHAR, MX_DOUBLE = 1, 4, 6
_DTYPES = {MI_INT8: "<i1", MI_UINT8: "<u1", MI_INT16: "<i2", MI_UINT16: "<u2",
           MI_INT32: "<i4", MI_UINT32: "<u4", MI_SINGLE: "<f4", MI_DOUBLE: "<f8",
           MI_INT64: "<i8", MI_UINT64: "<u8", MI_UTF8: "<u1", MI_UTF16: "<u2"}


class MatFileError(ValueError):
    """A file this reader cannot take (not a level-5 MAT-file, or an unsupported element)."""


# Writing -----------------------------------------------------------------------------------
def _element(kind: int, payload: bytes) -> bytes:
    pad = (-len(payload)) % 8
    return struct.pack("<II", kind, len(payload)) + payload + b"\0" * pad


def _matrix(name: str, value: Value) -> bytes:
    if isinstance(value, list):
        cls, dims = MX_CELL, (1, len(value))
        body = b"".join(_matrix("", s) for s in value)
    elif isinstance(value, str):
        cls, dims = MX_CHAR, (1, len(value))
        body = _element(MI_UTF16, np.array([ord(c) for c in value], dtype="<u2").tobytes())
    else:
        a = np.atleast_2d(np.asarray(value, dtype=float))
        cls, dims = MX_DOUBLE, a.shape
        body = _element(MI_DOUBLE, a.astype("<f8").tobytes(order="F"))
    head = (_element(MI_UINT32, struct.pack("<II", cls, 0))
            + _element(MI_INT32, struct.pack(f"<{len(dims)}i", *dims))
            + _element(MI_INT8, name.encode("ascii")))
    return _element(MI_MATRIX, head + body)


def write(path: str, values: Dict[str, Value]) -> None:
    """Writes `values` (name → matrix, or list of strings) as a level-5 MAT-file."""
    text = ("MATLAB 5.0 MAT-file Platform: posix, Created on: "
            + time.strftime("%a %b %d %H:%M:%S %Y") + " by tree_mech.trep").encode("ascii")
    header = text[:116].ljust(116, b" ") + b"\0" * 8 + struct.pack("<H", 0x0100) + b"IM"
    data = header + b"".join(_matrix(name, v) for name, v in values.items())
    with open(path, "wb") as f:
        f.write(data)


# Reading -----------------------------------------------------------------------------------
def _elements(data: bytes, start: int = 0):
    """Yields (type, payload) of each data element from `start`."""
    at = start
    while at + 8 <= len(data):
        kind, size = struct.unpack("<II", data[at:at + 8])
        if kind >> 16:  # small element: size in the upper half, data in the next 4 bytes
            size, kind = kind >> 16, kind & 0xFFFF
            yield kind, data[at + 4:at + 4 + size]
            at += 8
            continue
        payload = data[at + 8:at + 8 + size]
        if len(payload) < size:
            raise MatFileError("the file ends inside an element")
        yield kind, payload
        at += 8 + size + (-size % 8 if kind != MI_COMPRESSED else 0)


def _array(payload: bytes):
    parts = list(_elements(payload))
    if len(parts) < 3:
        raise MatFileError("an array element lacks its flags, dimensions or name")
    flags = np.frombuffer(parts[0][1], dtype="<u4")
    cls = int(flags[0]) & 0xFF
    dims = tuple(int(d) for d in np.frombuffer(parts[1][1], dtype="<i4"))
    name = parts[2][1].decode("ascii")
    if cls == MX_CELL:
        cells = [_array(p)[1] for kind, p in parts[3:] if kind == MI_MATRIX]
        return name, cells
    if len(parts) < 4:
        return name, "" if cls == MX_CHAR else np.zeros(dims)
    kind, raw = parts[3]
    if kind not in _DTYPES:
        raise MatFileError(f"array `{name}` holds data of an unsupported type ({kind})")
    values = np.frombuffer(raw, dtype=_DTYPES[kind])
    if cls == MX_CHAR:
        return name, "".join(chr(c) for c in values) if kind != MI_UTF8 else bytes(raw).decode("utf-8")
    if (int(flags[0]) >> 11) & 1:
        raise MatFileError(f"array `{name}` is complex; trajectories are real")
    return name, values.astype(float).reshape(dims, order="F")


def read(path: str) -> Dict[str, Value]:
    """The named matrices and string rows of a level-5 MAT-file."""
    with open(path, "rb") as f:
        data = f.read()
    if len(data) < 128 or data[126:128] != b"IM":
        raise MatFileError(f"{path} is not a little-endian level-5 MAT-file")
    out: Dict[str, Value] = {}
    try:
        for kind, payload in _elements(data, 128):
            if kind == MI_COMPRESSED:
                inner = zlib.decompress(payload)
                kind, payload = next(_elements(inner))
            if kind == MI_MATRIX:
                name, value = _array(payload)
                out[name] = value
    except (MatFileError, zlib.error, StopIteration, UnicodeDecodeError, ValueError) as e:
        raise MatFileError(f"{path}: {e}") from None
    return out
