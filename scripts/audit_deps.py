"""Known vulnerabilities of the installed dependencies, from PyPI's advisory data.

Lists every distribution installed in this interpreter's environment (the locked set: what
``pip freeze`` shows) and asks PyPI's JSON API for its known vulnerabilities (PyPI takes them
from the PyPA advisory database, as pip-audit's default service does). Prints one line per
distribution with a vulnerability, then a summary; exits 1 if any was found.

PyPI answers ``/pypi/NAME/VERSION/json`` with the advisories of that very release. Where only
the project document ``/pypi/NAME/json`` is reachable (a mirror or proxy), its advisories
are those of the latest release, so an installed release that is not the latest is reported
as *not audited* rather than as clean. Where ``pip-audit`` can reach its services, it is the
tool to use (README, "Development"); this script is its equivalent on such a network.

    .venv/bin/python scripts/audit_deps.py [--json]
"""

from __future__ import annotations

import argparse
import json
import sys
import urllib.error
import urllib.request
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict, dataclass, field
from importlib.metadata import distributions

PYPI = "https://pypi.org/pypi"
SELF = "mapwise"


@dataclass
class Audit:
    name: str
    version: str
    status: str  # "clean", "vulnerable" or "not audited"
    vulnerabilities: list[str] = field(default_factory=list)
    note: str = ""


def _get(url: str) -> dict | None:
    try:
        with urllib.request.urlopen(url, timeout=30) as response:
            return json.load(response)
    except urllib.error.HTTPError as exc:
        if exc.code == 404:
            return None
        raise


def _ids(document: dict) -> list[str]:
    return sorted(
        v.get("id", "?") + (f" (fixed in {', '.join(v['fixed_in'])})" if v.get("fixed_in") else "")
        for v in document.get("vulnerabilities") or []
    )


def audit(name: str, version: str) -> Audit:
    release = _get(f"{PYPI}/{name}/{version}/json")
    if release is not None:
        found = _ids(release)
        return Audit(name, version, "vulnerable" if found else "clean", found)
    project = _get(f"{PYPI}/{name}/json")
    if project is None:
        return Audit(name, version, "not audited", note="not on PyPI")
    latest = project["info"]["version"]
    if latest != version:
        return Audit(
            name, version, "not audited", note=f"only the latest release ({latest}) is reachable"
        )
    found = _ids(project)
    return Audit(name, version, "vulnerable" if found else "clean", found)


def installed() -> list[tuple[str, str]]:
    seen = {}
    for dist in distributions():
        name = dist.metadata["Name"]
        if name and name.lower() != SELF:
            seen[name.lower()] = (name, dist.version)
    return sorted(seen.values())


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--json", action="store_true", help="every distribution as JSON")
    args = parser.parse_args(argv)
    try:
        with ThreadPoolExecutor(8) as pool:
            audits = list(pool.map(lambda nv: audit(*nv), installed()))
    except (urllib.error.URLError, TimeoutError) as exc:
        print(f"audit_deps: PyPI is unreachable: {exc}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps([asdict(a) for a in audits], indent=2))
    for a in audits:
        if a.status != "clean" and not args.json:
            detail = ", ".join(a.vulnerabilities) or a.note
            print(f"{a.name} {a.version}: {a.status}: {detail}")
    counts = {s: sum(a.status == s for a in audits) for s in ("clean", "vulnerable", "not audited")}
    print(
        f"{len(audits)} distributions: {counts['clean']} without a known vulnerability, "
        f"{counts['vulnerable']} vulnerable, {counts['not audited']} not audited",
        file=sys.stderr if args.json else sys.stdout,
    )
    return 1 if counts["vulnerable"] else 0


if __name__ == "__main__":
    raise SystemExit(main())
