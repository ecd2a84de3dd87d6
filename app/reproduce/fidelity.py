"""The headline figures of mapwise at one mismatch level, noise level and seed, shared by
``scripts/fidelity.py`` (docs/fidelity.md's table over held-out seeds) and the robustness
section of ``mapwise reproduce`` (:mod:`app.reproduce.robustness`).

Each part ``f(level, seed, noise_scale=1.0)`` builds its scenarios at mismatch ``level`` with
every sensor noise σ of the log multiplied by ``noise_scale`` (the estimators' σ settings as
configured: :meth:`estimation.scenarios.Scenario.build`) and returns ``{key: figure}``:

- ``lpv/<scenario>/<part>``: LPV mean relative error [fraction], whole cycle and the papers'
  segment (WHTC 0–600 s for ETC part 1, FTP-75 0–505 s cold start); at ``nominal`` (noise 1)
  also with single sensor readings (``single``) and with the drawn model before
  identification (``drawn``);
- ``lpv/<scenario>/<part>/literal`` (part ``lpv-literal``, levels none and nominal only): the
  same with the paper's literal law, constant Γ = 200·I (``adaptation="constant"``);
- ``ekf/<variant>``: RMSE of the estimated compressor flow W_c [g/s] on ``maf-1d-whtc``, with
  mapwise's PSD-preserving covariance limit (at ``nominal``, noise 1, also with single
  sensor readings: ``ekf/<variant>/single``); ``ekf/<variant>/diag`` (part ``ekf-literal``)
  the same with the EKF paper's literal diagonal cap (``limit="diag"``);
- ``nox/<who>``: held-out prediction RMSE [ppm] of the measured NOx on ``nox-nedc`` over the
  last 30 % of the record with the map frozen after the first 70 % (kf, skf), the age-0 base
  calibration (``base``) or the filters' initial map θ0 = 0 (``initial``), each through the
  estimator-side sensor model;
- ``torque/<scenario>/<estimator>/<metric>``: ISE, SD, MAE over 5–30 s (TQ (60)–(62)).

:func:`table` and :func:`headline` render such figures (JSON lines ``{"level", "seed",
"figures"}``, optionally ``"noise_scale"``) as Markdown.
"""

from __future__ import annotations

import json
from contextvars import ContextVar
from pathlib import Path
from typing import Any

import numpy as np

from estimation.kernels.sensor import sensor_kernel
from estimation.metrics import map_metrics, torque_metrics
from estimation.registry import get_spec
from estimation.scenarios import Scenario, ScenarioData, get_scenario
from estimation.signals import delay_samples

SEGMENTS_S = {"maf-whtc": 600.0, "maf-ftp75": 505.0}
DURATION_S: ContextVar[float | None] = ContextVar("fidelity_duration_s", default=None)
"""Cut every scenario to its first so many seconds (``None``: whole records, the default;
``mapwise reproduce --robustness-duration``). The papers' segments are cut with it."""
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


def _build(
    sc: Scenario,
    level: str,
    seed: int,
    noise_scale: float = 1.0,
    *,
    averaging: int | None = None,
) -> ScenarioData:
    """One realisation at ``level`` and ``noise_scale``, cut to :data:`DURATION_S` (at most
    the scenario's own duration)."""
    cut = DURATION_S.get()
    return sc.build(
        seed=seed,
        duration_s=None if cut is None else min(cut, sc.duration_s),
        mismatch=level,  # type: ignore[arg-type]
        averaging=averaging,
        noise_scale=noise_scale,
    )


def lpv_mre(data: ScenarioData, config: dict[str, Any]) -> float:
    snap = get_spec("lpv").build(config).fit(data.signals)
    assert data.true_map is not None
    return map_metrics(
        snap.table, data.true_map, data.scoring_points(), truth_along=data.true_along
    )["mean_relative_error"]


