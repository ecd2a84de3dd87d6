"""Sample gates: which log samples a run may learn from, and why the others were rejected.

Used when a run is planned (validation) and by its worker (the accept mask, per-cell counts).

A run's config holds a list of gates over the dataset's channels (the answer to "why did
my map not learn here?"):

- ``{"type": "range", "channel": c, "min": a, "max": b}`` rejects sample k when
  ``x_k < a`` or ``x_k > b`` (bounds themselves pass; either bound may be omitted);
- ``{"type": "rate", "channel": c, "max_abs": r}`` rejects k when ``|ẋ_k| > r`` (units/s),
  ``ẋ_k = (x_k − x_{k−1}) / (t_k − t_{k−1})`` (backward difference; sample 0 takes
  sample 1's value);
- ``{"type": "holdoff", "channel": c, "below" | "above": v, "seconds": s}`` rejects k when
  the event ``x_j < v`` (or ``x_j > v``) held at some ``j ≤ k`` with ``t_k − t_j ≤ s``: the
  samples during the event and ``s`` seconds after it (e.g. 2 s after fuel cut-off).

Everything is vectorised numpy over the whole log (no per-sample Python).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Collection, Sequence
from dataclasses import dataclass
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, TypeAdapter, ValidationError, model_validator

from app.io.errors import InputError
from estimation import Signals

FiniteFloat = Annotated[float, Field(allow_inf_nan=False)]
SCAN_ROWS = 1 << 16  # rows of a streamed log a gate scan reads at a time (one row group)


class _Gate(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)

    channel: str = Field(min_length=1)


class RangeGate(_Gate):
    """Reject samples outside ``[min, max]`` (units of the channel)."""

    type: Literal["range"] = "range"
    min: FiniteFloat | None = None
    max: FiniteFloat | None = None

    @model_validator(mode="after")
    def _bounds(self) -> RangeGate:
        if self.min is None and self.max is None:
            raise ValueError("a range gate needs 'min', 'max' or both")
        if self.min is not None and self.max is not None and self.min > self.max:
            raise ValueError(f"min {self.min:g} is above max {self.max:g}")
        return self


class RateGate(_Gate):
    """Reject samples whose rate of change exceeds ``max_abs`` (channel units per second)."""

    type: Literal["rate"] = "rate"
    max_abs: FiniteFloat = Field(gt=0)


class HoldoffGate(_Gate):
    """Reject samples within ``seconds`` after the channel was below/above a threshold."""

    type: Literal["holdoff"] = "holdoff"
    below: FiniteFloat | None = None
    above: FiniteFloat | None = None
    seconds: FiniteFloat = Field(ge=0)

    @model_validator(mode="after")
    def _one_condition(self) -> HoldoffGate:
        if (self.below is None) == (self.above is None):
            raise ValueError("a holdoff gate needs exactly one of 'below' or 'above'")
        return self


Gate = Annotated[RangeGate | RateGate | HoldoffGate, Field(discriminator="type")]
_GATES = TypeAdapter(list[Gate])


@dataclass(frozen=True, slots=True)
class GateResult:
    """Outcome of the gates over a log of ``n`` samples.

    ``masks[label]`` is True where that gate rejects (each gate on its own);
    ``rejected[label]`` counts samples attributed to the first gate (in list order) that
    rejects them, so ``sum(rejected.values()) == (~accept).sum()``; ``failed[label]``
    counts every sample the gate rejects.
    """

    accept: np.ndarray
    masks: dict[str, np.ndarray]
    rejected: dict[str, int]
    failed: dict[str, int]

    def first_gate(self) -> dict[str, np.ndarray]:
        """label → mask of the samples attributed to that gate (disjoint)."""
        out, taken = {}, np.zeros_like(self.accept)
        for label, mask in self.masks.items():
            out[label] = mask & ~taken
            taken |= mask
        return out


def parse_gates(
    raw: Any, channels: Collection[str], *, field: str = "config.gates"
) -> list[RangeGate | RateGate | HoldoffGate]:
    """Validated gates; :class:`InputError` names the field, e.g. ``config.gates[1].channel``."""
    if raw is None:
        return []
    try:
        gates = _GATES.validate_python(raw)
    except ValidationError as exc:
        err = exc.errors()[0]
        loc = [str(p) for p in err["loc"]]
        # pydantic puts the discriminator tag in the path ("0", "range", "max"): drop it.
        path = field
        if loc:
            path += f"[{loc[0]}]"
            rest = [p for p in loc[1:] if p not in ("range", "rate", "holdoff")]
            path += "".join(f".{p}" for p in rest)
        message = err["msg"].removeprefix("Value error, ")
        raise InputError(f"{path}: {message}", field=path) from None
    for i, gate in enumerate(gates):
        if gate.channel not in channels:
            raise InputError(
                f"{field}[{i}].channel: unknown channel {gate.channel!r}; "
                f"the dataset has {sorted(channels)}",
                field=f"{field}[{i}].channel",
            )
    return gates


def gate_labels(gates: Sequence[RangeGate | RateGate | HoldoffGate]) -> list[str]:
    """``type:channel`` per gate, with ``#2``, ``#3`` … on repeats."""
    labels: list[str] = []
    for gate in gates:
        base = f"{gate.type}:{gate.channel}"
        n = sum(1 for lab in labels if lab == base or lab.startswith(base + "#"))
        labels.append(base if n == 0 else f"{base}#{n + 1}")
    return labels


