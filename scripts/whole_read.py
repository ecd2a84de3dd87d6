"""Peak memory of reading an upload whole, per byte of the file, by format.

    .venv/bin/python scripts/whole_read.py --rows 1000000

writes, in a temporary directory, a sparse CSV (a channel empty on every other row, so it
cannot stream), an MDF4 log of four channels (asammdf) and an MCAP log of JSON messages
with two fields (mcap), then reads each with :func:`app.io.ingest.ingest` in a fresh
process. The process imports the readers first, resets its peak resident set
(``/proc/self/clear_refs``) and reads: the growth of its peak ``VmHWM`` over its ``VmRSS``
before, divided by the file's size, is the factor
:data:`app.services.datasets.WHOLE_READ_FACTOR` rounds up (docs/data-formats.md#whole-reads).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from scripts.run_memory import MIB, PEAK_HELPERS, ROOT

_READER = (
    PEAK_HELPERS
    + """
import json, sys
import asammdf, mcap.reader, pyarrow.csv  # loaded before the baseline
from app.io.ingest import ingest

gc.collect()
Path("/proc/self/clear_refs").write_text("5")  # VmHWM := VmRSS (Linux >= 4.0)
before = kib("VmRSS")
with open(sys.argv[1], "rb") as file:
    parsed = ingest(file, time_required=True)
print(json.dumps({"rows": parsed.rows, "growth_kib": kib("VmHWM") - before}))
"""
)


def write_sparse_csv(path: Path, rows: int) -> Path:
    rng = np.random.default_rng(0)
    t = (np.arange(rows) * 0.01).tolist()
    a, b = rng.uniform(0, 1, rows).tolist(), rng.uniform(0, 1, rows).tolist()
    with path.open("w") as f:
        f.write("time [s],a [u],b [u]\n")
        for k in range(rows):
            f.write(f"{t[k]!r},{a[k]!r},{'' if k % 2 else repr(b[k])}\n")
    return path


def write_mdf4(path: Path, rows: int) -> Path:
    from asammdf import MDF, Signal

    rng = np.random.default_rng(0)
    t = np.arange(rows) * 0.01
    mdf = MDF(version="4.10")
    mdf.append([Signal(rng.uniform(0, 1, rows), t, name=f"c{i}", unit="u") for i in range(4)])
    mdf.save(path, overwrite=True)
    return path


def write_mcap(path: Path, rows: int) -> Path:
    from mcap.writer import Writer

    schema = {"type": "object", "properties": {k: {"type": "number"} for k in "txy"}}
    with path.open("wb") as f:
        writer = Writer(f)
        writer.start()
        schema_id = writer.register_schema("s", "jsonschema", json.dumps(schema).encode())
        channel = writer.register_channel("/t", "json", schema_id)
        for k in range(rows):
            data = json.dumps({"t": k * 0.01, "x": k * 0.5, "y": 1.0 / (k + 1)}).encode()
            writer.add_message(channel, log_time=k * 10**7, data=data, publish_time=k * 10**7)
        writer.finish()
    return path


def factor(path: Path) -> tuple[int, float]:
    """Rows read and peak growth per byte of ``path``, read whole in a fresh process."""
    env = os.environ | {"PYTHONPATH": str(ROOT), "OPENBLAS_NUM_THREADS": "1"}
    done = subprocess.run(
        [sys.executable, "-c", _READER, str(path)],
        capture_output=True,
        text=True,
        cwd=ROOT,
        env=env,
        timeout=600,
        check=False,
    )
    if done.returncode != 0:
        raise RuntimeError(f"reading {path.name} failed: {done.stderr[-2000:]}")
    out = json.loads(done.stdout.strip().splitlines()[-1])
    return out["rows"], out["growth_kib"] * 1024 / path.stat().st_size


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rows", type=int, default=1_000_000, help="samples per log")
    args = parser.parse_args()
    if not 1000 <= args.rows <= 20_000_000:
        parser.error("--rows must be within 1000 … 20 000 000")
    writers = {"csv": write_sparse_csv, "mdf4": write_mdf4, "mcap": write_mcap}
    suffix = {"csv": ".csv", "mdf4": ".mf4", "mcap": ".mcap"}
    with tempfile.TemporaryDirectory(prefix="mapwise-whole-read-") as tmp:
        for kind, write in writers.items():
            path = write(Path(tmp) / f"log{suffix[kind]}", args.rows)
            rows, per_byte = factor(path)
            size = path.stat().st_size / MIB
            print(f"{kind:5s} {size:7.1f} MiB, {rows:9d} rows: peak {per_byte:4.1f} × the file")


if __name__ == "__main__":
    main()
