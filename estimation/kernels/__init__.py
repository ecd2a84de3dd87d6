"""Compiled numba kernels.

Kernels take arrays, write into them or into ``out`` arrays, and do no validation:
the public modules (:mod:`estimation.table`, :mod:`estimation.filters`) validate and call them.

The public modules reach a kernel as ``kernels.<module>.<kernel>`` at the call, never by
importing it at the top: each submodule is imported on first use (PEP 562, as SciPy does
for its subpackages), so a process that only describes estimators and tables, such as the
API server, never loads numba and its LLVM (about 120 MiB; docs/reliability.md#api-memory).
"""

from __future__ import annotations

import importlib
import pkgutil
from types import ModuleType

SUBMODULES = frozenset(module.name for module in pkgutil.iter_modules(__path__))


def __getattr__(name: str) -> ModuleType:
    """``kernels.<name>``: the submodule, imported (and its kernels loaded) on first use."""
    if name in SUBMODULES:
        return importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(SUBMODULES | set(globals()))