class GateScan:
    """The gates' masks over a log fed in consecutive windows of rows: the same masks as
    over the whole log, since each gate carries what it needs across a window's edge (the
    rate gate the previous sample, the holdoff gate its last event's time). A streamed run
    (`docs/data-formats.md#streamed-runs`) computes its masks so, never holding the log."""

    def __init__(self, gates: Sequence[RangeGate | RateGate | HoldoffGate], n: int) -> None:
        self.gates = list(gates)
        self.labels = gate_labels(self.gates)
        self.n = n
        self.masks = [np.zeros(n, dtype=bool) for _ in self.gates]
        self.filled = 0
        self.previous: Signals | None = None  # the last sample fed (the rate gate's)
        self.last_event = [-math.inf] * len(self.gates)  # per holdoff gate

    def feed(self, rows: Signals) -> None:
        """Samples ``filled … filled + len(rows) − 1`` of the log."""
        a, z = self.filled, self.filled + len(rows)
        if z > self.n:
            raise ValueError(f"fed {z} samples of a log of {self.n}")
        if a == 0 and len(rows) < min(2, self.n):
            raise ValueError("the first window needs two samples (the rate gate's first)")
        for i, gate in enumerate(self.gates):
            self.masks[i][a:z] = self._mask(i, gate, rows)
        if len(rows):
            self.previous = rows.slice(len(rows) - 1, len(rows))
        self.filled = z

    def _mask(self, i: int, gate: RangeGate | RateGate | HoldoffGate, rows: Signals) -> np.ndarray:
        """``(len(rows),)`` bool, True where ``gate`` rejects the sample (module docstring)."""
        x, t = rows[gate.channel], rows.time
        if isinstance(gate, RangeGate):
            low = -math.inf if gate.min is None else gate.min
            high = math.inf if gate.max is None else gate.max
            return (x < low) | (x > high)
        if isinstance(gate, RateGate):
            if self.previous is None:
                if x.size < 2:
                    return np.zeros(x.size, dtype=bool)
                rate = np.abs(np.diff(x) / np.diff(t))
                return np.concatenate([rate[:1], rate]) > gate.max_abs
            x0, t0 = self.previous[gate.channel], self.previous.time
            rate = np.abs(np.diff(np.concatenate([x0, x])) / np.diff(np.concatenate([t0, t])))
            return rate > gate.max_abs
        event = x < gate.below if gate.below is not None else x > gate.above
        last_event = np.maximum.accumulate(np.where(event, t, -np.inf))
        np.maximum(last_event, self.last_event[i], out=last_event)
        if last_event.size:
            self.last_event[i] = float(last_event[-1])
        return (t - last_event) <= gate.seconds

    def result(self) -> GateResult:
        """Accept mask and rejection counts, once the whole log is fed."""
        if self.filled != self.n:
            raise ValueError(f"{self.filled} of {self.n} samples fed")
        masks = dict(zip(self.labels, self.masks, strict=True))
        accept = np.ones(self.n, dtype=bool)
        rejected: dict[str, int] = {}
        for label, mask in masks.items():
            rejected[label] = int(np.count_nonzero(mask & accept))
            accept &= ~mask
        failed = {label: int(np.count_nonzero(mask)) for label, mask in masks.items()}
        return GateResult(accept, masks, rejected, failed)


