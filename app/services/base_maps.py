"""Base maps: a run's map version promoted to a named starting map, or a map file imported
(JSON / CSV / DCM), each with its lineage (run, version, dataset, estimator, config, parent
base map, metrics) kept as a record that survives the deletion of what it came from."""

from __future__ import annotations

from app.db.engine import Database
from app.db.repositories import BaseMapRepo, RunRepo, VersionRepo
from app.domain import BaseMap, Page
from app.errors import ConflictError, InvalidRequestError
from app.io.names import check_name, without_refused
from app.services.admission import OverBudgetError
from app.services.base_map_edits import EditedMap

NAME_MAX = 200


class BaseMapService:
    def __init__(self, db: Database, *, max_cells: int | None = None) -> None:
        self.db = db
        self.max_cells = max_cells  # MAPWISE_MAX_CELLS; None: no cap

    def promote(
        self, *, run_id: int, version_id: int, name: str | None, edited: EditedMap | None = None
    ) -> BaseMap:
        with self.db.write() as s:
            run = RunRepo(s).get(run_id)
            version = VersionRepo(s).get(run_id, version_id)
            if version.values is None or version.axes is None:
                raise ConflictError(f"run {run_id} ({run.estimator}) has no map", field="run_id")
            return BaseMapRepo(s).add(
                name=_name(name, None, promoted_name(run.name, run.id, version.summary.number)),
                source="run" if edited is None else "edit",
                axes=version.axes,
                values=version.values if edited is None else edited.values_for(version),
                run_id=run.id,
                version_id=version.summary.id,
                dataset_id=run.dataset_id,
                estimator=run.estimator,
                config=run.config if edited is None else edited.config(run.config),
                parent_base_map_id=run.base_map_id,
                metrics=run.metrics,
            )

    def import_file(self, data: bytes, *, name: str | None, filename: str | None) -> BaseMap:
        from app.io.export import import_map

        given = _name(name, filename, "imported map")  # a bad name fails before the file is read
        table = import_map(data, name=None)
        if self.max_cells is not None and table.size > self.max_cells:
            raise OverBudgetError(
                f"the map has {table.size:,} cells ({' × '.join(map(str, table.shape))}) > "
                f"{self.max_cells:,}, the cap (MAPWISE_MAX_CELLS)",
                field="file",
            )
        with self.db.write() as s:
            return BaseMapRepo(s).add(
                name=given,
                source="file",
                axes=[a.to_dict() for a in table.axes],
                values=table.values,
            )

    def get(self, base_map_id: int) -> BaseMap:
        with self.db.read() as s:
            return BaseMapRepo(s).get(base_map_id)

    def list(self, *, limit: int, offset: int) -> Page[BaseMap]:
        with self.db.read() as s:
            return BaseMapRepo(s).list(limit=limit, offset=offset)


def promoted_name(run_name: str | None, run_id: int, number: int) -> str:
    """The default name of a promoted version: "<run name or run R> v<N>", N the version's
    number 1…n in its run (what the dashboard's URLs and export headers call it)."""
    return f"{(run_name or '').strip() or f'run {run_id}'} v{number}"[:NAME_MAX]


def _name(name: str | None, filename: str | None, fallback: str = "") -> str:
    """The name as given, as a dataset's (:func:`check_name`: ``/`` kept, 422 naming ``name``
    for a control or format character); without one, the last component of the client's file
    name with such characters dropped (it was not typed as a name), else ``fallback``."""
    if name is not None and name.strip():
        return check_name(name, field="name", what="base map name")[:NAME_MAX]
    text = without_refused((filename or "").replace("\\", "/").rsplit("/", 1)[-1]).strip()
    if not (text or fallback):
        raise InvalidRequestError("a base map needs a name", field="name")
    return (text or fallback)[:NAME_MAX]
