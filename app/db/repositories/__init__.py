"""Repositories: the only code that touches SQLAlchemy. They take a session, return domain
objects (:mod:`app.domain`) and never commit; the caller's unit of work does.

One module per aggregate; every repository is importable from here.
"""

from app.db.repositories.base import MAX_ID, aware
from app.db.repositories.base_maps import BaseMapRepo
from app.db.repositories.datasets import DatasetRepo
from app.db.repositories.ecus import EcuRepo
from app.db.repositories.groups import GroupRepo
from app.db.repositories.metrics import MetricRepo
from app.db.repositories.runs import RunRepo
from app.db.repositories.tokens import TokenRepo
from app.db.repositories.versions import VersionRepo

__all__ = [
    "MAX_ID",
    "BaseMapRepo",
    "DatasetRepo",
    "EcuRepo",
    "GroupRepo",
    "MetricRepo",
    "RunRepo",
    "TokenRepo",
    "VersionRepo",
    "aware",
]
