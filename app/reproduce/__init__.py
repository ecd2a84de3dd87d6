"""``mapwise reproduce``: the papers' figures and tables beside ours, computed live.

One module per section (:mod:`~app.reproduce.skf_sims`, :mod:`~app.reproduce.nox`,
:mod:`~app.reproduce.lpv`, :mod:`~app.reproduce.ekf`, :mod:`~app.reproduce.torque`), the
papers' constants in :mod:`~app.reproduce.paper_values`, rendering in
:mod:`~app.reproduce.report`, orchestration in :mod:`~app.reproduce.runner`; the command
line in :mod:`app.cli.reproduce`. Every case runs through :func:`app.cli.run.execute_scenario`,
as ``mapwise run`` does.
"""

from app.reproduce.runner import SECTION_KEYS, Reproduced, parse_only, parse_seeds, reproduce

__all__ = ["SECTION_KEYS", "Reproduced", "parse_only", "parse_seeds", "reproduce"]
