"""``mapwise bench``: throughput of the map filters, measured against peers in the same run.

* The SKF paper's Fig. 5 sweep: square n×n tables, n = 2…21, samples/s of every filter and
  its time relative to SSKF (the paper: SKF ≈ 1.15, KF ≈ 0.82·exp(0.0087·p)).
* The 12×18 NOx table of SKF (34), plain and with the sensor model (a = 0.96, τ = 38 samples).
* The full KF against FilterPy's ``KalmanFilter`` on the same problem, checking both give the
  same map.
* How far the SSKF product gain (SKF (15)) is from the exact 2-D steady-state Riccati gain.
* The observers over a whole cycle: the LPV observer on ``maf-whtc`` (with its LMI gain
  design timed apart) and the three EKF variants on ``maf-1d-whtc``.

``sections`` (``mapwise bench --section NAME``, repeatable) runs only some of these.

Throughput is the best of several repeats after a warm-up (numba compiled), one core.
Benchmarks report speed; correctness is the test suite's job (the same-map check here only
guards the comparison).
"""

from __future__ import annotations

import argparse
import json
import platform
from collections.abc import Sequence
from typing import Any

from estimation.errors import ConfigError

SECTIONS = ("sweep", "nox", "filterpy", "sskf-gain", "simulators", "estimators", "observers")


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "bench",
        help="measure samples/s of every filter (and FilterPy's KF for comparison)",
        description="Benchmarks the map filters on n×n tables (n = 2…21, the SKF paper's "
        "Fig. 5 sweep) and the 12×18 NOx table, and the full KF against FilterPy.",
    )
    p.add_argument("--json", action="store_true", help="print the results as JSON")
    p.add_argument("--quick", action="store_true", help="fewer sizes and samples (smoke run)")
    p.add_argument(
        "--section",
        action="append",
        choices=SECTIONS,
        help="run only this section (repeatable; default: all)",
    )
    p.set_defaults(handler=run_command)


def run_command(args: argparse.Namespace) -> int:
    """``mapwise bench``: the report as text, or as JSON."""
    report = run_benchmarks(quick=args.quick, sections=args.section)
    print(json.dumps(report, indent=1) if args.json else format_report(report))
    return 0


def run_benchmarks(*, quick: bool = False, sections: Sequence[str] | None = None) -> dict[str, Any]:
    """Every section of :data:`SECTIONS`, or only those named in ``sections``."""
    from app.cli import bench_sections as measure  # numba kernels: only when benchmarking

    chosen = set(SECTIONS if sections is None else sections)
    unknown = sorted(chosen - set(SECTIONS))
    if unknown:
        raise ConfigError(f"unknown bench section(s) {unknown}; choose from {list(SECTIONS)}")
    report: dict[str, Any] = {
        "machine": {"python": platform.python_version(), "cpu": platform.processor() or ""}
    }
    if "sweep" in chosen:
        sizes = [2, 4, 8, 12, 16] if quick else list(range(2, 22))
        rows = measure.sweep(sizes, quick)
        skf = {r["n"]: r["samples_per_s"]["skf"] for r in rows}
        report["sweep"] = rows
        report["skf_flatness"] = {
            "largest_over_smallest_time": skf[min(skf)] / skf[max(skf)],
            "sizes": [min(skf), max(skf)],
        }
    if "nox" in chosen:
        report["nox_12x18"] = measure.nox_table(quick)
    if "filterpy" in chosen:
        report["filterpy"] = measure.filterpy_comparison(16, 60 if quick else 300)
    if "sskf-gain" in chosen:
        report["sskf_product_vs_exact_gain"] = measure.sskf_gain_gap()
    if "simulators" in chosen:
        report["simulators"] = measure.simulators()
    if "estimators" in chosen:
        report["estimators"] = measure.estimators_on_scenarios(quick)
    if "observers" in chosen:
        report["observers"] = measure.observers_on_scenarios(quick)
    return report


