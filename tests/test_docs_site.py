"""The documentation site's sources stay complete without building it (``make docs`` builds it, warnings as
errors): every module of the package is in the API reference, and every page the index promises exists."""
from __future__ import annotations

import pkgutil
import re
from pathlib import Path

import finkensim

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"


def test_every_module_is_in_the_api_reference():
    listed = set(re.findall(r"^\s+(finkensim\.\w+)\s*$", (DOCS / "api" / "index.md").read_text(), flags=re.M))
    modules = {f"finkensim.{m.name}" for m in pkgutil.iter_modules(finkensim.__path__) if m.name != "data"}
    missing = sorted(modules - listed)
    assert not missing, f"docs/api/index.md does not list {missing}: add them to its 'Modules' autosummary"


def toctree_entries(page: Path) -> list[str]:
    blocks = re.findall(r"```\{toctree\}\n(.*?)```", page.read_text(), flags=re.S)
    return [line.strip() for block in blocks for line in block.splitlines()
            if line.strip() and not line.strip().startswith(":")]


def test_toctree_entries_exist():
    for page in DOCS.rglob("*.md"):
        if "_build" in page.parts:
            continue
        for entry in toctree_entries(page):
            if any(ch in entry for ch in "*?["):
                assert list(page.parent.glob(entry + ".*")), f"{page.relative_to(ROOT)}: toctree glob {entry} is empty"
                continue
            target = page.parent / entry
            assert target.with_suffix(".md").is_file() or target.with_suffix(".ipynb").is_file(), \
                f"{page.relative_to(ROOT)}: toctree entry {entry} names no page"
