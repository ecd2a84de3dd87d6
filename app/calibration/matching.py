"""Match A2L input quantities to recorded channel names, ignoring measurement-tool suffixes.

INCA and CANape name a recorded signal after the A2L MEASUREMENT plus where it came from:
``nmot_w\\ETK:1``, ``nmot_w\\XCP:1``, ``nmot_w\\CCP:1``, ``nmot_w:1``. A2L identifiers
contain neither ``\\`` nor ``:``, so the suffix is everything from the first ``\\``, then
a trailing ``:<digits>``.

Each quantity takes the first channel (in the given order) found by, in turn:

1. the exact name;
2. the same name once the channel's tool suffix is dropped;
3. the same, ignoring case.

Other channels that also fit at that step are listed in ``ambiguous``; quantities with no
channel are listed in ``unmatched`` with up to three similar channel names in
``suggestions``. See ``docs/calibration.md#a2l-import``.
"""

from __future__ import annotations

import difflib
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

_INSTANCE = re.compile(r":\d+$")


def strip_tool_suffix(name: str) -> str:
    """``nmot_w\\ETK:1`` → ``nmot_w``; ``nmot_w:1`` → ``nmot_w``; others unchanged."""
    base = name.split("\\", 1)[0]
    return _INSTANCE.sub("", base).strip()


@dataclass(frozen=True)
class ChannelMatch:
    """Quantity → channel; the quantities without a channel, in the order asked."""

    matched: dict[str, str]
    unmatched: list[str]
    ambiguous: dict[str, list[str]] = field(default_factory=dict)
    suggestions: dict[str, list[str]] = field(default_factory=dict)

    def message(self) -> str:
        """One line naming every unmatched quantity (and what it resembles), or ``""``."""
        if not self.unmatched:
            return ""
        parts = []
        for quantity in self.unmatched:
            close = self.suggestions.get(quantity)
            parts.append(f"{quantity!r} (similar: {', '.join(close)})" if close else repr(quantity))
        return "no channel for " + "; ".join(parts)


def match_channels(quantities: Sequence[str], channels: Sequence[str]) -> ChannelMatch:
    """Match each of ``quantities`` to one of ``channels`` (rules in the module docstring)."""
    stripped = [strip_tool_suffix(c) for c in channels]
    folded = [s.casefold() for s in stripped]
    steps: tuple[Callable[[str, int], bool], ...] = (
        lambda q, i: channels[i] == q,
        lambda q, i: stripped[i] == strip_tool_suffix(q),
        lambda q, i: folded[i] == strip_tool_suffix(q).casefold(),
    )
    matched: dict[str, str] = {}
    ambiguous: dict[str, list[str]] = {}
    unmatched: list[str] = []
    for quantity in dict.fromkeys(quantities):
        for fits in steps:
            hits = [channels[i] for i in range(len(channels)) if fits(quantity, i)]
            if hits:
                matched[quantity] = hits[0]
                if len(hits) > 1:
                    ambiguous[quantity] = hits[1:]
                break
        else:
            unmatched.append(quantity)
    suggestions = {q: _similar(q, channels, stripped) for q in unmatched}
    return ChannelMatch(
        matched=matched,
        unmatched=unmatched,
        ambiguous=ambiguous,
        suggestions={q: s for q, s in suggestions.items() if s},
    )


def _similar(quantity: str, channels: Sequence[str], stripped: Sequence[str]) -> list[str]:
    by_base = {s.casefold(): c for s, c in zip(stripped, channels, strict=True)}
    close = difflib.get_close_matches(
        strip_tool_suffix(quantity).casefold(), list(by_base), n=3, cutoff=0.6
    )
    return [by_base[c] for c in close]
