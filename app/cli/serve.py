"""``mapwise serve``, ``mapwise db upgrade|current`` and ``mapwise token create|list|revoke``.

Every problem (unreachable or out-of-date database, bad settings) is one line on stderr and
exit code 2, raised as the CLI's :class:`~app.cli.errors.UsageError`.
"""

from __future__ import annotations

import argparse
from typing import Any

from pydantic import ValidationError

from app.cli.errors import UsageError
from app.config import Settings
from app.domain import DEFAULT_SCOPES, SCOPES

#: Seconds an idle keep-alive connection stays open. Longer than what clients and proxies
#: keep an idle connection for (httpx 5 s, browsers and load balancers up to 60 s): a client
#: that reuses a connection the server is closing at that moment gets "server disconnected"
#: on a request that never reached the server (uvicorn's default, 5 s, equals httpx's).
KEEP_ALIVE_S = 65


def _database_arg(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--database-url",
        help="SQLAlchemy URL (default MAPWISE_DATABASE_URL or sqlite:///./mapwise.db)",
    )


def add_parsers(sub: argparse._SubParsersAction) -> None:
    serve = sub.add_parser(
        "serve",
        help="start the web service and dashboard",
        description="Start the web service. An empty database gets the schema and a demo "
        "dataset and run; a database at an older schema revision is refused (back it up and "
        "run `mapwise db upgrade`). Bearer tokens are required when --host is not loopback "
        "(or MAPWISE_REQUIRE_AUTH=1).",
    )
    serve.add_argument("--host", help="interface (default 127.0.0.1, MAPWISE_HOST)")
    serve.add_argument("--port", type=int, help="TCP port (default 8000, MAPWISE_PORT)")
    _database_arg(serve)
    serve.add_argument("--workers", type=int, help="run worker processes (MAPWISE_RUN_WORKERS)")
    serve.add_argument(
        "--executor",
        choices=["local", "dask"],
        help="where runs execute: local process pool (default) or a Dask cluster "
        "(MAPWISE_EXECUTOR; needs PostgreSQL)",
    )
    serve.add_argument(
        "--dask-address", help="Dask scheduler, tcp://host:8786 (MAPWISE_DASK_ADDRESS)"
    )
    serve.add_argument("--no-demo", action="store_true", help="do not seed an empty database")
    serve.add_argument("--log-level", default="info", choices=["debug", "info", "warning"])
    serve.set_defaults(handler=_cmd_serve)

    db = sub.add_parser("db", help="database schema: upgrade, or show the revision")
    db_sub = db.add_subparsers(dest="db_command", required=True)
    upgrade = db_sub.add_parser("upgrade", help="migrate the schema to this version's head")
    _database_arg(upgrade)
    upgrade.set_defaults(handler=_cmd_db_upgrade)
    current = db_sub.add_parser("current", help="show the schema revision and if it is current")
    _database_arg(current)
    current.set_defaults(handler=_cmd_db_current)

    token = sub.add_parser("token", help="API bearer tokens: create, list, revoke")
    token_sub = token.add_subparsers(dest="token_command", required=True)
    create = token_sub.add_parser(
        "create",
        help="create a token (its secret is shown once)",
        description="Create a bearer token. Scopes: read (see every dataset, run and map), "
        "run (upload, start, cancel, resume, label), admin (delete, base maps). Without "
        "--scope a token gets read and run; ask for admin explicitly.",
    )
    create.add_argument("--name", required=True, help="what the token is for")
    create.add_argument(
        "--scope",
        action="append",
        choices=list(SCOPES),
        dest="scopes",
        help="a scope of the token; repeat for several (default: read and run)",
    )
    _database_arg(create)
    create.set_defaults(handler=_cmd_token_create)
    listing = token_sub.add_parser("list", help="list tokens (never their secrets)")
    _database_arg(listing)
    listing.set_defaults(handler=_cmd_token_list)
    revoke = token_sub.add_parser("revoke", help="revoke a token by id")
    revoke.add_argument("id", type=int, help="token id (see mapwise token list)")
    _database_arg(revoke)
    revoke.set_defaults(handler=_cmd_token_revoke)


def _settings(args: argparse.Namespace, **extra: Any) -> Settings:
    overrides = {"database_url": getattr(args, "database_url", None), **extra}
    try:
        return Settings(**{k: v for k, v in overrides.items() if v is not None})
    except ValidationError as exc:
        first = exc.errors()[0]
        where = ".".join(str(p) for p in first["loc"]) or "settings"
        raise UsageError(f"{where}: {first['msg'].removeprefix('Value error, ')}") from None


def _db_error(exc: Exception, url: str) -> UsageError:
    from sqlalchemy.engine import make_url

    safe = make_url(url).render_as_string(hide_password=True) if "://" in url else url
    reason = str(getattr(exc, "orig", None) or exc).strip().splitlines()[0]
    return UsageError(f"cannot use the database {safe}: {reason}")


