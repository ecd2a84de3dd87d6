"""Drive and engine test cycles (docs/algorithms.md §6, data and licences in ``data/SOURCES.md``).

>>> from estimation.cycles import load_cycle
>>> load_cycle("udds").duration_s
1369.0
"""

from estimation.cycles.base import Cycle
from estimation.cycles.catalog import list_cycles, load_cycle
from estimation.cycles.synthetic import make_sdmp

__all__ = ["Cycle", "list_cycles", "load_cycle", "make_sdmp"]
