"""The README is the project's entry page: short, every link inside the repository, and its example runs as
written (issue 39). The numbers the README's example prints in comments are what it prints now."""
from __future__ import annotations

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
README = (ROOT / "README.md").read_text(encoding="utf-8")
LINK = re.compile(r"\]\(([^)\s]+)\)")
OUTSIDE = re.compile("/" + r"work/|\.\./shared/" + "spec")  # a machine path, or the shared spec beside the repo


def test_readme_is_an_entry_page():
    lines = README.splitlines()
    assert len(lines) < 200, f"README.md has {len(lines)} lines: move the long content into docs/"
    assert "make demo" in "\n".join(lines[:20]) and "make test" in "\n".join(lines[:20])
    prose = re.sub(r"```.*?```", "", README, flags=re.S)
    assert not re.findall(r"`[0-9a-f]{7,40}`", prose), "commit hashes belong in docs/performance-history.md"
    assert not re.findall(r"\b20\d\d-\d\d-\d\d\b", prose), "dates belong in the docs pages' history"


SOURCE_DIRS = ("docs", "finkensim", "tests", "examples", "benchmarks", "notebooks")


def markdown_files():
    """The repository's Markdown pages (not build output or tool caches)."""
    yield ROOT / "README.md"
    for folder in SOURCE_DIRS:
        for path in sorted((ROOT / folder).rglob("*.md")):
            if not {"_build", "generated", ".ipynb_checkpoints"} & set(path.parts):
                yield path


def test_links_stay_inside_the_repository():
    """Every relative link of a Markdown page names a file of the repository (no `../shared/...`, no machine paths)."""
    broken = []
    for page in markdown_files():
        for target in LINK.findall(page.read_text(encoding="utf-8")):
            if re.match(r"[a-z]+:", target) or target.startswith("#"):
                continue
            path = (page.parent / target.split("#")[0]).resolve()
            if ROOT not in path.parents or not path.exists():
                broken.append(f"{page.relative_to(ROOT)} -> {target}")
    assert not broken, f"links to files outside the repository or missing: {broken}"


def test_no_machine_paths():
    """Only tests/test_format_specs.py, which compares the in-repo formats with the shared spec, knows where that is."""
    for path in [*markdown_files(), *ROOT.glob("finkensim/**/*.py"), *ROOT.glob("tests/**/*.py")]:
        if path.name == "test_format_specs.py":
            continue
        text = path.read_text(encoding="utf-8")
        assert not OUTSIDE.search(text), f"{path.relative_to(ROOT)} names a path " \
                                                                            "outside the repository"


def python_example() -> str:
    return re.search(r"```python\n(.*?)```", README, flags=re.S).group(1)


def test_readme_example_runs_as_written(tmp_path, monkeypatch):
    """Executes the README's Python block in a temporary directory; an expression line whose comment starts with a
    value (``rec.pose.shape  # (1200, 64, 6, 3): ...``) must evaluate to that value."""
    monkeypatch.chdir(tmp_path)
    namespace: dict = {}
    checked = 0
    for stmt in ast.parse(python_example()).body:
        source = ast.get_source_segment(python_example(), stmt)
        if isinstance(stmt, ast.Expr):
            line = python_example().splitlines()[stmt.end_lineno - 1]
            comment = re.search(r"#\s*(\([^)]*\))", line)
            if comment:
                assert eval(source, namespace) == ast.literal_eval(comment.group(1)), line
                checked += 1
                continue
        exec(compile(ast.Module([stmt], []), "README.md", "exec"), namespace)
    assert checked >= 1
    assert (tmp_path / "flight.npz").is_file()
