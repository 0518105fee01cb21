"""The public API: every advertised name resolves, is documented, and `import finkensim` stays light."""
from __future__ import annotations

import subprocess
import sys

import pytest

import finkensim as fs


@pytest.mark.parametrize("name", [n for n in fs.__all__ if n != "__version__"])
def test_every_public_name_resolves_and_is_documented(name):
    obj = getattr(fs, name)
    assert (obj.__doc__ or "").strip(), f"finkensim.{name} has no docstring"


def test_unknown_names_raise_attribute_error():
    with pytest.raises(AttributeError, match="no attribute 'Wrold'"):
        fs.Wrold


def test_import_finkensim_does_not_load_numba():
    code = "import sys, finkensim; print('numba' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    assert out == "False"
