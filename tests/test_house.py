"""The house rules that a reader of the code should not have to police: ruff's checks pass, and
imports point the way docs/architecture.md draws them."""
from __future__ import annotations

import ast
import subprocess
import sys

from conftest import REPO

TOP = ("schemas", "services", "sim", "cli", "experiments")


def test_ruff_finds_nothing():
    done = subprocess.run([sys.executable, "-m", "ruff", "check", "--no-cache", str(REPO)], capture_output=True,
                          text=True, cwd=REPO)
    assert done.returncode == 0, done.stdout + done.stderr


def _room(path) -> str:
    """schemas, services/runtime, services/<name>, services/<module>.py (neutral), sim, cli, experiments."""
    parts = path.relative_to(REPO).parts
    if parts[0] == "services" and len(parts) > 2:
        return f"services/{parts[1]}"
    return "services (neutral)" if parts[0] == "services" else parts[0]


def _imported_rooms(path) -> set[str]:
    rooms = set()
    package = path.relative_to(REPO).parent.parts
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.level:
            base = package[:len(package) - node.level + 1]
            target = (*base, *(node.module.split(".") if node.module else ()))
        elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith("omninav."):
            target = tuple(node.module.split(".")[1:])
        else:
            continue
        if target and target[0] == "services" and len(target) > 1 and (REPO / "services" / target[1]).is_dir():
            rooms.add(f"services/{target[1]}")
        elif target:
            rooms.add("services (neutral)" if target[0] == "services" else target[0])
    return rooms


def test_schemas_import_nothing_of_ours_and_the_runtime_only_schemas():
    for path in (REPO / "schemas").rglob("*.py"):
        assert _imported_rooms(path) <= {"schemas"}, path
    for path in (REPO / "services" / "runtime").rglob("*.py"):
        assert _imported_rooms(path) <= {"schemas", "services/runtime", "services (neutral)"}, path


def test_nothing_in_the_library_imports_the_lab_or_the_command_line():
    for top in ("schemas", "services", "sim"):
        for path in (REPO / top).rglob("*.py"):
            assert not _imported_rooms(path) & {"experiments", "cli"}, path
