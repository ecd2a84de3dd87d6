"""The one base of every estimator state: frozen, copyable, serialisable.

A state is a frozen dataclass: the run functions copy its arrays, advance the copy and
return a new state, so a saved state resumes to a result bit-identical to an uninterrupted
run. Every state has the registry name of the estimator that made it (``kind``) and the
steps it has done (``step``); a subclass adds its fields and lists the array-valued ones in
``ARRAYS``.

``to_dict`` gives JSON-able data, tagged with the class name under ``state_class``; each
array is ``{"dtype", "shape", "data"}`` with the values flattened in C order (Python floats
round-trip exactly through JSON). This format is what the service stores, so it must stay
readable. ``save``/``load`` write ``.npz`` (arrays binary, scalars as a Python literal), or
that JSON when the path ends in ``.json``.
"""

from __future__ import annotations

import ast
import dataclasses
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar, Self

import numpy as np

from estimation.errors import StateError

_DTYPES = {"int64": np.int64, "float64": np.float64}


@dataclass(frozen=True, slots=True, eq=False)
class EstimatorState:
    """What every state has: its estimator's registry name and the steps done so far."""

    kind: str
    step: int

    ARRAYS: ClassVar[tuple[str, ...]] = ()
    WHAT: ClassVar[str] = "estimator state"  # for messages: "not a saved <WHAT>"

    def copy(self) -> Self:
        """The same state with its own copies of the arrays (the kernels write into them)."""
        return dataclasses.replace(
            self, **{name: np.array(getattr(self, name)) for name in self.ARRAYS}
        )

    def to_dict(self) -> dict[str, Any]:
        """JSON-able data: ``state_class``, then every field; arrays as dtype/shape/data."""
        out: dict[str, Any] = {"state_class": type(self).__name__}
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if isinstance(value, np.ndarray):
                out[f.name] = {
                    "dtype": str(value.dtype),
                    "shape": list(value.shape),
                    "data": value.ravel().tolist(),
                }
            else:
                out[f.name] = value.item() if isinstance(value, np.generic) else value
        return out

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Self:
        """Rebuild a state from :meth:`to_dict` output.

        Called on a base class (``EstimatorState``, ``FilterState``), the concrete class named
        by ``state_class`` is built; data without the tag is read as ``cls``.
        """
        tag = data.get("state_class")
        target = cls if tag is None or tag == cls.__name__ else state_class(str(tag))
        if not issubclass(target, cls):
            raise StateError(f"saved {target.__name__} cannot be loaded as {cls.__name__}")
        if target is not cls:
            return target.from_dict(data)  # type: ignore[return-value]
        names = [f.name for f in dataclasses.fields(cls)]
        missing = [n for n in names if n not in data]
        if missing:
            raise StateError(f"{cls.__name__}: saved state lacks {missing}")
        values: dict[str, Any] = {}
        for name in names:
            raw = data[name]
            if name in cls.ARRAYS:
                try:
                    dtype = _DTYPES[raw["dtype"]]
                    values[name] = np.array(raw["data"], dtype=dtype).reshape(raw["shape"])
                except (KeyError, TypeError, ValueError) as exc:
                    raise StateError(f"{cls.__name__}: bad array {name!r}: {exc}") from exc
            else:
                values[name] = raw
        values["kind"] = str(values["kind"])
        values["step"] = int(values["step"])
        return cls(**values)

    def save(self, path: str | Path) -> None:
        """Write the state to ``path``: JSON if it ends in ``.json``, otherwise ``.npz``
        (which :func:`numpy.savez` appends when missing)."""
        if str(path).endswith(".json"):
            Path(path).write_text(json.dumps(self.to_dict()))
            return
        scalars = {k: v for k, v in self.to_dict().items() if k not in self.ARRAYS}
        del scalars["state_class"]
        arrays = {name: getattr(self, name) for name in self.ARRAYS}
        np.savez(path, __class__=type(self).__name__, __scalars__=repr(scalars), **arrays)

    @classmethod
    def load(cls, path: str | Path) -> Self:
        """Read a state written by :meth:`save`; the concrete class is the one saved, and must
        be ``cls`` or derive from it."""
        with open(path, "rb") as f:
            is_json = f.read(1) == b"{"
        if is_json:
            return cls.from_dict(json.loads(Path(path).read_text()))
        with np.load(path, allow_pickle=False) as f:
            tag = str(f["__class__"]) if "__class__" in f.files else ""
            try:
                target = state_class(tag)
            except StateError:
                raise StateError(f"{path}: not a saved {cls.WHAT}") from None
            if not issubclass(target, cls):
                raise StateError(f"{path}: not a saved {cls.WHAT}: {tag!r}")
            scalars = ast.literal_eval(str(f["__scalars__"]))
            if not isinstance(scalars, dict):
                raise StateError(f"{path}: saved state scalars are not a mapping")
            arrays = {name: np.array(f[name]) for name in target.ARRAYS}
        return target(**scalars, **arrays)


def state_class(name: str) -> type[EstimatorState]:
    """The state class called ``name``: one a registered estimator declares, or a base."""
    from estimation.registry import state_classes

    try:
        return state_classes()[name]
    except KeyError:
        raise StateError(f"unknown estimator state class {name!r}") from None
