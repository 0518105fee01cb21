"""Public drone-ranging recordings as finkensim recordings and flight logs (in the style of scikit-learn's loaders).

    from finkensim.datasets import load_murp
    ds = load_murp()                 # a RealDataset: Recording in the arena frame, arena, truth per reading
    log = ds.flight()                # the flight log, through the importer
    args = ds.write_csv("out/murp")  # track.csv + read.csv and the `finkensim import` arguments that read them

The data stay outside the repository, in ``$FINKENSIM_DATA`` or ``../shared/realdata/`` beside the clone
(:func:`data_home`); every file is checked against its SHA-256 before it is read. Each loader's module says which
conversions it makes (frame, origin, yaw, time base, fixed anchors) and what it leaves out.
"""
from __future__ import annotations

from .files import DatasetError, data_home
from .miluv import load_miluv
from .murp import load_murp
from .record import RealDataset
from .util import load_util

__all__ = ["DatasetError", "data_home", "RealDataset", "load_miluv", "load_murp", "load_util", "LOADERS"]

#: dataset folder name -> loader
LOADERS = {"miluv_cirObstacles_3_random_0": load_miluv, "murp_trial16": load_murp, "util_twr_obs_log1": load_util}
