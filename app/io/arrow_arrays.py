"""float64 columns between NumPy and Arrow through their buffers.

``pa.array`` on a NumPy array and ``Array.to_numpy`` both import pandas, about 45 MiB of the
process for nothing: the API process, which parses uploads and reads stored logs but never
needs pandas, stays without it (docs/reliability.md#api-memory). Views, not copies, wherever
the layout allows.
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa


def float64_array(values: np.ndarray, absent: np.ndarray | None = None) -> pa.Array:
    """A float64 Arrow array over ``values`` (no copy when they are contiguous float64),
    null where ``absent`` is true."""
    values = np.ascontiguousarray(values, dtype=np.float64)
    if absent is None or not absent.any():
        return pa.Array.from_buffers(
            pa.float64(), values.size, [None, pa.py_buffer(values)], null_count=0
        )
    valid = np.packbits(~absent, bitorder="little")
    return pa.Array.from_buffers(
        pa.float64(),
        values.size,
        [pa.py_buffer(valid), pa.py_buffer(values)],
        null_count=int(np.count_nonzero(absent)),
    )


def float64_values(chunk: pa.Array) -> np.ndarray:
    """The values of a float64 chunk, a read-only view of its data buffer (a null's slot
    holds whatever the writer left there: see :func:`valid_rows`)."""
    if chunk.type != pa.float64():
        raise ValueError(f"a column is {chunk.type}, not float64")
    data = chunk.buffers()[1]
    if data is None:  # an empty chunk may have no data buffer
        return np.empty(0)
    return np.frombuffer(data, dtype=np.float64, count=len(chunk), offset=chunk.offset * 8)


def valid_rows(chunk: pa.Array) -> np.ndarray:
    """Whether each row of ``chunk`` holds a value (not null), as booleans."""
    validity = chunk.buffers()[0]
    if not chunk.null_count or validity is None:
        return np.ones(len(chunk), dtype=bool)
    bits = np.unpackbits(np.frombuffer(validity, dtype=np.uint8), bitorder="little")
    return bits[chunk.offset : chunk.offset + len(chunk)].astype(bool)
