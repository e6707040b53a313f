"""Arrow columns as NumPy arrays, read from their data buffers.

pyarrow's own ``to_numpy`` and its compute functions import pandas: 0.3 s of the 0.4 s it
took to load the example dataset. The trace readers (Parquet, and CSV parsed by pyarrow)
need only plain numbers, which are read here straight from the buffers.
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa

__all__ = ["plain_numbers"]


def plain_numbers(column: pa.ChunkedArray) -> np.ndarray | None:
    """A column of floats, integers or booleans without nulls, as float64 read from its
    data buffers; None for any other."""
    kind = column.type
    if column.null_count:
        return None
    if pa.types.is_floating(kind) or pa.types.is_integer(kind):
        code = (
            "f" if pa.types.is_floating(kind) else "i" if pa.types.is_signed_integer(kind) else "u"
        )
        dtype = np.dtype(f"<{code}{kind.bit_width // 8}")
        if code == "f" and dtype.itemsize == 2:
            return None  # half floats: let pyarrow convert them
        parts = [
            np.frombuffer(c.buffers()[1], dtype, count=len(c), offset=dtype.itemsize * c.offset)
            for c in column.chunks
        ]
    elif pa.types.is_boolean(kind):  # bit-packed, least significant bit first
        parts = [
            np.unpackbits(np.frombuffer(c.buffers()[1], np.uint8), bitorder="little")[
                c.offset : c.offset + len(c)
            ]
            for c in column.chunks
        ]
    else:
        return None
    # concatenate makes a new array: astype need not copy it again
    return np.concatenate(parts).astype(np.float64, copy=False) if parts else np.zeros(0)
