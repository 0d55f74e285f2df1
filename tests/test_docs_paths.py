"""Docs name only modules that exist: every path, file name and dotted module the docs mention."""
from __future__ import annotations

import re

from conftest import REPO

DOCS = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]
TOP = "services|bench|cli|experiments|geometry|sim|schemas|tests|parameters|compose"
PATH = re.compile(rf"(?<![\w./-])(?:\.\./)*(?:(?:{TOP})/)?[\w/]*\w\.py\b")
DOTTED = re.compile(rf"\bomninav\.(?:{TOP})(?:\.\w+)+")
# what the docs name that is not ours, and placeholders: never looked up
NOT_OURS = {
    "create_plugin_polynomial.py", "polynomial_fit.py",  # DynaBARN's generator (docs/dynabarn.md)
}
PLACEHOLDER = re.compile(r"(?:^|/)[A-Z]+\.py$")
REPO_FILES = [p.relative_to(REPO).as_posix() for p in REPO.rglob("*")
              if ".venv" not in p.parts and ".git" not in p.parts and p.is_file()]


def exists(mention: str) -> bool:
    """A path from the repository's root, or a file name or trailing path that some file of ours ends with."""
    stripped = re.sub(r"^(?:\.\./)+", "", mention)
    if (REPO / stripped).exists():
        return True
    return any(f == stripped or f.endswith("/" + stripped) for f in REPO_FILES)


def module_exists(dotted: str) -> bool:
    """omninav.a.b.c: a module, or a name defined in the longest module prefix."""
    parts = dotted.split(".")[1:]
    for cut in range(len(parts), 0, -1):
        base = REPO.joinpath(*parts[:cut])
        module = base.with_suffix(".py")
        if base.is_dir() or module.exists():
            rest = parts[cut:]
            if not rest:
                return True
            return module.exists() and len(rest) == 1 and re.search(
                rf"^(?:def|class) {rest[0]}\b|^{rest[0]}\s*[:=]", module.read_text(), re.M) is not None
    return False


def test_docs_name_only_files_that_exist():
    missing = []
    for doc in DOCS:
        text = doc.read_text()
        for mention in sorted(set(PATH.findall(text))):
            name = mention.rsplit("/", 1)[-1]
            if name in NOT_OURS or PLACEHOLDER.search(mention) or mention.startswith(("../shared", "maps/")):
                continue
            if not exists(mention):
                missing.append(f"{doc.relative_to(REPO)}: {mention}")
        for dotted in sorted(set(DOTTED.findall(text))):
            if not module_exists(dotted):
                missing.append(f"{doc.relative_to(REPO)}: {dotted}")
    assert not missing, "docs name what does not exist:\n" + "\n".join(missing)


def test_images_and_relative_links_exist():
    missing = []
    for doc in DOCS:
        for target in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", doc.read_text()):
            if target.startswith(("http://", "https://", "mailto:")):
                continue
            resolved = (doc.parent / target).resolve()
            if resolved.exists():
                continue
            missing.append(f"{doc.relative_to(REPO)}: {target}")
    assert not missing, "links to nothing:\n" + "\n".join(missing)
