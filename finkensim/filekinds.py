"""Which kind of finkensim input a file is: the one detector that ``check``, ``gap`` and ``import`` share.

:func:`file_kind` looks at the name, the first bytes and (for text) the CSV header or the TOML top-level keys:

=============  =================================================================  ====================================
kind           recognised by                                                      read by
=============  =================================================================  ====================================
``log``        ``.npz`` suffix or a zip archive                                   ``run`` output, ``gap``, ``check``
``csv``        ``.csv`` with the header ``t, copter, x, y, yaw`` (or any other     ``import --tracking``, ``check``
               header: the reader names the columns it expected)
``readings``   a CSV header ``t, copter, channel, value``                          ``import --readings``, ``check``
``bag``        a ``.bag`` / ``.mcap`` suffix, their magic bytes, or a folder        ``import --bag``, ``check``
               with ``metadata.yaml`` (ROS 2 bag)
``study``      TOML with ``n_trials``, ``objectives`` or ``params``                 ``tune``, ``check``
``sweep``      TOML with ``grid``, ``random``, ``variants``, ``replicates`` or      ``sweep``, ``check``
               ``metrics`` (``base`` alone: a sweep)
``topics``     TOML whose ``tracking`` / sensor entries are arrays of tables        ``import --topics``, ``check``
``scenario``   any other TOML                                                     ``run``, ``gap --config``, ``check``
=============  =================================================================  ====================================

Text that is neither valid UTF-8 TOML nor a recognised CSV raises :class:`FileKindError` naming the file. Nothing
here reads more than the header of a CSV or the tables of a TOML file.
"""
from __future__ import annotations

from pathlib import Path

from .usertext import loads_toml

__all__ = ["file_kind", "FileKindError", "KIND_NAMES", "STUDY_KEYS", "SWEEP_KEYS", "TOPICS_ROLES", "describe_kind"]

SWEEP_KEYS = ("grid", "random", "variants", "base", "replicates", "metrics")
"""Top-level TOML keys of a sweep file (a scenario's top-level keys are config sections)."""
STUDY_KEYS = ("n_trials", "objectives", "params")
"""Top-level TOML keys only a study file has (it shares ``base`` and ``duration`` with sweeps)."""
TOPICS_ROLES = ("tracking", "ultrasonic", "ranging", "imu")
"""Roles of a topics file: arrays of tables (``[[tracking]]``), where a scenario has tables (``[ranging]``)."""
TRACKING_HEADER = ("t", "copter", "x", "y", "yaw")
READINGS_HEADER = ("t", "copter", "channel", "value")
KIND_NAMES = {"log": "flight log", "csv": "tracking CSV", "readings": "readings CSV", "bag": "recording (bag)",
              "study": "study file", "sweep": "sweep file", "topics": "topics file", "scenario": "scenario file"}
"""Each kind in words, for messages."""
MAGIC = {b"PK\x03\x04": "log", b"#ROSBAG": "bag", b"\x89MCAP": "bag"}


class FileKindError(ValueError):
    """A file that is no finkensim input; the message names it and what was expected."""


def describe_kind(kind: str) -> str:
    """``kind`` in words (``"readings"`` -> ``"readings CSV"``)."""
    return KIND_NAMES.get(kind, kind)


def _csv_header(first_line: str) -> tuple[str, ...]:
    return tuple(c.strip().strip('"').lower() for c in first_line.split(","))


def file_kind(path: str | Path) -> str:
    """The kind (a key of :data:`KIND_NAMES`) of the existing file or folder ``path`` (module doc).

    Raises FileKindError for text that is neither TOML nor a CSV of a known header, and OSError when it cannot
    be read."""
    p = Path(path)
    if p.is_dir():
        if (p / "metadata.yaml").is_file():
            return "bag"
        raise FileKindError(f"{p}: a folder, not a file (only a ROS 2 bag folder, with metadata.yaml, is an input)")
    suffix = p.suffix.lower()
    if suffix == ".npz":
        return "log"
    if suffix in (".bag", ".mcap"):
        return "bag"
    with p.open("rb") as fh:
        head = fh.read(8)
    for magic, kind in MAGIC.items():
        if head.startswith(magic):
            return kind
    try:
        text = p.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise FileKindError(f"{p}: not a text (TOML) file, and not a flight log (.npz), CSV or bag (byte "
                            f"{exc.object[exc.start:exc.start + 1]!r} at offset {exc.start} is not UTF-8)") from None
    first = text.lstrip("\ufeff").split("\n", 1)[0]
    header = _csv_header(first)
    if sorted(header) == sorted(READINGS_HEADER):
        return "readings"
    if suffix == ".csv" or sorted(header) == sorted(TRACKING_HEADER):
        return "csv"
    import tomllib

    try:
        tables = loads_toml(text)
    except tomllib.TOMLDecodeError as exc:
        raise FileKindError(f"invalid TOML in {p}: {exc}") from None
    if any(k in tables for k in STUDY_KEYS):
        return "study"
    if any(k in tables for k in SWEEP_KEYS):
        return "sweep"
    if any(isinstance(tables.get(k), list) for k in TOPICS_ROLES):
        return "topics"
    return "scenario"
