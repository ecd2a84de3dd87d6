"""``mapwise reproduce``: run every section live and write ``report.md``, ``report.html``
and ``report.json``.

Nothing of ours is stored: each section runs the registered estimators on the catalog's
scenarios (:func:`app.cli.run.execute_scenario`) for the chosen seeds and puts the
results beside the papers' constants (:mod:`app.reproduce.paper_values`).

The default seeds are the held-out ones, 100–109, on which nothing was tuned
(:mod:`app.reproduce.seeds`); every seed is labelled held-out, tuning or other in the report.

``report.json`` (a contract: extend, never break)::

    {"title", "command", "seeds", "seconds", "mismatch", "seed_kinds",
     "sections": [{"key", "title", "verdict", "seconds", "data"}]}

``command`` is the command line that reproduces the report (every setting that changes a
figure: seeds, sections, ``--mismatch``, the robustness study's parts and duration);
``seed_kinds`` maps each seed to ``"held-out"``, ``"tuning"`` or ``"other"``.

``data`` is the section's figures where it has them as data (the robustness study: its
cells and one record ``{"level", "noise_scale", "seed", "figures"}`` per cell and seed), else
``{}``.
"""

from __future__ import annotations

import importlib
import json
import math
import time
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from app.reproduce import seeds as seed_kinds
from app.reproduce.report import Section, Table, Text, to_markdown, write_html
from estimation.errors import ConfigError

DEFAULT_SEEDS = seed_kinds.HELD_OUT_SEEDS
"""The held-out seeds 100–109: the ten default seeds take about 3–5 min of wall time in all
(measured on the shared 2-core machine: 176 s for the five paper sections before the
papers'-segment rows and the LPV γ sweep were added, 31 s for one seed)."""
DEFAULT_OUT = Path("reproduce")
TITLE = "mapwise — the four papers' results beside ours"


MODULES = {
    "skf": "app.reproduce.skf_sims",
    "nox": "app.reproduce.nox",
    "lpv": "app.reproduce.lpv",
    "ekf": "app.reproduce.ekf",
    "torque": "app.reproduce.torque",
    "sensitivity": "app.reproduce.sensitivity",
    "robustness": "app.reproduce.robustness",
}
"""Section key → the module whose ``build(seeds)`` makes it, in report order."""
SECTION_KEYS = tuple(MODULES)
OPT_IN = ("robustness",)
"""Sections run only when asked for (``--robustness`` or ``--only``): the robustness study
runs every headline figure in five cells: 66 s of CPU for one seed (9 min wall on a loaded
2-core machine), against seconds for most sections."""
DEFAULT_KEYS = tuple(k for k in SECTION_KEYS if k not in OPT_IN)


def _builder(key: str) -> Callable[[Sequence[int]], Section]:
    return importlib.import_module(MODULES[key]).build  # type: ignore[no-any-return]


@dataclass(frozen=True, slots=True)
class Reproduced:
    """What a run wrote, how long each section took [s], and which sections failed."""

    markdown: Path
    html: Path
    sections: tuple[tuple[Section, float], ...]
    seconds: float
    json: Path | None = None

    @property
    def failed(self) -> list[str]:
        return [s.key for s, _ in self.sections if s.verdict.startswith(FAILED)]


FAILED = "FAILED"


def _build_section(key: str, seeds: Sequence[int]) -> Section:
    """Run one section; an exception (other helpers' code may be mid-change) becomes a
    section that says so, so the rest of the report is still written."""
    try:
        return _builder(key)(list(seeds))
    except Exception as exc:
        message = " ".join(str(exc).split()) or type(exc).__name__
        return Section(
            key=key,
            title=f"{key}: failed",
            verdict=f"{FAILED}: {type(exc).__name__}: {message}",
            blocks=[Text(f"```\n{traceback.format_exc()}```")],
        )


MAX_SEEDS = 1000
"""Longest range ``a-b`` :func:`parse_seeds` expands."""


def parse_seeds(text: str) -> tuple[int, ...]:
    """``"0,1,2"`` → ``(0, 1, 2)``, ``"100-103,7"`` → ``(100, 101, 102, 103, 7)``: distinct
    non-negative integers and inclusive ranges ``a-b`` (``a <= b``), in the order given."""
    seeds: list[int] = []
    for part in text.split(","):
        lo, dash, hi = part.strip().partition("-")
        if not lo.isdigit() or (dash and not hi.isdigit()) or (dash and int(hi) < int(lo)):
            raise ConfigError(
                f"--seeds: expected comma-separated integers >= 0 or ranges a-b, got {text!r}"
            )
        stop = int(hi if dash else lo) + 1
        if stop - int(lo) > MAX_SEEDS:
            raise ConfigError(f"--seeds: at most {MAX_SEEDS} seeds in a range, got {part!r}")
        for seed in range(int(lo), stop):
            if seed not in seeds:
                seeds.append(seed)
    return tuple(seeds)


def parse_choices(text: str, choices: Sequence[str], flag: str, what: str) -> tuple[str, ...]:
    """``"a,b"`` → those of ``choices``, in their order; an unknown name or an empty list is
    an error naming the ``flag``, the ``what`` and the choices."""
    wanted = [p.strip() for p in text.split(",") if p.strip()]
    unknown = [w for w in wanted if w not in choices]
    if unknown or not wanted:
        raise ConfigError(
            f"{flag}: unknown {what} {', '.join(map(repr, unknown)) or repr(text)}; "
            f"choose from {','.join(choices)}"
        )
    return tuple(k for k in choices if k in wanted)


