"""``mapwise serve`` refuses an out-of-date schema (one line, exit 2, naming
``mapwise db upgrade``); ``mapwise db upgrade|current`` fix and show it. SQLite and PostgreSQL."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from app.cli import main as cli_main
from app.db.migrate import check_schema, head_revision, upgrade

ROOT = Path(__file__).resolve().parents[3]


def test_serve_refuses_an_out_of_date_schema(
    backend: str,
    fresh_url,
    capsys: pytest.CaptureFixture[str],  # type: ignore[no-untyped-def]
) -> None:
    url = fresh_url(backend)
    upgrade(url, "0001")  # a database left by an older mapwise
    result = subprocess.run(
        [sys.executable, "-m", "app.cli", "serve", "--port", "1", "--database-url", url],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 2
    assert result.stdout == ""
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1
    assert lines[0].startswith("mapwise: error: ")
    assert "mapwise db upgrade" in lines[0]
    assert check_schema(url).current == "0001"  # never migrated silently

    assert cli_main(["db", "current", "--database-url", url]) == 0
    assert "outdated" in capsys.readouterr().out
    assert cli_main(["db", "upgrade", "--database-url", url]) == 0
    head = head_revision()
    assert capsys.readouterr().out.strip() == f"schema 0001 -> {head}"
    assert cli_main(["db", "current", "--database-url", url]) == 0
    assert capsys.readouterr().out.strip() == f"{head} (head {head}): current"


def test_unreachable_database_is_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    url = "postgresql://postgres@127.0.0.1:9/nowhere"
    assert cli_main(["db", "current", "--database-url", url]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert err[0].startswith("mapwise: error: cannot use the database")


def test_token_commands_need_a_schema(
    backend: str,
    fresh_url,
    capsys: pytest.CaptureFixture[str],  # type: ignore[no-untyped-def]
) -> None:
    url = fresh_url(backend)
    assert cli_main(["token", "create", "--name", "x", "--database-url", url]) == 2
    assert "mapwise db upgrade" in capsys.readouterr().err
    assert cli_main(["token", "revoke", "5", "--database-url", url]) == 2
