"""Where the public recordings live and whether they are intact: the data folder, SHA-256 checks, CSV reading.

The recordings stay outside the repository (``../shared/realdata/`` beside the clone, or any folder named by the
environment variable ``FINKENSIM_DATA``). Each dataset lives in a sub-folder; every file it uses is checked
against the SHA-256 of its uncompressed bytes (:data:`SHA256`) before it is read, so a truncated or edited copy is
a named error, never silently different numbers.
"""
from __future__ import annotations

import gzip
import hashlib
import os
from pathlib import Path

__all__ = ["DatasetError", "SHA256", "data_home", "dataset_folder", "verified_bytes", "read_csv_verified"]

ENV = "FINKENSIM_DATA"

#: SHA-256 of each file's uncompressed bytes, by dataset folder and file name (without ``.gz``). MILUV and MURP:
#: copied from the folders' ``SHA256SUMS.uncompressed``; UTIL: that folder lists only the original binary log
#: (``SHA256SUMS.original_binary``), so these are the sums of its decoded CSV files and survey file as published
#: there (``zcat FILE.gz | sha256sum``).
SHA256 = {
    "miluv_cirObstacles_3_random_0": {
        "ifo001/mocap.csv": "e633dc86e442b4b6a92643db3501a9bac1c912d5b8c9b6194b90437cb540e7d8",
        "ifo002/mocap.csv": "f6184648cc935afc97e037677dd2486100db3ccfb375672f542d00349c075677",
        "ifo003/mocap.csv": "684ac2748dce9f5343d055a55e52b4f3b0195de882a35ab3503288baac5c28cb",
        "ifo001/uwb_range.csv": "d79d77aafa44715a0f5f3302de4eb08ff158837c423597807481c029a552dad8",
        "ifo002/uwb_range.csv": "8bf7381fc06d7dd2126fab59951533f054e00e91b13d0bb05ccc14bff8349305",
        "ifo003/uwb_range.csv": "14729982c5cf392a37c4abc80a1d90481581342ed2a1af4fe229839ebfceab14",
        "timeshift.yaml": "4b392d2924fa445bb930b059da8b7eacca9e1bd0386ba642e93fba6b79be475f",
    },
    "murp_trial16": {
        "16_base-1_targ-2_win-1_step-1.csv": "5bf2877da7066481d762dfcc9191d36e384d4b4df7d3aaa5859a943f54763bbb",
        "16_base-1_targ-3_win-1_step-1.csv": "40aba04b43b56605e98a8cc2e979fc925e6d26fd93a611e3f6ffc906942bac0d",
        "16_base-2_targ-1_win-1_step-1.csv": "f9685baf41372219cdb3a9373adb413b91a75352b78c40ac25e272a04512f6bb",
        "16_base-2_targ-3_win-1_step-1.csv": "ef70e73f11574ace7dd22ef3a0b848aee2f29bf47307d225f4cd163a1fcdb875",
        "16_base-3_targ-1_win-1_step-1.csv": "128828f90cc5090f014fa5de7a17013df157224d267d00ef4e4872a3d4a6a63f",
        "16_base-3_targ-2_win-1_step-1.csv": "cfc60284978bdd44e11c528a350c1decece2fae4aa40aed7292b8c5e27ed4a45",
    },
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
    """The sub-folder of one dataset (a key of :data:`SHA256`), or a :class:`DatasetError` naming it."""
    folder = data_home() / name
    if not folder.is_dir():
        raise DatasetError(f"dataset folder {folder} does not exist; expected the {name!r} recording there "
                           f"(set {ENV} to the folder that holds {name}/)")
    return folder


def verified_bytes(dataset: str, name: str) -> bytes:
    """The uncompressed bytes of file ``name`` of ``dataset`` (read from ``name`` or ``name.gz``), checked against
    :data:`SHA256`; a :class:`DatasetError` names the file when it is absent, unreadable or differs."""
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
    want = SHA256[dataset][name]
    if got != want:
        raise DatasetError(f"{folder}: file {name} has SHA-256 {got}, expected {want} (a corrupt or different copy; "
                           "fetch the published one again)")
    return data


def read_csv_verified(dataset: str, name: str, **kwargs):
    """A pandas DataFrame of a verified CSV file (:func:`verified_bytes`); ``kwargs`` go to ``pandas.read_csv``."""
    import io

    import pandas as pd

    return pd.read_csv(io.BytesIO(verified_bytes(dataset, name)), **kwargs)
