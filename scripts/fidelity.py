"""The fidelity table of docs/fidelity.md: the headline figures at mismatch none / nominal /
severe on held-out seeds.

    .venv/bin/python scripts/fidelity.py --seeds 100-109 --levels none,nominal,severe \
        --out fidelity.json

Prints one JSON line per (level, seed) as it goes and writes every figure to ``--out``;
``--table`` reads such files and prints the Markdown tables (seed mean and range).
Figures (docs/fidelity.md says what each is):

- ``lpv/<scenario>/<part>``: LPV mean relative error, whole cycle and the papers' segment
  (WHTC 0–600 s for ETC part 1, FTP-75 0–505 s cold start); at ``nominal`` also with single
  sensor readings (``single``) and with the drawn model before identification (``drawn``);
- ``lpv/<scenario>/<part>/literal`` (part ``lpv-literal``, levels none and nominal only): the
  same with the paper's literal law, constant Γ = 200·I (``adaptation="constant"``);
- ``ekf/<variant>``: RMSE of the estimated compressor flow W_c [g/s] on ``maf-1d-whtc``;
- ``nox/<who>``: held-out prediction RMSE [ppm] of the measured NOx on ``nox-nedc`` over the
  last 30 % of the record with the map frozen after the first 70 % (kf, skf), the age-0 base
  calibration (``base``) or the filters' initial map θ0 = 0 (``initial``), each through the
  estimator-side sensor model;
- ``torque/<scenario>/<estimator>/<metric>``: ISE, SD, MAE over 5–30 s (TQ (60)–(62)).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from estimation.kernels.sensor import sensor_kernel
from estimation.metrics import map_metrics, torque_metrics
from estimation.registry import get_spec
from estimation.scenarios import ScenarioData, get_scenario
from estimation.signals import delay_samples

SEGMENTS_S = {"maf-whtc": 600.0, "maf-ftp75": 505.0}
TORQUE = ("uio", "smo", "dirty", "adaptive-const/0.0", "adaptive-const/0.1", "adaptive-tv/0.0")
TORQUE += ("adaptive-tv/0.1",)


def head(data: ScenarioData, seconds: float) -> ScenarioData:
    """The realisation cut to its first ``seconds`` (signals, scoring points, truth along)."""
    import dataclasses

    t = data.signals.time
    stop = int(np.searchsorted(t, t[0] + seconds, side="right"))
    return dataclasses.replace(
        data,
        signals=data.signals.slice(0, stop),
        map_points=None if data.map_points is None else data.map_points[:stop],
        true_along=None if data.true_along is None else data.true_along[:stop],
        scored_series={k: v[:stop] for k, v in data.scored_series.items()},
    )


def lpv_mre(data: ScenarioData, config: dict[str, Any]) -> float:
    snap = get_spec("lpv").build(config).fit(data.signals)
    assert data.true_map is not None
    return map_metrics(
        snap.table, data.true_map, data.scoring_points(), truth_along=data.true_along
    )["mean_relative_error"]


def lpv(level: str, seed: int) -> dict[str, float]:
    out = {}
    for name, seconds in SEGMENTS_S.items():
        sc = get_scenario(name)
        data = sc.build(seed=seed, mismatch=level)  # type: ignore[arg-type]
        config = sc.default_config("lpv", data=data)
        out[f"lpv/{name}/full"] = lpv_mre(data, config)
        out[f"lpv/{name}/segment"] = lpv_mre(head(data, seconds), config)
        if level == "nominal":
            drawn = config | {"model": config["model"] | data.metadata["identification"]["drawn"]}
            out[f"lpv/{name}/segment/drawn"] = lpv_mre(head(data, seconds), drawn)
            single = sc.build(seed=seed, mismatch=level, averaging=1)  # type: ignore[arg-type]
            config1 = sc.default_config("lpv", data=single)
            out[f"lpv/{name}/full/single"] = lpv_mre(single, config1)
            out[f"lpv/{name}/segment/single"] = lpv_mre(head(single, seconds), config1)
    return out


LPV_LITERAL = {"adaptation": "constant", "gamma": 200.0}
"""LPV (24)–(25) as printed: the constant adaptation gain Γ = 200·I (docs/estimators.md)."""


def lpv_literal(level: str, seed: int) -> dict[str, float]:
    """The paper's literal LPV law beside the adaptive-gain one, at ``none`` and ``nominal``
    only (elsewhere: nothing)."""
    out: dict[str, float] = {}
    if level not in ("none", "nominal"):
        return out
    for name, seconds in SEGMENTS_S.items():
        sc = get_scenario(name)
        data = sc.build(seed=seed, mismatch=level)  # type: ignore[arg-type]
        config = sc.default_config("lpv", data=data) | LPV_LITERAL
        with np.errstate(all="ignore"):
            out[f"lpv/{name}/full/literal"] = lpv_mre(data, config)
            out[f"lpv/{name}/segment/literal"] = lpv_mre(head(data, seconds), config)
    return out


def ekf(level: str, seed: int) -> dict[str, float]:
    sc = get_scenario("maf-1d-whtc")
    data = sc.build(seed=seed, mismatch=level)  # type: ignore[arg-type]
    truth = data.scored_series["w_c_kg_s"]
    out = {}
    for name in ("ekf-def", "ekf-aug", "ekf-map"):
        snap = get_spec(name).build(sc.default_config(name, data=data)).fit(data.signals)
        error = snap.outputs["w_c_kg_s"] - truth
        out[f"ekf/{name}"] = 1e3 * float(np.sqrt(np.mean(error**2)))
    return out


def nox(level: str, seed: int) -> dict[str, float]:
    from estimation.plants.nox import nox_base_map

    sc = get_scenario("nox-nedc")
    data = sc.build(seed=seed, mismatch=level)  # type: ignore[arg-type]
    n = len(data.signals)
    split = int(0.7 * n)
    inputs = data.signals.stack(list(data.map_inputs))
    measured = data.signals["nox_ppm"]
    out = {}
    base = nox_base_map()
    tables = {"base": base, "initial": base.with_values(np.zeros(base.shape))}
    for name in ("kf", "skf"):
        config = sc.default_config(name, data=data)
        tables[name] = get_spec(name).build(config).fit(data.signals.slice(0, split)).table
    sensor = sc.default_config("skf", data=data)["sensor"]
    period = data.signals.sample_period()
    tau = delay_samples(float(sensor["delay_s"]), period)
    for who, table in tables.items():
        x = np.ascontiguousarray(table.evaluate(inputs))
        y = np.empty(n)
        sensor_kernel(x, tau, float(sensor["lag"]), float(x[0]), y)
        out[f"nox/{who}"] = float(np.sqrt(np.mean((y[split:] - measured[split:]) ** 2)))
    return out


def torque(level: str, seed: int) -> dict[str, float]:
    out = {}
    for name in ("torque-si", "torque-rig"):
        sc = get_scenario(name)
        data = sc.build(seed=seed, mismatch=level)  # type: ignore[arg-type]
        truth = data.scored_series["torque_nm"]
        t = data.signals.time
        for key in TORQUE:
            est, _, kappa = key.partition("/")
            config = sc.default_config(est, data=data)
            if kappa:
                config |= {"kappa": float(kappa)}
            with np.errstate(all="ignore"):
                estimate = get_spec(est).build(config).fit(data.signals).outputs["torque_nm"]
            m = torque_metrics(t, truth - estimate, window_s=(5.0, 30.0))
            for metric in ("ise", "sd", "mae"):
                out[f"torque/{name}/{key}/{metric}"] = float(m[metric])
    return out


PARTS = {"lpv": lpv, "lpv-literal": lpv_literal, "ekf": ekf, "nox": nox, "torque": torque}


def parse_seeds(text: str) -> list[int]:
    if "-" in text:
        lo, hi = text.split("-")
        return list(range(int(lo), int(hi) + 1))
    return [int(s) for s in text.split(",")]


def _figures(paths: list[Path]) -> dict[str, dict[str, list[float]]]:
    """Every figure of the JSON-lines files, per key and mismatch level, over the seeds."""
    rows: dict[str, dict[str, list[float]]] = {}
    for path in paths:
        for line in path.read_text().splitlines():
            rec = json.loads(line)
            for key, value in rec["figures"].items():
                rows.setdefault(key, {}).setdefault(rec["level"], []).append(value)
    return rows


def table(paths: list[Path]) -> str:
    rows = _figures(paths)
    levels = ("none", "nominal", "severe")
    lines = ["| figure | " + " | ".join(levels) + " |", "|---|" + "---|" * len(levels)]
    for key in sorted(rows):
        cells = []
        for level in levels:
            v = rows[key].get(level)
            if not v:
                cells.append("—")
                continue
            scale = 100.0 if key.startswith("lpv/") else 1.0
            a = np.array(v) * scale
            cells.append(f"{a.mean():.3g} ({a.min():.3g}–{a.max():.3g}, n={a.size})")
        lines.append(f"| {key} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


HEADLINE = (
    ("LPV MRE, WHTC 0–600 s (paper ETC part 1: 10.41 %)", "lpv/maf-whtc/segment", "%"),
    ("LPV MRE, FTP-75 0–505 s (paper: 5.28 %)", "lpv/maf-ftp75/segment", "%"),
    ("LPV MRE, whole WHTC", "lpv/maf-whtc/full", "%"),
    ("LPV MRE, whole FTP-75", "lpv/maf-ftp75/full", "%"),
    ("LPV MRE, WHTC 0–600 s, single readings", "lpv/maf-whtc/segment/single", "%"),
    ("LPV MRE, FTP-75 0–505 s, single readings", "lpv/maf-ftp75/segment/single", "%"),
    ("LPV MRE, WHTC 0–600 s, paper's law Γ = 200 I", "lpv/maf-whtc/segment/literal", "%"),
    ("LPV MRE, FTP-75 0–505 s, paper's law Γ = 200 I", "lpv/maf-ftp75/segment/literal", "%"),
    ("EKF W_c RMSE, Def [g/s]", "ekf/ekf-def", ""),
    ("EKF W_c RMSE, Aug [g/s]", "ekf/ekf-aug", ""),
    ("EKF W_c RMSE, Map [g/s]", "ekf/ekf-map", ""),
    ("NOx held-out RMSE, KF [ppm]", "nox/kf", ""),
    ("NOx held-out RMSE, SKF [ppm]", "nox/skf", ""),
    ("NOx held-out RMSE, θ0 = 0 [ppm]", "nox/initial", ""),
    ("NOx held-out RMSE, age-0 calibration [ppm]", "nox/base", ""),
    ("torque-si ISE, UIO / SMO / dirty", "torque/torque-si/{uio,smo,dirty}/ise", ""),
    ("torque-rig ISE, UIO / SMO / dirty", "torque/torque-rig/{uio,smo,dirty}/ise", ""),
    (
        "torque-si ISE, (54) κ = 0.1 / (50) κ = 0",
        "torque/torque-si/{adaptive-tv/0.1,adaptive-const/0.0}/ise",
        "",
    ),
    (
        "torque-rig ISE, (54) κ = 0.1 / (50) κ = 0.1",
        "torque/torque-rig/{adaptive-tv/0.1,adaptive-const/0.1}/ise",
        "",
    ),
)


def headline(paths: list[Path]) -> str:
    """The README table: seed means (range) of the headline figures per level."""
    rows = _figures(paths)
    levels = ("none", "nominal", "severe")
    out = ["| figure (seeds 100–109) | " + " | ".join(levels) + " |", "|---|---|---|---|"]
    for label, pattern, unit in HEADLINE:
        head, _, rest = pattern.partition("{")
        keys = (
            [head + k + rest.split("}")[1] for k in rest.split("}")[0].split(",")]
            if rest
            else [pattern]
        )
        cells = []
        for level in levels:
            parts = []
            for key in keys:
                v = np.array(rows.get(key, {}).get(level, []))
                if v.size == 0:
                    parts.append("—")
                    continue
                v = v * (100.0 if unit == "%" else 1.0)
                fmt = ".3g"
                text = f"{v.mean():{fmt}}"
                if len(keys) == 1:
                    text += f" ({v.min():{fmt}}–{v.max():{fmt}})"
                parts.append(text)
            cells.append(" / ".join(parts))
        out.append(f"| {label} | " + " | ".join(cells) + " |")
    return "\n".join(out)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seeds", default="100-109")
    p.add_argument("--levels", default="none,nominal,severe")
    p.add_argument("--parts", default=",".join(PARTS))
    p.add_argument("--out", type=Path, default=Path("fidelity.jsonl"))
    p.add_argument("--table", nargs="*", type=Path, help="print the tables of these files")
    p.add_argument("--headline", nargs="*", type=Path, help="print the README table of these")
    args = p.parse_args()
    if args.table:
        print(table(args.table))
        return 0
    if args.headline:
        print(headline(args.headline))
        return 0
    with args.out.open("a") as f:
        for level in args.levels.split(","):
            for seed in parse_seeds(args.seeds):
                figures: dict[str, float] = {}
                for part in args.parts.split(","):
                    figures |= PARTS[part](level, seed)
                line = json.dumps({"level": level, "seed": seed, "figures": figures})
                print(line, file=sys.stderr)
                f.write(line + "\n")
                f.flush()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
