"""The fidelity table of docs/fidelity.md: the headline figures at mismatch none / nominal /
severe on held-out seeds.

    .venv/bin/python scripts/fidelity.py --seeds 100-109 --levels none,nominal,severe \
        --out fidelity.json

Prints one JSON line per (level, seed) as it goes and writes every figure to ``--out``;
``--table`` reads such files and prints the Markdown tables (seed mean and range);
``--noise-scale S`` multiplies every sensor noise σ of the logs (records carry it).
The figures and their tables are :mod:`app.reproduce.fidelity`'s (shared with the robustness
section of ``mapwise reproduce``), which says what each figure is.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from app.reproduce.fidelity import PARTS, headline, parse_seeds, table


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seeds", default="100-109")
    p.add_argument("--levels", default="none,nominal,severe")
    p.add_argument("--parts", default=",".join(PARTS))
    p.add_argument("--noise-scale", type=float, default=1.0, help="factor on every noise σ")
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
                    figures |= PARTS[part](level, seed, args.noise_scale)
                record = {"level": level, "seed": seed, "figures": figures}
                if args.noise_scale != 1.0:
                    record["noise_scale"] = args.noise_scale
                line = json.dumps(record)
                print(line, file=sys.stderr)
                f.write(line + "\n")
                f.flush()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