def lpv(level: str, seed: int, noise_scale: float = 1.0) -> dict[str, float]:
    out = {}
    for name, seconds in SEGMENTS_S.items():
        sc = get_scenario(name)
        data = _build(sc, level, seed, noise_scale)
        config = sc.default_config("lpv", data=data)
        out[f"lpv/{name}/full"] = lpv_mre(data, config)
        out[f"lpv/{name}/segment"] = lpv_mre(head(data, seconds), config)
        if level == "nominal" and noise_scale == 1.0:
            drawn = config | {"model": config["model"] | data.metadata["identification"]["drawn"]}
            out[f"lpv/{name}/segment/drawn"] = lpv_mre(head(data, seconds), drawn)
            single = _build(sc, level, seed, averaging=1)
            config1 = sc.default_config("lpv", data=single)
            out[f"lpv/{name}/full/single"] = lpv_mre(single, config1)
            out[f"lpv/{name}/segment/single"] = lpv_mre(head(single, seconds), config1)
    return out


LPV_LITERAL = {"adaptation": "constant", "gamma": 200.0}
"""LPV (24)–(25) as printed: the constant adaptation gain Γ = 200·I (docs/estimators.md)."""


def lpv_literal(level: str, seed: int, noise_scale: float = 1.0) -> dict[str, float]:
    """The paper's literal LPV law beside the adaptive-gain one, at ``none`` and ``nominal``
    only (elsewhere: nothing)."""
    out: dict[str, float] = {}
    if level not in ("none", "nominal"):
        return out
    for name, seconds in SEGMENTS_S.items():
        sc = get_scenario(name)
        data = _build(sc, level, seed, noise_scale)
        config = sc.default_config("lpv", data=data) | LPV_LITERAL
        with np.errstate(all="ignore"):
            out[f"lpv/{name}/full/literal"] = lpv_mre(data, config)
            out[f"lpv/{name}/segment/literal"] = lpv_mre(head(data, seconds), config)
    return out


EKF_VARIANTS = ("ekf-def", "ekf-aug", "ekf-map")


def _ekf(
    level: str,
    seed: int,
    noise_scale: float,
    variants: tuple[str, ...],
    limit: str | None,
    *,
    averaging: int | None = None,
) -> dict[str, float]:
    sc = get_scenario("maf-1d-whtc")
    data = _build(sc, level, seed, noise_scale, averaging=averaging)
    truth = data.scored_series["w_c_kg_s"]
    out = {}
    for name in variants:
        config = sc.default_config(name, data=data)
        if limit is not None:
            config |= {"limit": limit}
        snap = get_spec(name).build(config).fit(data.signals)
        error = snap.outputs["w_c_kg_s"] - truth
        suffix = ("" if limit is None else f"/{limit}") + ("/single" if averaging == 1 else "")
        out[f"ekf/{name}{suffix}"] = 1e3 * float(np.sqrt(np.mean(error**2)))
    return out


def ekf(level: str, seed: int, noise_scale: float = 1.0) -> dict[str, float]:
    """W_c RMSE [g/s] of Def, Aug and Map with mapwise's PSD-preserving limit; at
    ``nominal`` (noise 1) also with single sensor readings (``ekf/<variant>/single``), as the
    LPV figures are."""
    out = _ekf(level, seed, noise_scale, EKF_VARIANTS, None)
    if level == "nominal" and noise_scale == 1.0:
        out |= _ekf(level, seed, noise_scale, EKF_VARIANTS, None, averaging=1)
    return out


def ekf_literal(level: str, seed: int, noise_scale: float = 1.0) -> dict[str, float]:
    """W_c RMSE [g/s] of Aug and Map (the variants with parameters to cap) with the EKF
    paper's literal diagonal cap, ``limit="diag"`` (docs/algorithms.md §2.5)."""
    return _ekf(level, seed, noise_scale, ("ekf-aug", "ekf-map"), "diag")


def nox(level: str, seed: int, noise_scale: float = 1.0) -> dict[str, float]:
    from estimation.plants.nox import nox_base_map

    sc = get_scenario("nox-nedc")
    data = _build(sc, level, seed, noise_scale)
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


def torque(level: str, seed: int, noise_scale: float = 1.0) -> dict[str, float]:
    out = {}
    for name in ("torque-si", "torque-rig"):
        sc = get_scenario(name)
        data = _build(sc, level, seed, noise_scale)
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


PARTS = {
    "lpv": lpv,
    "lpv-literal": lpv_literal,
    "ekf": ekf,
    "ekf-literal": ekf_literal,
    "nox": nox,
    "torque": torque,
}
"""Every part by name; ``scripts/fidelity.py --parts`` picks from these."""