def _cmd_serve(args: argparse.Namespace) -> int:
    import sys

    import uvicorn
    from sqlalchemy.exc import SQLAlchemyError

    from app.allocators import use_lean_allocators
    from app.api import create_app
    from app.db.migrate import check_schema, migrate

    use_lean_allocators()
    settings = _settings(
        args,
        host=args.host,
        port=args.port,
        run_workers=args.workers,
        executor=args.executor,
        dask_address=args.dask_address,
        seed_demo=False if args.no_demo else None,
    )
    demo_run: int | None = None
    try:
        check = before = check_schema(settings.database_url)
        if check.state != "current":  # migrated if empty; else checked again under the lock
            before, check = migrate(
                settings.database_url, store_url=settings.store_url, only_if_empty=True
            )
        if before.state == "empty":
            if settings.seed_demo:
                from app.services.demo import seed_demo

                demo_run = seed_demo(settings)
                print(
                    f"mapwise: new database: schema {check.head}, demo run {demo_run}",
                    file=sys.stderr,
                )
        elif check.state != "current":
            raise UsageError(check.message)
        else:
            from app.services.demo import demo_run_id

            demo_run = demo_run_id(settings.database_url)
        if settings.auth_required and not _has_tokens(settings):
            print(
                "mapwise: warning: authentication is required but no token exists; "
                "create one with `mapwise token create --name NAME`",
                file=sys.stderr,
            )
    except SQLAlchemyError as exc:
        raise _db_error(exc, settings.database_url) from None
    if settings.allowed_hosts is None and settings.host in ("0.0.0.0", "::"):
        print(
            "mapwise: note: only requests to "
            f"{', '.join(settings.trusted_hosts)} are answered (DNS-rebinding protection); "
            "set MAPWISE_ALLOWED_HOSTS to the names clients use to reach this server",
            file=sys.stderr,
        )
    shown = "localhost" if settings.host in ("127.0.0.1", "::1") else settings.host
    print(f"mapwise: dashboard at http://{shown}:{settings.port}/", file=sys.stderr)
    if demo_run is not None:
        print(
            f"mapwise: demo run at http://{shown}:{settings.port}/runs/{demo_run}", file=sys.stderr
        )
    uvicorn.run(
        create_app(settings),
        host=settings.host,
        port=settings.port,
        log_level=args.log_level,
        ws="websockets-sansio",
        ws_per_message_deflate=settings.ws_deflate,
        timeout_keep_alive=KEEP_ALIVE_S,
    )
    return 0


def _has_tokens(settings: Settings) -> bool:
    from app.db.engine import Database
    from app.services.tokens import TokenService

    db = Database(settings.database_url)
    try:
        return any(t.revoked_at is None for t in TokenService(db).list())
    finally:
        db.dispose()


def _cmd_db_upgrade(args: argparse.Namespace) -> int:
    from sqlalchemy.exc import SQLAlchemyError

    from app.db.migrate import migrate

    settings = _settings(args)
    try:
        before, after = migrate(settings.database_url, store_url=settings.store_url)
        if before.state == "unknown":
            raise UsageError(before.message)
    except SQLAlchemyError as exc:
        raise _db_error(exc, settings.database_url) from None
    print(f"schema {before.current or 'empty'} -> {after.current}")
    return 0


def _cmd_db_current(args: argparse.Namespace) -> int:
    from sqlalchemy.exc import SQLAlchemyError

    from app.db.migrate import check_schema

    settings = _settings(args)
    try:
        check = check_schema(settings.database_url)
    except SQLAlchemyError as exc:
        raise _db_error(exc, settings.database_url) from None
    print(f"{check.current or 'none'} (head {check.head}): {check.state}")
    return 0


def _tokens(args: argparse.Namespace) -> Any:
    from app.db.engine import Database
    from app.db.migrate import check_schema
    from app.services.tokens import TokenService

    settings = _settings(args)
    check = check_schema(settings.database_url)
    if check.state != "current":
        raise UsageError(
            check.message
            if check.state != "empty"
            else "the database has no schema yet; "
            "run `mapwise db upgrade` (or `mapwise serve`) first"
        )
    return TokenService(Database(settings.database_url))


def _cmd_token_create(args: argparse.Namespace) -> int:
    token, secret = _tokens(args).create(args.name, tuple(args.scopes or DEFAULT_SCOPES))
    print(secret)
    import sys

    print(
        f"token {token.id} ({token.name}, scopes {','.join(token.scopes)}) created; "
        "the secret above is shown only once",
        file=sys.stderr,
    )
    return 0


def _cmd_token_list(args: argparse.Namespace) -> int:
    for t in _tokens(args).list():
        state = "revoked" if t.revoked_at else "active"
        used = t.last_used_at.isoformat(timespec="seconds") if t.last_used_at else "never"
        scopes = ",".join(t.scopes)
        print(f"{t.id:>4}  {t.prefix}…  {state:<8} {scopes:<14} last used {used:<25} {t.name}")
    return 0


def _cmd_token_revoke(args: argparse.Namespace) -> int:
    from app.errors import NotFoundError

    try:
        token = _tokens(args).revoke(args.id)
    except NotFoundError as exc:
        raise UsageError(exc.message) from None
    print(f"token {token.id} ({token.name}) revoked")
    return 0
