"""Flight-log files: :func:`save` and :func:`load` a :class:`~finkensim.flightlog.format.FlightLog`
as a compressed NumPy ``.npz`` archive of named arrays (no pickles; format ``finkensim-flightlog/1``).
"""
from __future__ import annotations

import os
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from ..atomic import atomic_path
from ..budget import check_memory
from ..config import ConfigError
from .encoding import as_text, meta_from_json, meta_to_json
from .format import FORMAT, OPTIONAL, REQUIRED, STANDARD, FlightLog, FlightLogError
from .validation import check_dtype
from .validation import validate as validate_log  # load() has a parameter called validate

__all__ = ["save", "load"]


def _with_file(path, exc: FlightLogError) -> FlightLogError:
    return FlightLogError(f"flight log {str(path)!r}: {exc}")


def save(log: FlightLog, path: str | os.PathLike, *, check_units: bool = True) -> None:
    """Validate ``log`` and write it to ``path`` as a compressed ``.npz`` (no pickles).

    The file is written exactly at ``path`` (no ``.npz`` suffix is appended) via a temporary
    file in the same directory, so a failed save leaves no partial file. Numeric arrays are
    stored as float64, ``format`` and ``meta`` as 0-d str arrays, ``copter_ids`` as a unicode
    str array, extras unchanged.

    Parameters
    ----------
    log : FlightLog
        The flight to write.
    path : str or PathLike
        Where to write it (exactly this name).
    check_units : bool
        Include the unit checks (values that look like cm or mm, times like ms) in the validation.

    Raises
    ------
    FlightLogError
        The log is not valid; nothing is written.
    """
    validate_log(log, check_units=check_units)
    arrays: dict[str, np.ndarray] = {"format": np.array(FORMAT)}
    for name in REQUIRED + OPTIONAL:
        v = getattr(log, name)
        if v is None:
            continue
        if name == "copter_ids":
            arrays[name] = np.asarray(as_text(name, v, scalar=False)).astype(str)
        else:
            arrays[name] = np.asarray(v, dtype=np.float64)
    arrays["meta"] = np.array(meta_to_json(log.meta))
    for k, v in log.extras.items():
        arrays[k] = np.asarray(v)

    with atomic_path(path) as tmp, open(tmp, "xb") as f:  # plain open: the usual umask permissions
        np.savez_compressed(f, **arrays)


def _member_bytes(npz, key: str) -> float:
    """Bytes the array ``key`` of an open archive takes once read, from its .npy header (0 if unreadable)."""
    try:
        with npz.zip.open(key + ".npy") as fh:
            version = np.lib.format.read_magic(fh)
            read = np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
            shape, _, dtype = read(fh)
        return float(np.prod(shape, dtype=float)) * dtype.itemsize
    except Exception:  # noqa: BLE001 - an unreadable member is reported when it is read
        return 0.0


def _check_size(path: Path, npz) -> None:
    """Refuse (before reading anything) an archive whose arrays would not fit in the available memory."""
    sizes = {key: _member_bytes(npz, key) for key in npz.files}
    try:
        check_memory(sizes, "reading the flight log",
                     "split the flight into shorter logs or use a machine with more memory")
    except ConfigError as exc:
        raise FlightLogError(f"flight log {str(path)!r}: {exc}") from None


def load(path: str | os.PathLike, validate: bool = True, *, check_units: bool = True) -> FlightLog:
    """Read a flight log ``.npz`` (``allow_pickle=False``) and, by default, :func:`validate` it.

    A missing or unreadable file, a file that is not an ``.npz`` archive, an object (pickled)
    array, a wrong or missing ``format``, missing required arrays or a ``meta`` that is not a
    JSON object, an integer array where the format asks for float64 (anything but ``arena`` and
    ``ultrasonic_offset``), arrays larger than the available memory (checked from the headers
    before anything is read, :mod:`finkensim.budget`) always raise :class:`FlightLogError` naming the
    file; ``validate=False`` skips only the content checks of :func:`validate`. Numeric arrays are
    returned as float64; arrays the format does not name go to ``extras``.

    Parameters
    ----------
    path : str or PathLike
        The ``.npz`` file (format ``finkensim-flightlog/1``, ``docs/formats/flightlog.md``).
    validate : bool
        Check the content (shapes, units, arena, ranges) with :func:`validate` (default True).
    check_units : bool
        Include the unit checks (values that look like cm or mm, times like ms) in the validation.

    Returns
    -------
    FlightLog
        The flight: ``t`` (T,) s, ``pose`` (T, N, 3) m, m, rad and the sensor blocks present in the file.

    Raises
    ------
    FlightLogError
        The file cannot be read as a flight log, or (with ``validate``) its content is wrong; the message
        names the file, the array and what was expected.
    """
    do_validate = validate
    p = Path(path)
    if not p.exists():
        raise FlightLogError(f"flight log {str(p)!r}: file does not exist")
    try:
        npz = np.load(p, allow_pickle=False)
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
        raise FlightLogError(f"flight log {str(p)!r}: cannot be read as a NumPy .npz archive ({exc})") from None
    if not isinstance(npz, np.lib.npyio.NpzFile):
        raise FlightLogError(f"flight log {str(p)!r}: is a single .npy array; expected an .npz archive of named arrays")
    raw: dict[str, np.ndarray] = {}
    with npz:
        _check_size(p, npz)
        for key in npz.files:
            try:
                raw[key] = npz[key]
            except ValueError as exc:
                if "allow_pickle" in str(exc) or "Object arrays" in str(exc):
                    raise FlightLogError(
                        f"flight log {str(p)!r}: array {key!r} is an object (pickled) array; expected numbers or str, no pickles"
                    ) from None
                raise FlightLogError(f"flight log {str(p)!r}: array {key!r} cannot be read ({exc})") from None
            except Exception as exc:  # noqa: BLE001 (a corrupt member raises zlib, zipfile or format errors)
                raise FlightLogError(f"flight log {str(p)!r}: array {key!r} cannot be read ({type(exc).__name__}: {exc})") from None

    try:
        if "format" not in raw:
            raise FlightLogError(f"format is missing; expected a 0-d str array {FORMAT!r}")
        fmt = as_text("format", raw["format"], scalar=True)
        if fmt != FORMAT:
            raise FlightLogError(f"format = {fmt!r}; expected exactly {FORMAT!r}")
        missing = [n for n in REQUIRED if n not in raw]
        if missing:
            raise FlightLogError(
                f"required array{'s' if len(missing) > 1 else ''} {', '.join(missing)} missing; "
                f"a flight log needs {', '.join(REQUIRED)}"
            )
        meta = meta_from_json(as_text("meta", raw["meta"], scalar=True)) if "meta" in raw else {}
        kwargs: dict[str, Any] = {}
        for name in REQUIRED + OPTIONAL:
            if name not in raw:
                continue
            a = raw[name]
            if name == "copter_ids":
                a = as_text(name, a, scalar=False) if a.dtype.kind in "US" else a  # numbers: named by validate
            elif a.dtype.kind in "iuf":
                check_dtype(name, a)  # an integer pose / t is an error even without validation
                a = a.astype(np.float64, copy=False)
                if name == "ultrasonic_offset" and a.shape == ():
                    a = float(a)
            kwargs[name] = a
        extras = {k: v for k, v in raw.items() if k not in STANDARD}
        log = FlightLog(**kwargs, meta=meta, extras=extras)
        if do_validate:
            validate_log(log, check_units=check_units)
    except FlightLogError as exc:
        raise _with_file(p, exc) from None
    return log
