"""Input-checking helpers (finkensim.arrays): conversions, and errors that name the array and what was expected."""
from __future__ import annotations

import numpy as np
import pytest

from finkensim.arrays import as_array, as_env_ids, as_points, as_vectors, check_inplace, describe_shape
from finkensim.config import ConfigError


def test_describe_shape():
    assert describe_shape(("B", "N", 2)) == "(B, N, 2)"
    assert describe_shape(("B", "N", 2), {"B": 4, "N": 3}) == "(B, N, 2) = (4, 3, 2)"
    assert describe_shape(("M",)) == "(M,)"
    assert describe_shape((None, 3)) == "(*, 3)"
    assert describe_shape(()) == "()"


def test_as_array_converts_without_copying_good_input():
    a = np.zeros((3, 2))
    assert as_array("a", a, np.float64, ("N", 2)) is a
    b = as_array("b", [[1, 2], [3, 4]], np.float64, (2, "K"))
    assert b.dtype == np.float64 and b.flags.c_contiguous and b.shape == (2, 2)
    f = np.asfortranarray(np.ones((3, 4)))
    assert as_array("f", f).flags.c_contiguous
    assert as_array("i", [1.0, 2.0], np.int64).dtype == np.int64
    assert as_array("s", 3.5).shape == ()


@pytest.mark.parametrize("value, shape, kwargs, match", [
    (np.zeros((2, 3)), ("B", "N", 2), {}, r"x has shape \(2, 3\): expected \(B, N, 2\) m"),
    (np.zeros((2, 3, 3)), ("B", "N", 2), {}, r"x has shape \(2, 3, 3\): expected \(B, N, 2\)"),
    (np.zeros((2, 3)), ("N", "N"), {}, r"shape \(2, 3\): expected \(N, N\)"),
    (np.zeros((2, 3)), ("B", 3), {"sizes": {"B": 4}}, r"expected \(B, 3\) m = \(4, 3\)|expected \(B, 3\) = \(4, 3\) m"),
    ([[1.0, np.nan]], ("N", 2), {"finite": True}, r"x\[0, 1\] = nan: expected finite values m"),
    ([1.0, np.inf], None, {"finite": True}, r"x\[1\] = inf: expected finite values m"),
    ("abc", ("N",), {}, r"x = 'abc': expected an array of numbers \(N,\) m"),
    ([[1.0, 2.0], [3.0]], None, {}, r"expected an array of numbers"),
    (None, ("N",), {}, r"x = None"),
])
def test_as_array_errors_name_the_array_and_the_expectation(value, shape, kwargs, match):
    with pytest.raises(ConfigError, match=match):
        as_array("x", value, np.float64, shape, unit="m", **kwargs)


def test_as_array_integers_are_not_truncated():
    with pytest.raises(ConfigError, match=r"ids = \[0.5, 1.0\]: expected integers"):
        as_array("ids", [0.5, 1.0], np.int64)
    with pytest.raises(ConfigError, match="expected integers"):
        as_array("ids", [np.nan], np.int64)


def test_errors_are_value_errors():
    # callers that caught ValueError before the helpers existed still do
    with pytest.raises(ValueError):
        as_points("positions", np.zeros((2, 3)), ("B", "N"))


def test_as_vectors_and_points():
    v = as_vectors("acc", np.ones((4, 3)), 3)
    assert v.shape == (4, 3)
    with pytest.raises(ConfigError, match=r"acc has shape \(4, 2\): expected \(N, 3\)"):
        as_vectors("acc", np.ones((4, 2)), 3)
    p = as_points("positions", np.ones((2, 5, 2)), ("B", "N"))
    assert p.shape == (2, 5, 2) and p.dtype == np.float64
    with pytest.raises(ConfigError, match=r"positions\[0, 1, 0\] = nan: expected finite values m"):
        as_points("positions", [[[0.0, 0.0], [np.nan, 1.0]]], ("B", "N"))
    with pytest.raises(ConfigError, match=r"beacons has shape \(3,\): expected \(M, 2\) m"):
        as_points("beacons", [1.0, 2.0, 3.0], ("M",), allow_empty=True)
    for empty in ((), [], None, np.zeros((0, 2))):
        e = as_points("beacons", empty, ("M",), allow_empty=True)
        assert e.shape == (0, 2) and e.dtype == np.float64
    with pytest.raises(ConfigError, match="beacons"):
        as_points("beacons", None, ("M",))
    sized = as_points("p", np.ones((3, 2)), ("N",), sizes={"N": 3})
    assert sized.shape == (3, 2)
    with pytest.raises(ConfigError, match=r"expected \(N, 2\) = \(4, 2\) m"):
        as_points("p", np.ones((3, 2)), ("N",), sizes={"N": 4})


def test_as_env_ids():
    env = as_env_ids("env_ids", [3, 4, 5], 3)
    assert env.dtype == np.int64 and env.tolist() == [3, 4, 5] and env.flags.c_contiguous
    assert as_env_ids("env_ids", 7).tolist() == [7]
    assert as_env_ids("env_ids", np.array([1, 2], dtype=np.int32)).dtype == np.int64
    with pytest.raises(ConfigError, match=r"env_ids has 1 entries: expected 2 \(one per environment\)"):
        as_env_ids("env_ids", [0], 2)
    with pytest.raises(ConfigError, match=r"env_ids has shape \(2, 2\): expected \(B,\)"):
        as_env_ids("env_ids", np.zeros((2, 2), dtype=np.int64))
    with pytest.raises(ConfigError, match="expected integers"):
        as_env_ids("env_ids", [0.5])


def test_check_inplace():
    out = np.empty((2, 3))
    assert check_inplace("out", out, (2, 3)) is out
    want = r"out is a float64 array of shape \(3, 2\): expected a writable C-contiguous float64 array of shape \(2, 3\)"
    with pytest.raises(ConfigError, match=want):
        check_inplace("out", np.empty((3, 2)), (2, 3))
    with pytest.raises(ConfigError, match=r"out is a float32 array of shape \(2, 3\):"):
        check_inplace("out", np.empty((2, 3), dtype=np.float32), (2, 3))
    with pytest.raises(ConfigError, match="not C-contiguous"):
        check_inplace("out", np.empty((3, 2)).T, (2, 3))
    ro = np.empty((2, 3))
    ro.setflags(write=False)
    with pytest.raises(ConfigError, match="read-only"):
        check_inplace("out", ro, (2, 3))
    with pytest.raises(ConfigError, match="out is a list"):
        check_inplace("out", [[0.0] * 3] * 2, (2, 3))
    ints = np.empty(4, dtype=np.int64)
    assert check_inplace("counts", ints, (4,), np.int64) is ints
