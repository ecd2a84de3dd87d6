"""The report's seeds: tuning seeds, on which the declared rules chose the settings the papers
leave open, and held-out seeds, on which nothing was tuned and the claims are made (issue 17,
docs/tuning.md#declared-rules).

``mapwise reproduce`` runs the held-out seeds by default; any seed it runs is labelled in the
report with :func:`kind`.
"""

from __future__ import annotations

from collections.abc import Sequence

TUNING_SEEDS: tuple[int, ...] = (0, 1, 2, 3, 4)
"""Seeds the declared tuning rules sweep (Γ of TQ (54), γ of the LPV observer)."""
HELD_OUT_SEEDS: tuple[int, ...] = tuple(range(100, 110))
"""Seeds nothing was tuned on: the claims' seeds and ``mapwise reproduce``'s default."""


def kind(seed: int) -> str:
    """``"held-out"`` (100–109), ``"tuning"`` (0–4) or ``"other"`` (neither declared set:
    not tuned on, but not part of the held-out claims either)."""
    if seed in HELD_OUT_SEEDS:
        return "held-out"
    if seed in TUNING_SEEDS:
        return "tuning"
    return "other"


def label(seed: int) -> str:
    """``"100 (held-out)"``: a seed with its kind, for a table cell."""
    return f"{seed} ({kind(seed)})"


def _runs(seeds: Sequence[int]) -> str:
    """``(100, 101, 102, 105)`` → ``"100–102, 105"``."""
    parts: list[str] = []
    ordered = sorted(seeds)
    start = prev = ordered[0]
    for s in [*ordered[1:], None]:
        if s is not None and s == prev + 1:
            prev = s
            continue
        parts.append(f"{start}" if start == prev else f"{start}–{prev}")
        if s is not None:
            start = prev = s
    return ", ".join(parts)


def describe(seeds: Sequence[int]) -> str:
    """The seeds grouped by kind, e.g. ``"100–109 (held-out)"`` or ``"0, 1 (tuning: the
    declared rules chose settings on 0–4, so these are not held-out)"``."""
    notes = {
        "held-out": "held-out: nothing was tuned on them",
        "tuning": "tuning: the declared rules chose settings on seeds 0–4, so these are not "
        "held-out",
        "other": "neither tuning nor the declared held-out set 100–109",
    }
    groups = []
    for k in ("held-out", "tuning", "other"):
        chosen = [s for s in seeds if kind(s) == k]
        if chosen:
            groups.append(f"{_runs(chosen)} ({notes[k]})")
    return "; ".join(groups)
