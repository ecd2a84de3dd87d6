"""Make ``docs/img/run-<family>.png``: the finished Run view of one estimator per family.

A map filter (SKF on the NOx NEDC scenario), the LPV observer (MAF error map on the WHTC), the
joint state+map EKF (``ekf-aug`` on the 1-D MAF scenario) and a torque estimator (UIO on the
SI engine). Each dataset is simulated through the REST API and each run starts from the
dataset's own scenario setup (``GET /api/datasets/{id}/setup``), as the New-run form's
"Use the scenario's setup" does. Uses the browser tests' setup (Debian's Chromium through
Playwright, a real ``mapwise serve`` on a temporary SQLite database).

    .venv/bin/python scripts/run_screenshots.py [--out docs/img] [--theme dark|light]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path
from typing import Any

import httpx

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from scripts.page_shot import capture, chromium_missing, open_page  # noqa: E402
from tests.frontend.browser import start_server  # noqa: E402
from tests.support.helpers import wait_run  # noqa: E402

# family -> (estimator, scenario, simulated seconds: enough for a readable map, a short run)
FAMILIES: dict[str, tuple[str, str, float | None]] = {
    "map-filter": ("skf", "nox-nedc", 600.0),
    "lpv": ("lpv", "maf-whtc", 600.0),
    "ekf": ("ekf-aug", "maf-1d-whtc", 600.0),
    "torque": ("uio", "torque-si", None),
}


def start_family_run(
    api: httpx.Client, estimator: str, scenario: str, seconds: float | None
) -> int:
    """Simulate the scenario, start ``estimator`` on the dataset's own setup; the run id."""
    body: dict[str, Any] = {"scenario": scenario, "seed": 100}
    if seconds is not None:
        body["duration_s"] = seconds
    response = api.post("/api/datasets/simulate", json=body, timeout=300)
    response.raise_for_status()
    dataset = response.json()
    setup = api.get(f"/api/datasets/{dataset['id']}/setup").json()["estimators"][estimator]
    run = {
        "dataset_id": dataset["id"],
        "estimator": estimator,
        "name": f"{estimator} on {scenario}",
        **{k: v for k, v in setup.items() if v is not None},
    }
    response = api.post("/api/runs", json=run)
    response.raise_for_status()
    return int(response.json()["id"])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "img")
    parser.add_argument("--theme", choices=["dark", "light"], default="light")
    parser.add_argument("--family", choices=sorted(FAMILIES), action="append")
    args = parser.parse_args(argv)
    if chromium_missing("run_screenshots"):
        return 2
    with tempfile.TemporaryDirectory(prefix="mapwise-shots-") as tmp:
        server = start_server(Path(tmp))
        try:
            with server.api() as api:
                for family in args.family or sorted(FAMILIES):
                    estimator, scenario, seconds = FAMILIES[family]
                    run_id = start_family_run(api, estimator, scenario, seconds)
                    done = wait_run(api, run_id, timeout=600)
                    if done["status"] != "succeeded":
                        raise RuntimeError(f"{estimator} on {scenario}: {done['error']}")
                    out = args.out / f"run-{family}.png"
                    with open_page(f"{server.url}/runs/{run_id}", args.theme) as page:
                        page.locator("[data-plot] .main-svg").first.wait_for()
                        page.wait_for_load_state("networkidle")
                        capture(page, out)
                    print(f"wrote {out}")
        finally:
            server.stop()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
