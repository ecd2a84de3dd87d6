"""Benchmark the A2L import on a ~2 MB A2L: first parse, cached re-open, listing and search,
and a re-open through the service's cache while another A2L is being parsed.

The A2L is the ASAM demo from the pya2ldb wheel with its CHARACTERISTIC and AXIS_PTS
blocks replicated under new names (``<name>__<k>``, common-axis
references renamed with them) until the file reaches ``--size-mb``. Everything happens in
a temporary directory. Figures are reported in ``docs/calibration.md#a2l-import``.

    .venv/bin/python scripts/bench_a2l.py [--size-mb 2] [--repeat 5]
"""

from __future__ import annotations

import argparse
import os
import re
import resource
import statistics
import tempfile
import threading
import time
from pathlib import Path

import pya2l

from app.calibration import a2l as a2l_module
from app.calibration.a2l import open_a2l
from app.services import a2l_cache

DEMO = Path(pya2l.__file__).parent / "examples" / "ASAP2_Demo_V161.a2l"
_BLOCKS = re.compile(r"/begin (CHARACTERISTIC|AXIS_PTS)\s.*?/end \1\n", re.S)


def big_a2l(size_mb: float) -> bytes:
    """The demo with its CHARACTERISTICs and AXIS_PTS copied until ``size_mb`` megabytes."""
    text = DEMO.read_text(encoding="latin-1").replace("\r\n", "\n")
    blocks = [m.group(0) for m in _BLOCKS.finditer(text)]
    names = [block.split()[2] for block in blocks]
    anchor = text.index("    /begin COMPU_METHOD")
    copies: list[str] = []
    size, k = len(text), 0
    while size < size_mb * 1e6:
        k += 1
        for block in blocks:
            copy = block
            for name in names:
                copy = copy.replace(f" {name} ", f" {name}__{k} ")
            copies.append(copy)
            size += len(copy)
    return (text[:anchor] + "".join(copies) + text[anchor:]).encode("latin-1")


def reopen_from_disk(data: bytes, cache: Path) -> None:
    """A re-open as after a restart: the in-memory copies are dropped first."""
    a2l_module._MEMO.clear()
    open_a2l(data, cache_dir=cache)


def reopen_during_parse(data: bytes, cache: Path, repeat: int) -> tuple[list[float], bool]:
    """Re-open times of the cached ``data`` through :func:`app.services.a2l_cache.open_bytes`
    (memory copies dropped first) while another A2L's parse holds the parse lock; and
    whether that parse was still running at the end (the re-opens did not wait for it)."""
    limits = a2l_cache.CacheLimits(cache, max_files=10**6, max_bytes=10**12)
    other = data + b"\n/* another A2L: new content, a new parse */\n"
    parse = threading.Thread(target=a2l_cache.open_bytes, args=(other, limits))
    parse.start()
    while not a2l_cache._parse_lock.locked() and parse.is_alive():
        time.sleep(0.01)

    def reopen() -> None:
        a2l_cache.forget()
        a2l_module._MEMO.clear()
        a2l_cache.open_bytes(data, limits)

    times = timed(reopen, repeat)
    overlapped = parse.is_alive()
    parse.join()
    return times, overlapped


def timed(action, repeat: int) -> list[float]:  # type: ignore[no-untyped-def]
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        action()
        times.append(time.perf_counter() - start)
    return times


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size-mb", type=float, default=2.0)
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()

    data = big_a2l(args.size_mb)
    with tempfile.TemporaryDirectory() as tmp:
        cache = Path(tmp)
        start, cpu = time.perf_counter(), _cpu()
        a2l = open_a2l(data, cache_dir=cache)
        first, first_cpu = time.perf_counter() - start, _cpu() - cpu
        cpu = _cpu()
        reopen = timed(lambda: reopen_from_disk(data, cache), args.repeat)
        reopen_cpu = (_cpu() - cpu) / args.repeat
        memo = timed(lambda: open_a2l(data, cache_dir=cache), args.repeat)
        listing = timed(lambda: a2l.search(types=("MAP", "CURVE"), limit=100), args.repeat)
        search = timed(lambda: a2l.search("std_axis", limit=100), args.repeat)
        lookup = timed(lambda: a2l.get(a2l.characteristics[-1].name).to_json(), args.repeat)
        during, overlapped = reopen_during_parse(data, cache, args.repeat)

    print(
        f"A2L: {len(data) / 1e6:.2f} MB, {len(a2l)} characteristics, {len(a2l.axis_pts)} AXIS_PTS"
    )
    print(
        f"first open (parse):      {first:8.2f} s  ({first_cpu:.2f} s CPU incl. the parser process)"
    )
    for label, times in (
        ("re-open from disk", reopen),
        ("re-open, in memory", memo),
        ("list MAP+CURVE, 100", listing),
        ("search 'std_axis', 100", search),
        ("get + to_json", lookup),
        ("re-open during a parse", during),
    ):
        print(
            f"{label + ':':24} {statistics.median(times) * 1e3:8.1f} ms median, "
            f"{max(times) * 1e3:.1f} ms worst of {len(times)}"
        )

    if not overlapped:
        print("(the other parse ended before the re-opens did: repeat with a larger --size-mb)")
    print(f"re-open CPU time:        {reopen_cpu * 1e3:8.1f} ms mean (wall times include waiting)")
    print(f"load average: {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs")


def _cpu() -> float:
    """CPU seconds of this process and its finished children (the parser)."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


if __name__ == "__main__":
    main()