def parse_seeds(text: str) -> list[int]:
    if "-" in text:
        lo, hi = text.split("-")
        return list(range(int(lo), int(hi) + 1))
    return [int(s) for s in text.split(",")]


Record = dict[str, Any]
"""One line of a figures file: ``{"level", "seed", "figures"}`` and optionally
``"noise_scale"`` (default 1)."""

LEVELS = ("none", "nominal", "severe")


def read_records(paths: list[Path]) -> list[Record]:
    """Every record of the JSON-lines files."""
    return [json.loads(line) for path in paths for line in path.read_text().splitlines()]


def column_of(record: Record) -> str:
    """The column a record belongs to: its level, with ``noise × s`` where s ≠ 1."""
    scale = float(record.get("noise_scale", 1.0))
    return record["level"] if scale == 1.0 else f"{record['level']}, noise × {scale:g}"


def collect(records: list[Record]) -> dict[str, dict[str, list[float]]]:
    """Every figure per key and column (:func:`column_of`), over the seeds."""
    rows: dict[str, dict[str, list[float]]] = {}
    for rec in records:
        for key, value in rec["figures"].items():
            rows.setdefault(key, {}).setdefault(column_of(rec), []).append(value)
    return rows


def _figures(paths: list[Path]) -> dict[str, dict[str, list[float]]]:
    return collect(read_records(paths))


def table(paths: list[Path], columns: tuple[str, ...] = LEVELS) -> str:
    """Every figure (seed mean, range and count) per column, as Markdown."""
    rows = _figures(paths)
    lines = ["| figure | " + " | ".join(columns) + " |", "|---|" + "---|" * len(columns)]
    for key in sorted(rows):
        cells = []
        for column in columns:
            v = rows[key].get(column)
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
    ("EKF W_c RMSE, Def, single readings [g/s]", "ekf/ekf-def/single", ""),
    ("EKF W_c RMSE, Aug, single readings [g/s]", "ekf/ekf-aug/single", ""),
    ("EKF W_c RMSE, Map, single readings [g/s]", "ekf/ekf-map/single", ""),
    ("EKF W_c RMSE, Aug, paper's diagonal cap [g/s]", "ekf/ekf-aug/diag", ""),
    ("EKF W_c RMSE, Map, paper's diagonal cap [g/s]", "ekf/ekf-map/diag", ""),
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
"""(label, key or ``head{a,b}tail`` pattern of keys, unit: ``"%"`` scales by 100)."""


def expand(pattern: str) -> list[str]:
    """``"a/{x,y}/b"`` → ``["a/x/b", "a/y/b"]``; a plain key → ``[key]``."""
    head, _, rest = pattern.partition("{")
    if not rest:
        return [pattern]
    inner, _, tail = rest.partition("}")
    return [head + k + tail for k in inner.split(",")]


def headline_rows(
    rows: dict[str, dict[str, list[float]]], columns: tuple[str, ...]
) -> list[tuple[str, list[str]]]:
    """One ``(label, cells)`` per :data:`HEADLINE` entry with any figure: per column the
    seed mean (with the range for a single key), ``—`` where there is none."""
    out = []
    for label, pattern, unit in HEADLINE:
        keys = expand(pattern)
        if not any(key in rows for key in keys):
            continue
        cells = []
        for column in columns:
            parts = []
            for key in keys:
                v = np.array(rows.get(key, {}).get(column, []), dtype=float)
                if v.size == 0:
                    parts.append("—")
                    continue
                v = v * (100.0 if unit == "%" else 1.0)
                text = f"{v.mean():.3g}"
                if len(keys) == 1 and v.size > 1:
                    text += f" ({v.min():.3g}–{v.max():.3g})"
                parts.append(text)
            cells.append(" / ".join(parts))
        out.append((label, cells))
    return out


def headline(paths: list[Path], columns: tuple[str, ...] = LEVELS) -> str:
    """The README table: seed means (range) of the headline figures per level."""
    rows = _figures(paths)
    out = [
        "| figure (seeds 100–109) | " + " | ".join(columns) + " |",
        "|---|" + "---|" * len(columns),
    ]
    for label, cells in headline_rows(rows, columns):
        out.append(f"| {label} | " + " | ".join(cells) + " |")
    return "\n".join(out)
