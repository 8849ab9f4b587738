"""The ragged-group helpers shared across the core (:mod:`core._groups`)."""

import numpy as np
import pytest

from core._groups import member_of, sort_keys, sorted_unique, stable_argsort


def test_stable_argsort_is_numpys_stable_argsort():
    rng = np.random.default_rng(6)
    for x in (rng.integers(0, 50, 1000), rng.integers(0, 1 << 40, 1000),
              np.array([2 ** 62, 3, 2 ** 62, 0]), np.zeros(0, dtype=np.int64),
              rng.integers(0, 3000, 100_000).astype(np.int32)):   # (int32 keys times k)
        np.testing.assert_array_equal(stable_argsort(x), np.argsort(x, kind="stable"))


@pytest.mark.parametrize("bound", [1, 2, 1 << 16, (1 << 16) + 1, 1 << 30, 1 << 45])
def test_sort_keys_is_the_stable_order_and_the_sorted_keys_at_every_width(bound):
    # 16-bit keys go to NumPy's radix sort, wider ones to the packed sort (the edges)
    rng = np.random.default_rng(bound % 1000)
    key = rng.integers(0, bound, 5000)
    key[:3] = [bound - 1, 0, bound - 1]
    want = np.argsort(key, kind="stable")
    order, ks = sort_keys(key.copy(), bound)
    np.testing.assert_array_equal(order, want)
    np.testing.assert_array_equal(ks, key[want])
    assert order.dtype == ks.dtype == np.int64


@pytest.mark.parametrize("dtype", [np.int64, np.int32, np.uint16, np.bool_, np.float64])
def test_sorted_unique_is_np_unique_value_for_value_and_dtype(dtype):
    # NumPy 2.3+ finds np.unique's values with a hash table (2M int64: 1.4 s against
    # 0.02 s by a sort); the helper sorts, as NumPy 1.x did: the same array
    rng = np.random.default_rng(11)
    for x in (rng.integers(0, 40, (300, 3)), rng.integers(0, 1 << 14, 10_000),
              np.arange(7)[::-1], np.zeros(0, dtype=np.int64), np.array([5]), np.full(9, 3)):
        x = x.astype(dtype)
        got, want = sorted_unique(x), np.unique(x)
        assert got.dtype == want.dtype and got.shape == want.shape
        np.testing.assert_array_equal(got, want)


def test_member_of_is_np_isin_with_a_sort_not_a_hash():
    rng = np.random.default_rng(12)
    for values, among in ((rng.integers(0, 1 << 40, (200, 3)), rng.integers(0, 1 << 40, 500)),
                          (rng.integers(0, 60, 1000), rng.integers(0, 60, (40, 3))),
                          (np.arange(10), np.zeros(0, dtype=np.int64)),
                          (np.zeros(0, dtype=np.int64), np.arange(5)),
                          (np.array([-3, 0, 7]), np.array([7, -3])),
                          (rng.integers(0, 1 << 20, 5000).astype(np.int32), rng.integers(0, 1 << 20, 900))):
        values[..., :1] = among.ravel()[:1] if among.size else 0       # (a hit at the start)
        got = member_of(values, among)
        assert got.dtype == bool and got.shape == values.shape
        np.testing.assert_array_equal(got, np.isin(values, among))