def apply_gates(
    gates: Sequence[RangeGate | RateGate | HoldoffGate], signals: Signals
) -> GateResult:
    """Accept mask and rejection counts of ``gates`` over ``signals``, held whole."""
    scan = GateScan(gates, len(signals))
    scan.feed(signals)
    return scan.result()


def scan_gates(
    gates: Sequence[RangeGate | RateGate | HoldoffGate],
    read: Callable[[int, int], Signals],
    n: int,
    *,
    window: int = SCAN_ROWS,
) -> GateResult:
    """:func:`apply_gates` over a log of ``n`` samples read ``window`` rows at a time
    (``read(a, z)`` gives rows ``a … z−1`` with the gates' channels): the same result, with
    only the masks (a byte a sample a gate) spanning the log."""
    scan = GateScan(gates, n)
    for a in range(0, n, max(window, 2)):
        scan.feed(read(a, min(a + max(window, 2), n)))
    return scan.result()


def nearest_cell(idx: np.ndarray, w: np.ndarray) -> np.ndarray:
    """``(n,)`` flat index of each sample's heaviest regressor corner (its grid node)."""
    return np.take_along_axis(idx, np.argmax(w, axis=1)[:, None], axis=1)[:, 0]


def cell_counts(
    idx: np.ndarray, w: np.ndarray | None, mask: np.ndarray, n_cells: int
) -> np.ndarray:
    """``(n_cells,)`` count of the samples in ``mask`` per cell.

    ``idx``: ``(n,)`` flat cell of each sample (counts are integers), or the regressor's
    ``(n, 2^d)`` indices with weights ``w`` (counts are interpolation-weighted, so a sample
    counts once in total, split over its corners).
    """
    idx = np.asarray(idx)
    if idx.ndim == 1:
        return np.bincount(idx[mask], minlength=n_cells)[:n_cells]
    if w is None:
        raise ValueError("regressor indices (n, 2^d) need their weights w")
    return np.bincount(idx[mask].ravel(), weights=np.asarray(w)[mask].ravel(), minlength=n_cells)[
        :n_cells
    ]


def rejected_per_cell(
    result: GateResult,
    idx: np.ndarray,
    w: np.ndarray | None,
    n_cells: int,
    *,
    attributed: bool = True,
) -> dict[str, np.ndarray]:
    """Rejected samples per cell and gate (:func:`cell_counts` of each gate's mask).

    ``attributed``: use the disjoint first-gate attribution (else each gate's own mask).
    """
    masks = result.first_gate() if attributed else result.masks
    return {label: cell_counts(idx, w, mask, n_cells) for label, mask in masks.items()}


def gate_channels(config: dict[str, Any]) -> list[str]:
    """The channels a run's gates name, read leniently: a malformed gate list fails later,
    in :func:`run_options` and :func:`parse_gates`, with the message planning gives."""
    gates = config.get("gates")
    if not isinstance(gates, list):
        return []
    named = (g.get("channel") for g in gates if isinstance(g, dict))
    return [name for name in named if isinstance(name, str)]
