"""``mapwise bench``: throughput of the map filters, measured against peers in the same run.

* The SKF paper's Fig. 5 sweep: square n×n tables, n = 2…21, samples/s of every filter and
  its time relative to SSKF (the paper: SKF ≈ 1.15, KF ≈ 0.82·exp(0.0087·p)).
* The 12×18 NOx table of SKF (34), plain and with the sensor model (a = 0.96, τ = 38 samples).
* The full KF on 16×16 from P0 and at steady state (after P has filled), against a plain
  numpy update and FilterPy's ``KalmanFilter`` on the same samples, checking all give the
  same map.
* SKF, SSKF, RLS and NLMS against their plain-numpy updates on the 12×18 table.
* The kernels compiled for a fixed corner count against the generic ones on 2×2, 12×18 and
  21×21 tables with drive-like and uniform inputs: SKF/SSKF and 21×21 / 2×2 time ratios.
* How far the SSKF product gain (SKF (15)) is from the exact 2-D steady-state Riccati gain.
* The observers over a whole cycle: the LPV observer on ``maf-whtc`` (with its LMI gain
  design timed apart) and the three EKF variants on ``maf-1d-whtc``.

``sections`` (``mapwise bench --section NAME``, repeatable) runs only some of these.

Map-filter throughput is the median and the worst of 5 runs after a warm-up (numba compiled),
in CPU time and wall time, one core; the report states the machine (CPU model, cores) and the
load average before and after, since a shared machine makes every figure noisy. Benchmarks
report speed; correctness is the test suite's job (the same-map check here only
guards the comparison).
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Sequence
from typing import Any

from estimation.errors import ConfigError

SECTIONS = (
    "sweep", "nox", "kf", "numpy", "specialisation", "sskf-gain", "simulators", "estimators",
    "observers",
)  # fmt: skip
# Section names earlier releases had, still accepted: `filterpy` is now part of `kf`.
ALIASES = {"filterpy": "kf"}


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
        choices=SECTIONS + tuple(ALIASES),
        help="run only this section (repeatable; default: all; filterpy = kf)",
    )
    p.set_defaults(handler=run_command)


def run_command(args: argparse.Namespace) -> int:
    """``mapwise bench``: the report as text, or as JSON."""
    sections = None if args.section is None else [ALIASES.get(s, s) for s in args.section]
    report = run_benchmarks(quick=args.quick, sections=sections)
    print(json.dumps(report, indent=1) if args.json else format_report(report))
    return 0


def run_benchmarks(*, quick: bool = False, sections: Sequence[str] | None = None) -> dict[str, Any]:
    """Every section of :data:`SECTIONS`, or only those named in ``sections``."""
    # numba kernels: only when benchmarking
    from app.cli import bench_filters, bench_peers, bench_scenarios
    from app.cli.bench_timing import machine

    chosen = set(SECTIONS if sections is None else sections)
    unknown = sorted(chosen - set(SECTIONS))
    if unknown:
        raise ConfigError(f"unknown bench section(s) {unknown}; choose from {list(SECTIONS)}")
    report: dict[str, Any] = {"machine": machine()}
    if "sweep" in chosen:
        sizes = [2, 4, 8, 12, 16] if quick else list(range(2, 22))
        rows = bench_filters.sweep(sizes, quick)
        skf = {r["n"]: r["samples_per_s"]["skf"] for r in rows}
        report["sweep"] = rows
        report["skf_flatness"] = {
            "largest_over_smallest_time": skf[min(skf)] / skf[max(skf)],
            "sizes": [min(skf), max(skf)],
        }
    if "nox" in chosen:
        report["nox_12x18"] = bench_filters.nox_table(quick)
    if "kf" in chosen:
        report["full_kf"] = bench_peers.full_kf(16, quick)
    if "numpy" in chosen:
        report["numpy"] = bench_peers.numpy_comparison(quick)
    if "specialisation" in chosen:
        report["specialisation"] = bench_filters.specialisation(quick)
    if "sskf-gain" in chosen:
        report["sskf_product_vs_exact_gain"] = bench_filters.sskf_gain_gap()
    if "simulators" in chosen:
        report["simulators"] = bench_scenarios.simulators()
    if "estimators" in chosen:
        report["estimators"] = bench_scenarios.estimators_on_scenarios(quick)
    if "observers" in chosen:
        report["observers"] = bench_scenarios.observers_on_scenarios(quick)
    report["machine"]["load_average_after"] = machine()["load_average"]
    return report


def format_report(report: dict[str, Any]) -> str:
    """The report as text; sections not in ``report`` are left out."""
    from app.cli.bench_filters import FILTERS

    lines: list[str] = _machine_lines(report["machine"])
    if "sweep" in report:
        lines += [
            "",
            "Map filters, samples/s of CPU time (kernel, one core, median of 5) and time "
            "relative to SSKF",
            "",
        ]
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
            "12x18 NOx table, samples/s  kernel CPU median (worst)  generic kernel   kernel wall"
            "   end to end CPU   cell changes"
        )
        for name, rate in report["nox_12x18"]["filters"].items():
            lines.append(
                f"  {name:<22} {_median_worst(rate['kernel'], 'cpu'):>26} "
                f"{rate['generic_kernel']['cpu_median']:>16.3g} "
                f"{rate['kernel']['wall_median']:>13.3g} "
                f"{rate['end_to_end']['cpu_median']:>16.3g} {rate['cell_change_rate']:>14.1%}"
            )
    if "full_kf" in report:
        lines += [*_gap(lines), *_full_kf_lines(report["full_kf"])]
    if "numpy" in report:
        lines += _gap(lines)
        lines.append(
            "12x18 table vs plain numpy, samples/s  kernel CPU median (worst)"
            "   numpy CPU median (worst)   speed-up   same map"
        )
        for name, row in report["numpy"]["filters"].items():
            lines.append(
                f"  {name:<36} {_median_worst(row['kernel'], 'cpu'):>26} "
                f"{_median_worst(row['numpy'], 'cpu'):>26} {row['speedup_cpu']:>9.0f}x "
                f"{row['same_map']!s:>9}"
            )
    if "specialisation" in report:
        lines += [*_gap(lines), *_specialisation_lines(report["specialisation"])]
    if "sskf_product_vs_exact_gain" in report:
        gap = report["sskf_product_vs_exact_gain"]
        lines += _gap(lines)
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
            "   gain design s (first)   ρ samples/s",
        ]
        for name, rate in report["observers"].items():
            design = (
                f"{rate['design_s']:>16.3f} ({rate['first_design_s']:.3f})"
                if "design_s" in rate
                else f"{'-':>24}"
            )
            rho = rate.get("rho_samples_per_s")
            rho_col = f"{rho:>14.3g}" if rho is not None else f"{'-':>14}"
            label = f"{name} ({rate['samples']:.0f})"
            lines.append(
                f"  {label:<37} {rate['kernel_samples_per_s']:>17.3g} "
                f"{rate['fit_samples_per_s']:>15.3g} {rate['fit_s']:>8.3f}{design}{rho_col}"
            )
    if "simulators" in report:
        lines += [*_gap(lines), "Ground-truth simulators (wall time, compiled)"]
        for name, sim in report["simulators"].items():
            lines.append(f"  {name:<48} {sim['wall_s']:>7.3f} s")
    return "\n".join(lines)


def _machine_lines(machine: dict[str, Any]) -> list[str]:
    load = machine["load_average"]
    after = machine.get("load_average_after")
    line = (
        f"Machine: {machine['cpu_model']}, {machine['cores']} logical cores, Python "
        f"{machine['python']}, OpenBLAS threads {machine.get('openblas_threads', 'default')}; "
        f"load average (1/5/15 min) {load[0]:.1f} / {load[1]:.1f} / {load[2]:.1f} before"
    )
    if after is not None:
        line += f", {after[0]:.1f} / {after[1]:.1f} / {after[2]:.1f} after"
    return [line]


def _median_worst(rates: dict[str, float], clock: str) -> str:
    return f"{rates[clock + '_median']:.3g} ({rates[clock + '_worst']:.3g})"


def _full_kf_lines(kf: dict[str, Any]) -> list[str]:
    steady, p0 = kf["steady_state"], kf["from_p0"]
    fast = steady["samples_per_s"]["cpu_median"]
    lines = [
        f"Full KF {kf['n']}x{kf['n']} (p={kf['p']}), samples/s of CPU time, median (worst) of 5",
        f"  mapwise kernel from P0 ({kf['timed_samples']} samples, P {p0['p_nonzero_after']:.1%}"
        f" non-zero after)      {_median_worst(p0['samples_per_s'], 'cpu')}",
        f"  mapwise kernel at steady state (after {steady['warm_up_samples']} samples, P "
        f"{steady['p_nonzero']:.1%} non-zero)  {_median_worst(steady['samples_per_s'], 'cpu')}"
        f"  wall {_median_worst(steady['samples_per_s'], 'wall')}",
    ]
    peers = [("plain numpy", kf["numpy"])]
    if kf["filterpy"]["available"]:
        peers.append(("FilterPy KalmanFilter", kf["filterpy"]))
    else:
        lines.append(f"  FilterPy skipped: {kf['filterpy']['note']}")
    for name, peer in peers:
        rate = peer["samples_per_s"]
        lines.append(
            f"  {name} at steady state ({peer['samples']} samples)  "
            f"{_median_worst(rate, 'cpu')}: kernel is {fast / rate['cpu_median']:.0f}x faster "
            f"at steady state, {p0['samples_per_s']['cpu_median'] / rate['cpu_median']:.0f}x "
            f"from P0; same map: {peer['same_map']}"
        )
    return lines


def _specialisation_lines(spec: dict[str, Any]) -> list[str]:
    lines = [
        "Kernels compiled for 4 corners vs generic, samples/s of CPU time (median of 5)",
        f"  {'filter':<6} {'table':>6} {'inputs':>8} {'compiled':>10} {'generic':>10}"
        f" {'speed-up':>9} {'cell changes':>13}",
    ]
    for row in spec["rows"]:
        fast, slow = row["specialised"]["cpu_median"], row["generic"]["cpu_median"]
        lines.append(
            f"  {row['filter']:<6} {row['shape'][0]:>3}x{row['shape'][1]:<2} {row['inputs']:>8}"
            f" {fast:>10.3g} {slow:>10.3g} {fast / slow:>8.2f}x {row['cell_change_rate']:>13.1%}"
        )
    ratios = ", ".join(f"{k} {v:.2f}" for k, v in spec["skf_over_sskf_time"].items())
    lines.append(f"  SKF/SSKF time (target <= 1.15): {ratios}")
    ratios = ", ".join(f"{k} {v:.2f}" for k, v in spec["largest_over_smallest_time"].items())
    lines.append(f"  21x21 / 2x2 time (target <= 1.3): {ratios}")
    return lines


def _gap(lines: list[str]) -> list[str]:
    """A blank line between sections (none before the first)."""
    return [""] if lines else []
