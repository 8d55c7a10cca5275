"""Print the Python requirements of Home Assistant integrations, one a line.

    python requirements.py mqtt recorder stream

Reads the installed Home Assistant's own manifests (``requirements`` of
each integration named, of the integrations this release always sets up
(``bootstrap.DEFAULT_INTEGRATIONS``: from 2024.3 on, a frontend that does
not load sends Home Assistant into recovery mode) and of everything they
depend on), so the set fits the release installed. The check installs them into the virtualenv before
Home Assistant starts with ``--skip-pip``: a missing one then fails at
once instead of being fetched while the test runs.
"""

import json
import pathlib
import sys

from homeassistant import bootstrap
import homeassistant.components as components

ROOT = pathlib.Path(components.__file__).parent


def main(domains: list[str]) -> None:
    seen: set[str] = set()
    requirements: list[str] = []
    todo = list(domains) + sorted(getattr(bootstrap, "DEFAULT_INTEGRATIONS", set()))
    while todo:
        domain = todo.pop()
        if domain in seen:
            continue
        seen.add(domain)
        manifest = json.loads((ROOT / domain / "manifest.json").read_text())
        for r in manifest.get("requirements", []):
            if r not in requirements:
                requirements.append(r)
        todo.extend(manifest.get("dependencies", []))
    print("\n".join(sorted(requirements)))


if __name__ == "__main__":
    main(sys.argv[1:])