def parse_only(text: str) -> tuple[str, ...]:
    """``"skf,torque"`` → the sections in report order; unknown names are an error."""
    return parse_choices(text, SECTION_KEYS, "--only", "section")


def reproduce(
    out: Path = DEFAULT_OUT,
    *,
    seeds: Sequence[int] = DEFAULT_SEEDS,
    only: Sequence[str] = DEFAULT_KEYS,
    progress: Callable[[str], None] | None = None,
) -> Reproduced:
    """Run the chosen sections for ``seeds`` and write ``out/report.md``,
    ``out/report.html`` and ``out/report.json``."""
    if not seeds:
        raise ConfigError("--seeds: give at least one seed")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ConfigError(f"--out {out}: {exc.strerror or exc}") from None
    t0 = time.perf_counter()
    done: list[tuple[Section, float]] = []
    for key in only:
        t = time.perf_counter()
        section = _build_section(key, seeds)
        done.append((section, time.perf_counter() - t))
        if progress is not None:
            progress(f"{key}: {done[-1][1]:.1f} s")
    seconds = time.perf_counter() - t0
    preamble = _preamble(seeds, only, done, seconds)
    sections = [s for s, _ in done]
    markdown, html, doc = out / "report.md", out / "report.html", out / "report.json"
    try:
        markdown.write_text(to_markdown(TITLE, preamble, sections), encoding="utf-8")
        write_html(html, TITLE, preamble, sections)
        doc.write_text(
            json.dumps(_document(seeds, only, done, seconds), allow_nan=False) + "\n",
            encoding="utf-8",
        )
    except OSError as exc:
        raise ConfigError(f"--out {out}: {exc.strerror or exc}") from None
    return Reproduced(markdown, html, tuple(done), seconds, doc)


def _seeds_flag(seeds: Sequence[int]) -> str:
    """``--seeds`` that :func:`parse_seeds` reads back as ``seeds``: runs of three or more
    consecutive seeds as ``a-b`` (``100,101,…,109`` → ``100-109``), in the order given."""
    parts: list[str] = []
    i = 0
    while i < len(seeds):
        j = i
        while j + 1 < len(seeds) and seeds[j + 1] == seeds[j] + 1:
            j += 1
        if j - i >= 2:
            parts.append(f"{seeds[i]}-{seeds[j]}")
        else:
            parts += [str(s) for s in seeds[i : j + 1]]
        i = j + 1
    return ",".join(parts)


def _command(seeds: Sequence[int], only: Sequence[str]) -> str:
    """The ``mapwise reproduce`` command line that makes this report: the seeds, the
    sections, and every non-default setting in effect (``--mismatch``; with the study,
    ``--robustness-parts`` and ``--robustness-duration``)."""
    from app.cli.run import MISMATCH
    from app.reproduce.fidelity import DURATION_S
    from app.reproduce.robustness import PARTS, SELECTED_PARTS

    command = f"mapwise reproduce --seeds {_seeds_flag(seeds)}"
    if tuple(only) == DEFAULT_KEYS + OPT_IN:
        command += " --robustness"
    elif tuple(only) != DEFAULT_KEYS:
        command += f" --only {','.join(only)}"
    if MISMATCH.get() != "nominal":
        command += f" --mismatch {MISMATCH.get()}"
    if "robustness" in only:
        if SELECTED_PARTS.get() != PARTS:
            command += f" --robustness-parts {','.join(SELECTED_PARTS.get())}"
        if DURATION_S.get() is not None:
            command += f" --robustness-duration {DURATION_S.get():g}"
    return command


def _document(
    seeds: Sequence[int], only: Sequence[str], done: Sequence[tuple[Section, float]], seconds: float
) -> dict[str, object]:
    return {
        "title": TITLE,
        "command": _command(seeds, only),
        "seeds": list(seeds),
        "seconds": seconds,
        "mismatch": _mismatch(),
        "seed_kinds": {str(s): seed_kinds.kind(s) for s in seeds},
        "sections": [
            {
                "key": s.key,
                "title": s.title,
                "verdict": s.verdict,
                "seconds": t,
                "data": _finite(s.data),
            }
            for s, t in done
        ],
    }


def _mismatch() -> str:
    from app.cli.run import MISMATCH

    return MISMATCH.get()


def _finite(value: object) -> object:
    """``value`` with every non-finite float as ``None`` (JSON has no inf or NaN)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite(v) for v in value]
    return value


def _preamble(
    seeds: Sequence[int],
    only: Sequence[str],
    done: Sequence[tuple[Section, float]],
    seconds: float,
) -> list[Text | Table]:
    command = _command(seeds, only)
    return [
        Text(
            f"Generated by `{command}` in {seconds:.1f} s. Every number of ours is computed "
            "live from the registered estimators on the scenario catalog; the papers' numbers "
            "are the constants of `app/reproduce/paper_values.py`, each with its table or "
            "figure. Interactive figures are in `report.html` (works offline)."
        ),
        Text(
            f"Seeds {seed_kinds.describe(seeds)}. The settings the papers leave open were "
            "chosen by declared rules on the tuning seeds 0–4 (section `sensitivity`, "
            "docs/tuning.md#declared-rules); claims are made on the held-out seeds 100–109. "
            f"Model mismatch: `{_mismatch()}` (docs/fidelity.md#mismatch)."
        ),
        Table(
            "Summary",
            ["Section", "Verdict", "Run time [s]"],
            [[s.title, s.verdict, f"{t:.1f}"] for s, t in done],
        ),
    ]
