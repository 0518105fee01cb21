"""With ``NUMBA_DISABLE_JIT=1`` (a line-coverage run of the kernels, as STUMPY measures its own) the package imports
and flies the same flight as the compiled engine, bit for bit."""
import os
import subprocess
import sys

import numpy as np

import finkensim as fs

_FLY = """
import sys, warnings
import numpy as np
warnings.simplefilter("ignore")  # uint64 wrap-around in the counter-based draws warns in plain Python
import finkensim as fs, finkensim.gap, finkensim.envs, finkensim.importing
sim = fs.SwarmSim(fs.load_config())
_, rec = sim.rollout(sim.init(n_envs=2, seed=3), n_steps=6)
np.savez(sys.argv[1], **{k: v for k, v in rec._asdict().items() if isinstance(v, np.ndarray)})
"""


def test_the_package_flies_the_same_flight_without_jit(tmp_path):
    out = tmp_path / "nojit.npz"
    env = {**os.environ, "NUMBA_DISABLE_JIT": "1"}
    done = subprocess.run([sys.executable, "-c", _FLY, str(out)], env=env, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-3000:]
    sim = fs.SwarmSim(fs.load_config())
    _, rec = sim.rollout(sim.init(n_envs=2, seed=3), n_steps=6)
    plain = np.load(out)
    compiled = {k: v for k, v in rec._asdict().items() if isinstance(v, np.ndarray)}
    assert set(plain.files) == set(compiled)
    for name in plain.files:
        np.testing.assert_array_equal(plain[name], compiled[name], err_msg=name)
