"""docs/estimators.md#torque-results from a ``mapwise reproduce --only torque`` report: the
per-seed ISE and SD of TQ Tables III/IV (torque-si) and VI/VII (torque-rig) as ranges over
the seeds, beside the paper's values, so the table is never typed by hand.

    mapwise reproduce --only torque --seeds 0,1,2 --out reproduce
    .venv/bin/python scripts/torque_results.py reproduce/report.md
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

ROWS = (
    ("`uio`", "UIO (14)", "III", "VI"),
    ("`smo`", "Sliding mode (21)", "III", "VI"),
    ("`dirty`", "Dirty diff. (24)", "III", "VI"),
    ("(50) κ = 0", "(50) κ = 0", "IV", "VII"),
    ("(50) κ = 0.1", "(50) κ = 0.1", "IV", "VII"),
    ("(54) κ = 0", "(54) κ = 0", "IV", "VII"),
    ("(54) κ = 0.1", "(54) κ = 0.1", "IV", "VII"),
)


def tables(markdown: str) -> dict[tuple[str, str, str], tuple[str, list[float]]]:
    """(table, index, estimator) → (paper's value, our per-seed values)."""
    out = {}
    table = None
    for line in markdown.splitlines():
        m = re.match(r"\*torque-(?:si|rig): TQ Table (\w+) beside ours\.\*", line)
        if m:
            table = m.group(1)
            continue
        if table is None or not line.startswith("| ") or line.startswith("| Index"):
            continue
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        index, estimator, paper, *seeds, _ratio = cells
        out[(table, index.split(" ")[0], estimator)] = (paper, [float(s) for s in seeds])
    return out


def span(values: list[float]) -> str:
    lo, hi = f"{min(values):.4g}", f"{max(values):.4g}"
    return lo if lo == hi else f"{lo}–{hi}"


def main(path: str) -> str:
    t = tables(Path(path).read_text(encoding="utf-8"))
    lines = [
        "| | paper | `torque-si` (SI engine, §VI) | paper | `torque-rig` (diesel rig, §VII) |",
        "|---|---|---|---|---|",
    ]
    for label, name, si, rig in ROWS:
        cells = []
        for table in (si, rig):
            ise_paper, ise = t[(table, "ISE", name)]
            sd_paper, sd = t[(table, "SD", name)]
            cells += [f"{ise_paper} / {sd_paper}", f"{span(ise)} / {span(sd)}"]
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


if __name__ == "__main__":
    print(main(sys.argv[1]))
