"""Where the public recordings live and whether they are intact: the data folder, SHA-256 checks, CSV reading.

The recordings stay outside the repository (``../shared/realdata/`` beside the clone, or any folder named by the
environment variable ``FINKENSIM_DATA``). Each dataset lives in a sub-folder; every file it uses is checked
against the SHA-256 of its uncompressed bytes before it is read: the sum the folder itself lists
(:data:`LISTED_SUMS`), or finkensim's own (:data:`OWN_SHA256`) for a file the folder lists none for, so a truncated or edited copy is
a named error, never silently different numbers.
"""
from __future__ import annotations

import gzip
import hashlib
import os
from pathlib import Path

__all__ = ["DatasetError", "LISTED_SUMS", "OWN_SHA256", "data_home", "dataset_folder", "listed_sums", "expected_sum",
           "verified_bytes", "read_csv_verified"]

ENV = "FINKENSIM_DATA"

#: The list of SHA-256 sums each dataset folder publishes: one line ``<hex>  <file>`` per file, of the uncompressed
#: bytes (MILUV, MURP and the Paparazzi log publish one).
LISTED_SUMS = "SHA256SUMS.uncompressed"

#: SHA-256 of the uncompressed bytes of files whose folder publishes no sum for them, by dataset folder and file name
#: (without ``.gz``): UTIL's folder lists only the original binary log (``SHA256SUMS.original_binary``), so these are
#: finkensim's own sums of the decoded CSV files and the survey file as published there (``zcat FILE.gz | sha256sum``).
OWN_SHA256 = {
    "util_twr_obs_log1": {
        "estDistance.csv": "d0eb7d7435da124d449e4b577baa8c02a1c292db8b7d7291d35156cb870fdb9c",
        "estPose_mocap.csv": "81a501a7bba0dd4d7c55d8d924a85b89842750a91fba8c7c8663f5442a250224",
        "anchor_0607.txt": "ab48e3fe1c2bb93814e11e0a2bfa8ac95fce1d3d31619aade3e1f6c561c2188f",
    },
}


class DatasetError(OSError):
    """A public recording is absent, incomplete or corrupt; the message names the folder and the file."""


def _candidates():
    env = os.environ.get(ENV, "").strip()
    if env:
        yield Path(env).expanduser(), f"${ENV}"
        return
    repo = Path(__file__).resolve().parents[2]
    yield repo.parent / "shared" / "realdata", "../shared/realdata beside the repository"
    yield Path.cwd().parent / "shared" / "realdata", "../shared/realdata beside the working directory"


def data_home() -> Path:
    """The folder holding the public recordings: ``$FINKENSIM_DATA`` when set, else ``../shared/realdata`` beside
    the repository (or beside the working directory). A :class:`DatasetError` names where it looked."""
    tried = []
    for path, why in _candidates():
        if path.is_dir():
            return path
        tried.append(f"{path} ({why})")
    raise DatasetError(f"real-data folder not found; looked in {'; '.join(tried)}: put the recordings there (see "
                       f"docs/real-data.md) or set {ENV} to the folder that holds them")


def dataset_folder(name: str) -> Path:
    """The sub-folder ``name`` of one dataset (e.g. ``"murp_trial16"``), or a :class:`DatasetError` naming it."""
    folder = data_home() / name
    if not folder.is_dir():
        raise DatasetError(f"dataset folder {folder} does not exist; expected the {name!r} recording there "
                           f"(set {ENV} to the folder that holds {name}/)")
    return folder


def listed_sums(dataset: str) -> dict[str, str]:
    """The SHA-256 sums that the folder of ``dataset`` publishes (:data:`LISTED_SUMS`): file name → hex digest;
    empty when it publishes none. A malformed line is a :class:`DatasetError` naming the file and the line."""
    path = dataset_folder(dataset) / LISTED_SUMS
    if not path.is_file():
        return {}
    sums = {}
    for number, line in enumerate(path.read_text().splitlines(), 1):
        if not line.strip():
            continue
        parts = line.split()
        if len(parts) != 2 or len(parts[0]) != 64:
            raise DatasetError(f"{path}: line {number} reads {line[:80]!r}; expected '<64 hex digits>  <file name>'")
        sums[parts[1].lstrip("*")] = parts[0].lower()
    return sums


def expected_sum(dataset: str, name: str) -> str:
    """The SHA-256 that file ``name`` of ``dataset`` must have: the folder's own list first, then
    :data:`OWN_SHA256`; a :class:`DatasetError` when neither holds one."""
    want = listed_sums(dataset).get(name) or OWN_SHA256.get(dataset, {}).get(name)
    if want is None:
        raise DatasetError(f"{dataset_folder(dataset)}: no SHA-256 sum for file {name} (neither in the folder's "
                           f"{LISTED_SUMS} nor in finkensim's own list); expected the published folder")
    return want


def verified_bytes(dataset: str, name: str) -> bytes:
    """The uncompressed bytes of file ``name`` of ``dataset`` (read from ``name`` or ``name.gz``), checked against
    :func:`expected_sum`; a :class:`DatasetError` names the file when it is absent, unreadable or differs."""
    folder = dataset_folder(dataset)
    plain, packed = folder / name, folder / f"{name}.gz"
    try:
        if packed.is_file():
            data = gzip.decompress(packed.read_bytes())
        elif plain.is_file():
            data = plain.read_bytes()
        else:
            raise DatasetError(f"{folder}: file {name} (or {name}.gz) is missing; expected the published copy")
    except (OSError, EOFError, gzip.BadGzipFile) as exc:
        if isinstance(exc, DatasetError):
            raise
        raise DatasetError(f"{folder}: file {name} cannot be read ({exc}); expected the published copy") from None
    got = hashlib.sha256(data).hexdigest()
    want = expected_sum(dataset, name)
    if got != want:
        raise DatasetError(f"{folder}: file {name} has SHA-256 {got}, expected {want} (a corrupt or different copy; "
                           "fetch the published one again)")
    return data


def read_csv_verified(dataset: str, name: str, **kwargs):
    """A pandas DataFrame of a verified CSV file (:func:`verified_bytes`); ``kwargs`` go to ``pandas.read_csv``."""
    import io

    import pandas as pd

    return pd.read_csv(io.BytesIO(verified_bytes(dataset, name)), **kwargs)
