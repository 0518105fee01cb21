"""The format pages the project publishes (``docs/formats/``) agree with the shared specification in their
normative parts: the flight log's array table (name, dtype, shape, unit) and the gap report's JSON keys and
required features. The shared specification is looked up in ``$FINKENSIM_SPEC`` or ``../shared/spec`` beside the
repository; without it the comparisons skip, naming the folder. The in-repo pages are also checked against the
code that implements them, which needs no shared folder.
"""
from __future__ import annotations

import json
import os
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
FORMATS = ROOT / "docs" / "formats"
SHARED_SPEC = Path(os.environ.get("FINKENSIM_SPEC", ROOT.parent / "shared" / "spec"))


def shared(name: str) -> str:
    path = SHARED_SPEC / name
    if not path.is_file():
        pytest.skip(f"the shared specification {path} is absent (set FINKENSIM_SPEC to the folder holding {name})")
    return path.read_text(encoding="utf-8")


def ours(name: str) -> str:
    return (FORMATS / name).read_text(encoding="utf-8")


def array_table(text: str) -> dict[str, tuple[str, str, str]]:
    """``{name: (dtype, shape, unit)}`` from the rows ``| `name` | dtype | shape | unit | meaning |`` of a page."""
    rows = re.findall(r"^\| `(\w+)` \|([^|]*)\|([^|]*)\|([^|]*)\|[^\n]*\|$", text, flags=re.M)
    table = {name: tuple(cell.strip() for cell in cells) for name, *cells in rows}
    assert len(table) == len(rows), "an array appears twice in the table"
    assert {"format", "t", "pose", "meta"} <= table.keys(), "the array table was not found"
    return table


def json_blocks(text: str) -> list[dict]:
    return [json.loads(block) for block in re.findall(r"```json\n(.*?)```", text, flags=re.S)]


def key_paths(doc, prefix: str = "") -> set[str]:
    """Every key of a JSON document as a dotted path (list items under ``[]``)."""
    if isinstance(doc, dict):
        paths = set()
        for key, value in doc.items():
            paths |= {f"{prefix}{key}"} | key_paths(value, f"{prefix}{key}.")
        return paths
    if isinstance(doc, list):
        return set().union(*(key_paths(item, f"{prefix}[].") for item in doc)) if doc else set()
    return set()


def backticked(text: str, after: str, before: str) -> set[str]:
    """The `code` words from the phrase ``after`` (excluded) to ``before`` (included) of a page."""
    start = text.index(after) + len(after)
    return set(re.findall(r"`(\w+)`", text[start:text.index(before, start) + len(before)]))


def test_flightlog_arrays_agree_with_the_shared_spec():
    mine, theirs = array_table(ours("flightlog.md")), array_table(shared("flightlog.md"))
    assert mine.keys() == theirs.keys(), f"arrays only in docs/formats: {sorted(mine.keys() - theirs.keys())}, " \
                                         f"only in the shared spec: {sorted(theirs.keys() - mine.keys())}"
    for name in theirs:
        assert mine[name] == theirs[name], f"{name}: docs/formats says (dtype, shape, unit) = {mine[name]}, " \
                                           f"the shared spec {theirs[name]}"


def test_flightlog_page_names_the_arrays_the_code_defines():
    from finkensim.flightlog.format import FORMAT, NUMERIC, STANDARD

    table = array_table(ours("flightlog.md"))
    assert set(table) == set(STANDARD)
    assert all(table[name][0] == "float64" for name in NUMERIC)
    assert f"`{FORMAT}`" in ours("flightlog.md")


def test_gap_report_keys_agree_with_the_shared_spec():
    mine, theirs = json_blocks(ours("gap-report.md")), json_blocks(shared("gap-report.md"))
    assert len(mine) == len(theirs) == 2, "expected the report's JSON block and the additions' block"
    for which, a, b in zip(("report", "additions"), mine, theirs):
        assert key_paths(a) == key_paths(b), f"{which}: keys only in docs/formats: {sorted(key_paths(a) - key_paths(b))}," \
                                             f" only in the shared spec: {sorted(key_paths(b) - key_paths(a))}"
    assert mine[0]["format"] == theirs[0]["format"]


def test_gap_report_required_features_and_sensors_agree_with_the_shared_spec():
    mine, theirs = ours("gap-report.md"), shared("gap-report.md")
    for what, after, before in (("sensors", "`sensor` is", "`imu`"), ("channels", "`channel` is", "`all`"),
                                ("required features", "at least", "`hit_to_copter`")):
        assert backticked(mine, after, before) == backticked(theirs, after, before), what


def test_gap_report_page_lists_the_keys_the_code_writes():
    from finkensim.gap.report.result import FORMAT, SPEC_KEYS

    report, additions = json_blocks(ours("gap-report.md"))
    assert report["format"] == FORMAT
    assert set(report) | set(additions) == set(SPEC_KEYS)
