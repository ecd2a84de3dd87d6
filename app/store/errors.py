"""What goes wrong with a stored object: it is missing, or its bytes are not the ones stored.

Both are the server's fault, never the client's: a 500 whose ``code`` says which and whose
message names the dataset and the object's key (a run on such a dataset fails with the same
message).
"""

from __future__ import annotations

from app.errors import AppError


class ArtifactError(AppError):
    """A dataset's object in the artifact store cannot be used."""

    code = "artifact_error"
    status = 500


class ArtifactMissingError(ArtifactError):
    """The object the database names is not in the store."""

    code = "artifact_missing"


class ArtifactCorruptError(ArtifactError):
    """The object's SHA-256 or content is not what was stored."""

    code = "artifact_corrupt"
