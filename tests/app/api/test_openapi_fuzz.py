"""Schemathesis fuzzes every operation of the OpenAPI document against a real server:
no request may produce a 5xx, and status codes, content types and bodies must match what the
document declares. SQLite and PostgreSQL."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
import schemathesis
from hypothesis import HealthCheck, given, settings
from schemathesis.checks import not_a_server_error
from schemathesis.specs.openapi.checks import (
    content_type_conformance,
    response_schema_conformance,
    status_code_conformance,
)

from tests.support.server import Server

pytestmark = pytest.mark.slow  # hypothesis drives every operation of a real server

CHECKS = (
    not_a_server_error,
    status_code_conformance,
    content_type_conformance,
    response_schema_conformance,
)


@pytest.fixture(scope="module")
def fuzz_server(backend: str, fresh_url) -> Iterator[Server]:  # type: ignore[no-untyped-def]
    server = Server(fresh_url(backend), demo=True)  # the demo gives runs and versions to hit
    yield server
    server.stop()


def test_no_server_errors_and_documented_responses(fuzz_server: Server) -> None:
    schema = schemathesis.openapi.from_url(f"{fuzz_server.base}/openapi.json")
    failures: list[str] = []
    operations = [result.ok() for result in schema.get_all_operations()]
    assert len(operations) >= 20
    for operation in operations:

        @given(case=operation.as_strategy())
        @settings(
            max_examples=40,
            deadline=None,
            suppress_health_check=list(HealthCheck),
            derandomize=True,
            database=None,
        )
        def fuzz(case) -> None:  # type: ignore[no-untyped-def]
            response = case.call(base_url=fuzz_server.base, timeout=60)
            case.validate_response(response, checks=CHECKS)

        try:
            fuzz()
        except Exception as exc:
            failures.append(f"{operation.method.upper()} {operation.path}: {exc}"[:1500])
    assert not failures, "\n\n".join(failures)