def format_report(report: dict[str, Any]) -> str:
    """The report as text; sections not in ``report`` are left out."""
    from app.cli.bench_sections import FILTERS

    lines: list[str] = []
    if "sweep" in report:
        lines += ["Map filters, samples/s (kernel, one core) and time relative to SSKF", ""]
        head = f"{'n':>3} {'p':>4} " + "".join(f"{f:>12}" for f in FILTERS)
        lines += [head + "   SKF/SSKF  KF/SSKF (paper KF)  cell changes"]
        for row in report["sweep"]:
            rates = "".join(f"{row['samples_per_s'][f]:>12.3g}" for f in FILTERS)
            rel = row["relative_time"]
            lines.append(
                f"{row['n']:>3} {row['p']:>4} {rates}   {rel['skf']:>8.2f} {rel['kf']:>8.1f} "
                f"({row['paper_relative_time']['kf']:>5.1f})  {row['cell_change_rate']:>11.1%}"
            )
        flat = report["skf_flatness"]
        lines += [
            "",
            f"SKF time {flat['sizes'][1]}x{flat['sizes'][1]} / {flat['sizes'][0]}x"
            f"{flat['sizes'][0]}: {flat['largest_over_smallest_time']:.2f}",
        ]
    if "nox_12x18" in report:
        lines += _gap(lines)
        lines.append(
            "12x18 NOx table        kernel samples/s   end-to-end samples/s   cell changes"
        )
        for name, rate in report["nox_12x18"]["filters"].items():
            lines.append(
                f"  {name:<20} {rate['kernel_samples_per_s']:>14.3g} "
                f"{rate['end_to_end_samples_per_s']:>22.3g} {rate['cell_change_rate']:>14.1%}"
            )
    if "filterpy" in report:
        fp = report["filterpy"]
        lines += _gap(lines)
        if fp["available"]:
            lines.append(
                f"Full KF {fp['n']}x{fp['n']} (p={fp['p']}): mapwise "
                f"{fp['mapwise_samples_per_s']:.3g} samples/s, FilterPy "
                f"{fp['filterpy_samples_per_s']:.3g} samples/s, "
                f"speed-up {fp['speedup']:.0f}x, same map: {fp['same_map']} "
                f"(max |Δθ| {fp['max_abs_map_difference']:.1e})"
            )
        else:
            lines.append(f"FilterPy comparison skipped: {fp['note']}")
    if "sskf_product_vs_exact_gain" in report:
        gap = report["sskf_product_vs_exact_gain"]
        lines += [] if "filterpy" in report else _gap(lines)
        lines.append(
            f"SSKF product gain vs exact 2-D Riccati gain (r = {gap['r']:g}): max |ΔK| "
            f"{gap['max_abs_gain_difference']:.3f} at η = {gap['at_eta']}"
        )
    if "estimators" in report:
        lines += [*_gap(lines), "Estimators on scenarios (end to end, samples/s)"]
        for name, rate in report["estimators"].items():
            lines.append(f"  {name:<48} {rate['samples_per_s']:>10.3g}")
    if "observers" in report:
        lines += [
            *_gap(lines),
            "Observers, whole log (samples)           kernel samples/s   fit samples/s    fit s"
            "   gain design s",
        ]
        for name, rate in report["observers"].items():
            design = f"{rate['design_s']:>16.3f}" if "design_s" in rate else f"{'-':>16}"
            label = f"{name} ({rate['samples']:.0f})"
            lines.append(
                f"  {label:<37} {rate['kernel_samples_per_s']:>17.3g} "
                f"{rate['fit_samples_per_s']:>15.3g} {rate['fit_s']:>8.3f}{design}"
            )
    if "simulators" in report:
        lines += [*_gap(lines), "Ground-truth simulators (wall time, compiled)"]
        for name, sim in report["simulators"].items():
            lines.append(f"  {name:<48} {sim['wall_s']:>7.3f} s")
    return "\n".join(lines)


def _gap(lines: list[str]) -> list[str]:
    """A blank line between sections (none before the first)."""
    return [""] if lines else []
