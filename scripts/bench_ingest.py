"""CSV ingest benchmark (figures for docs/data-formats.md; not a test).

The drive log of ``scripts/bench_service.py`` (time + 12 channels at 100 Hz, ``%.6f``) at
120 000 rows (≈ 15 MB) and 360 000 rows (≈ 45 MB), read by:

* ``mapwise read_csv`` — :func:`app.io.csv_files.read_csv` (``mapwise adapt``): decode,
  pyarrow blocks, checks, :class:`estimation.Signals`;
* ``mapwise upload parse`` — :func:`app.io.csv_files.parse_sparse_csv` on the decoded text
  (what an upload runs, empty cells allowed);
* ``mapwise streamed parse`` / ``upload`` — :func:`app.io.csv_stream.stream_csv`, what an
  upload of a dense CSV of 16 MiB or more runs: 2 MiB blocks by pyarrow, the checks, into
  nothing (parse only) or into the dataset's Parquet file (written and hashed);
* ``pyarrow.csv alone`` — ``pyarrow.csv.read_csv(path)`` with its defaults (a Table, types
  inferred, multi-threaded);
* ``pandas.read_csv`` — its defaults (C engine), skipped with a note when pandas is absent;
* ``old pure-Python`` — the reader mapwise had before (:mod:`tests.support.csv_reference`).

Each reader runs in a child process of its own, 5 times after a warm-up run (the file in
the page cache): median and worst CPU time (``time.process_time``: every thread of the child) and
wall time; the child's peak RSS (``ru_maxrss`` from ``os.wait4``) and how far it rose
above the child's RSS after its imports, as a multiple of the file size.

    .venv/bin/python scripts/bench_ingest.py [--rows 120000 360000] [--repeats 5] [--json]
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

READERS = {
    # app.io.csv_arrow imported up front: pyarrow is then part of the after-imports RSS
    "mapwise read_csv": "import app.io.csv_arrow\nfrom app.io.csv_files import read_csv as read",
    "mapwise upload parse": "import app.io.csv_arrow\n"
    "from app.io.csv_files import parse_sparse_csv\n"
    "read = lambda path: parse_sparse_csv(path.read_text(encoding='utf-8-sig'))",
    # the streamed upload (app/io/csv_stream.py): once parsing only, into a sink that keeps
    # nothing, and once writing the dataset's Parquet file as an upload does
    "mapwise streamed parse": "import app.io.csv_arrow\n"
    "from scripts.bench_ingest import streamed\n"
    "read = lambda path: streamed(path, parquet=False)",
    "mapwise streamed upload": "import app.io.csv_arrow\n"
    "from scripts.bench_ingest import streamed\n"
    "read = lambda path: streamed(path, parquet=True)",
    "pyarrow.csv alone": "import pyarrow.csv\nread = pyarrow.csv.read_csv",
    "pandas.read_csv": "import pandas\nread = pandas.read_csv",
    "old pure-Python": "from tests.support.csv_reference import read_csv as read",
}
BASELINE = "pyarrow.csv alone"  # what "our parse" is held to: within 1.5x of it


class _Nowhere:
    """A row sink that keeps nothing (:class:`app.io.csv_stream.RowSink`)."""

    def write(self, time: Any, values: Any) -> None:
        pass

    def close(self) -> str:
        return ""

    def abort(self) -> None:
        pass


def streamed(path: Path, *, parquet: bool) -> Any:
    """The streamed upload of ``path``: parsed block by block, into a Parquet file beside it
    (written and hashed, then removed) or into nowhere."""
    from app.io.csv_stream import stream_csv
    from app.store.parquet_signals import SignalsWriter

    out = path.with_suffix(".parquet")

    def sink(channels: list[tuple[str, str]]) -> Any:
        return SignalsWriter(out, channels) if parquet else _Nowhere()

    try:
        with path.open("rb") as f:
            return stream_csv(
                f,
                sink,
                units=None,
                time_column=None,
                channels=None,
                rate_hz=None,
                max_header_bytes=1 << 16,
                max_channels=2000,
                min_samples=2,
            )
    finally:
        out.unlink(missing_ok=True)


def make_logs(directory: Path, rows: list[int]) -> dict[int, Path]:
    """The benchmark logs, written once per row count by the generator of bench_service (in
    a child process: this one stays small, see :func:`measure`)."""
    paths = {n: directory / f"drive_{n}.csv" for n in rows}
    todo = [f"make_log(Path({str(p)!r}), {n})" for n, p in paths.items() if not p.exists()]
    if todo:
        code = "from pathlib import Path\nfrom bench_service import make_log\n" + "\n".join(todo)
        subprocess.run([sys.executable, "-c", code], check=True, cwd=ROOT / "scripts")
    return paths


def machine() -> dict[str, Any]:
    """:func:`app.cli.bench_timing.machine`, asked of a child process."""
    code = "import json\nfrom app.cli.bench_timing import machine\nprint(json.dumps(machine()))"
    out = subprocess.run([sys.executable, "-c", code], check=True, cwd=ROOT, capture_output=True)
    return json.loads(out.stdout)


def child(reader: str, path: Path, repeats: int) -> dict[str, Any]:
    """In the child process: import the reader, run it ``repeats`` times, report times and
    the RSS high-water mark after the imports (KiB)."""
    scope: dict[str, Any] = {}
    exec(READERS[reader], scope)
    read = scope["read"]
    path.read_bytes()  # the file in the page cache before the first timed run
    after_imports = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    read(path)  # warm-up: lazy imports, first-touch of the allocator's pages
    cpu, wall = [], []
    for _ in range(repeats):
        c0, t0 = time.process_time(), time.perf_counter()
        result = read(path)
        cpu.append(time.process_time() - c0)
        wall.append(time.perf_counter() - t0)
        del result
    return {"cpu": cpu, "wall": wall, "rss_after_imports_kib": after_imports}


def measure(reader: str, path: Path, repeats: int) -> dict[str, Any]:
    """One reader on one file, in a child process: times, peak RSS, rise per file byte.

    Linux keeps a process's RSS high-water mark across ``exec``, and the child starts as a
    copy of this process: so this process imports nothing big (numpy, the app) itself."""
    process = subprocess.Popen(
        [sys.executable, __file__, "--child", reader, str(path), "--repeats", str(repeats)],
        stdout=subprocess.PIPE,
        cwd=ROOT,
    )
    assert process.stdout is not None
    out = process.stdout.read()
    _, status, usage = os.wait4(process.pid, 0)
    process.returncode = os.waitstatus_to_exitcode(status)
    if process.returncode != 0:
        raise SystemExit(f"{reader} on {path.name} failed (exit {process.returncode})")
    report = json.loads(out)
    size = path.stat().st_size
    peak = usage.ru_maxrss * 1024  # Linux: KiB
    rise = peak - report["rss_after_imports_kib"] * 1024
    return {
        "cpu_median_s": statistics.median(report["cpu"]),
        "cpu_worst_s": max(report["cpu"]),
        "wall_median_s": statistics.median(report["wall"]),
        "wall_worst_s": max(report["wall"]),
        "peak_rss_mb": peak / 1e6,
        "rss_rise_over_file": rise / size,
    }


def run(rows: list[int], repeats: int, directory: Path) -> dict[str, Any]:
    paths = make_logs(directory, rows)
    report: dict[str, Any] = {"machine": machine(), "repeats": repeats, "files": []}
    if importlib.util.find_spec("pandas") is None:
        report["note"] = "pandas not installed: pandas.read_csv skipped"
    for n, path in paths.items():
        entry: dict[str, Any] = {"rows": n, "mb": path.stat().st_size / 1e6, "readers": {}}
        for reader in READERS:
            if reader == "pandas.read_csv" and "note" in report:
                continue
            entry["readers"][reader] = measure(reader, path, repeats)
        base = entry["readers"][BASELINE]
        for figures in entry["readers"].values():
            figures["cpu_vs_pyarrow"] = figures["cpu_median_s"] / base["cpu_median_s"]
            figures["wall_vs_pyarrow"] = figures["wall_median_s"] / base["wall_median_s"]
        report["files"].append(entry)
    report["machine"]["load_average_after"] = machine()["load_average"]
    return report


def format_report(report: dict[str, Any]) -> str:
    m = report["machine"]
    lines = [
        f"Machine: {m['cpu_model']}, {m['cores']} logical cores, Python {m['python']}; load "
        f"average {m['load_average'][0]:.1f} before, {m['load_average_after'][0]:.1f} after",
        f"Median (worst) of {report['repeats']} runs, each after a warm-up in its own child "
        "process; CPU = all threads; RSS rise = peak minus after-imports, per file byte",
    ]
    if "note" in report:
        lines.append(report["note"])
    for entry in report["files"]:
        lines += [
            "",
            f"{entry['rows']} rows x 13 columns, {entry['mb']:.1f} MB",
            f"  {'reader':<22}{'CPU s':>16}{'wall s':>16}{'CPU/pa':>8}{'wall/pa':>8}"
            f"{'peak RSS MB':>12}{'RSS rise':>9}",
        ]
        for name, f in entry["readers"].items():
            lines.append(
                f"  {name:<22}{f['cpu_median_s']:>8.3f} ({f['cpu_worst_s']:.3f})"
                f"{f['wall_median_s']:>8.3f} ({f['wall_worst_s']:.3f})"
                f"{f['cpu_vs_pyarrow']:>7.2f}x{f['wall_vs_pyarrow']:>7.2f}x"
                f"{f['peak_rss_mb']:>12.0f}{f['rss_rise_over_file']:>8.1f}x"
            )
    return "\n".join(lines)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rows", type=int, nargs="+", default=[120_000, 360_000])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--dir", type=Path, help="where the logs are written (kept)")
    parser.add_argument("--json", action="store_true")
    parser.add_argument("--child", nargs=2, metavar=("READER", "PATH"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(child(args.child[0], Path(args.child[1]), args.repeats)))
        return 0
    with tempfile.TemporaryDirectory() as tmp:
        report = run(args.rows, args.repeats, args.dir or Path(tmp))
    print(json.dumps(report, indent=1) if args.json else format_report(report))
    return 0


if __name__ == "__main__":
    sys.exit(main())
