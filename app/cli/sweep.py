"""``mapwise sweep``: a tuning sweep through a running mapwise server's REST API.

It builds the ``POST /api/sweeps`` body from flags, waits for every run (on whatever executor
the server uses: its process pool or a Dask cluster) and prints the runs ranked by the metric.
An error from the server is one line on stderr naming its field, exit code 2.

    mapwise sweep --url http://127.0.0.1:8000 --dataset 3 --estimator skf --y nox_ppm \\
        --axis speed_rpm=750,1500,3000 --axis fuel_mg_per_stroke=0,20,40,80 \\
        --set p0=10000 --grid sigma_w=5,10,15 --grid sigma_v=10,25 --metric output_rmse
"""

from __future__ import annotations

import argparse
import json
import os
import time
from typing import Any

from app.cli.errors import UsageError
from app.domain import FINISHED, RunStatus


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "sweep",
        help="run a tuning sweep on a mapwise server and rank the runs",
        description="Sweep an estimator's settings over one dataset on a mapwise server: "
        "--grid key=v1,v2,... (the product of all grids) or --range key=MIN:MAX[:log] with "
        "--samples N (seeded random draws). Fixed settings with --set key=value. Values are "
        "JSON where they parse. Prints the runs best first by --metric.",
    )
    p.add_argument("--url", default="http://127.0.0.1:8000", help="the server")
    p.add_argument("--token", help="bearer token (default MAPWISE_TOKEN)")
    p.add_argument("--dataset", type=int, required=True, help="dataset id")
    p.add_argument("--estimator", required=True)
    p.add_argument("--y", metavar="COLUMN", help="measured table output (table filters)")
    p.add_argument("--signal", action="append", default=[], metavar="ROLE=COLUMN")
    p.add_argument("--axis", action="append", default=[], metavar="NAME=B1,B2,...")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    p.add_argument("--grid", action="append", default=[], metavar="KEY=V1,V2,...")
    p.add_argument("--range", action="append", default=[], metavar="KEY=MIN:MAX[:log]")
    p.add_argument("--samples", type=int, help="random sample size (with --range)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--metric", default="output_rmse", help="ranking metric (default output_rmse)")
    p.add_argument("--order", choices=["min", "max"], default="min")
    p.add_argument("--name")
    p.add_argument("--timeout", type=float, default=3600.0, help="seconds to wait for the runs")
    p.add_argument("--no-wait", action="store_true", help="print the sweep id and return")
    p.add_argument("--json", action="store_true", help="print the final sweep document")
    p.set_defaults(handler=run_command)


def _value(raw: str) -> Any:
    try:
        return json.loads(raw)
    except json.JSONDecodeError:
        return raw


def _pairs(items: list[str], flag: str) -> list[tuple[str, str]]:
    out = []
    for item in items:
        key, sep, raw = item.partition("=")
        if not sep or not key.strip() or not raw:
            raise UsageError(f"{flag} {item!r}: expected KEY=VALUE")
        out.append((key.strip(), raw))
    return out


def sweep_body(args: argparse.Namespace) -> dict[str, Any]:
    from app.cli.run import parse_set

    parameters: dict[str, Any] = {}
    for key, raw in _pairs(args.grid, "--grid"):
        parameters[key] = [_value(v) for v in raw.split(",")]
    for key, raw in _pairs(args.range, "--range"):
        parts = raw.split(":")
        try:
            low, high = float(parts[0]), float(parts[1])
        except (ValueError, IndexError):
            raise UsageError(f"--range {key}={raw}: expected MIN:MAX[:log]") from None
        scale = parts[2] if len(parts) > 2 else "linear"
        parameters[key] = {"min": low, "max": high, "scale": scale}
    if not parameters:
        raise UsageError("give at least one --grid or --range")
    signals = dict(_pairs(args.signal, "--signal"))
    if args.y:
        signals["y"] = args.y
    body: dict[str, Any] = {
        "dataset_id": args.dataset,
        "estimator": args.estimator,
        "signals": signals,
        "config": parse_set(args.set),
        "parameters": parameters,
        "seed": args.seed,
        "metric": args.metric,
        "order": args.order,
    }
    if args.axis:
        axes = []
        for name, raw in _pairs(args.axis, "--axis"):
            try:
                axes.append({"name": name, "breakpoints": [float(v) for v in raw.split(",")]})
            except ValueError:
                raise UsageError(f"--axis {name}: breakpoints must be numbers") from None
        body["table"] = {"axes": axes}
    if args.samples is not None:
        body["samples"] = args.samples
    if args.name:
        body["name"] = args.name
    return body


def run_command(args: argparse.Namespace) -> int:
    """``mapwise sweep``: create the sweep, wait for its runs, print the ranking; exit code 1
    if a run did not succeed."""
    import httpx

    body = sweep_body(args)
    token = args.token or os.environ.get("MAPWISE_TOKEN")
    headers = {"Authorization": f"Bearer {token}"} if token else {}
    try:
        with httpx.Client(base_url=args.url, headers=headers, timeout=60) as client:
            sweep = _checked(client.post("/api/sweeps", json=body))
            if args.no_wait:
                print(sweep["id"])
                return 0
            deadline = time.monotonic() + args.timeout
            while any(r["status"] not in FINISHED for r in sweep["runs"]):
                if time.monotonic() > deadline:
                    raise UsageError(f"sweep {sweep['id']} not finished after {args.timeout} s")
                time.sleep(0.5)
                sweep = _checked(client.get(f"/api/sweeps/{sweep['id']}"))
    except httpx.HTTPError as exc:
        raise UsageError(f"cannot reach the mapwise server at {args.url}: {exc}") from None
    if args.json:
        print(json.dumps(sweep, indent=1))
    else:
        print(format_ranking(sweep))
    return 0 if all(r["status"] == RunStatus.SUCCEEDED for r in sweep["runs"]) else 1


def _checked(response: Any) -> dict[str, Any]:
    if response.status_code >= 400:
        try:
            error = response.json()["error"]
            where = f"{error['field']}: " if error.get("field") else ""
            message = f"{where}{error['message']}"
        except (ValueError, KeyError, TypeError):
            message = f"HTTP {response.status_code}"
        raise UsageError(message)
    return dict(response.json())


def format_ranking(sweep: dict[str, Any]) -> str:
    metric = sweep["metric"]
    lines = [f"sweep {sweep['id']}: {sweep['name']} — best {sweep['order']} {metric} first", ""]
    keys = list(sweep["request"]["parameters"])
    lines.append(f"{'rank':>4} {'run':>6} " + "".join(f"{k:>14}" for k in keys) + f" {metric:>14}")
    for i, run in enumerate(sweep["runs"], start=1):
        values = "".join(f"{_fmt((run['params'] or {}).get(k)):>14}" for k in keys)
        value = _fmt(run["metric"]) if run["status"] == RunStatus.SUCCEEDED else run["status"]
        lines.append(f"{i:>4} {run['id']:>6} {values} {value:>14}")
    return "\n".join(lines)


def _fmt(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:.5g}"
    return "-" if value is None else str(value)
