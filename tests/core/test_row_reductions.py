"""core.mesh's reductions along rows of three (row_sums, row_norms, any_in_rows,
all_in_rows) give NumPy's own results bit for bit, on real coordinates and at
the edges of the floats."""

import numpy as np
import pytest

from core.mesh import (all_in_rows, any_in_rows, face_areas, power_of_two_scale, row_norms,
                       row_sums, unit_rows)
from tests.mesh_factory import load_shared


def _awkward_rows(rng, scale):
    """Rows of mixed sign and magnitude (cancellation, zeros, huge and tiny)."""
    X = rng.normal(size=(50_000, 3)) * scale
    X[::7, 1] = 0.0
    X[::11] *= -1e8
    X[::13, 2] = -X[::13, 0]         # exact cancellation of the first two of a row's sum
    X[::17] = [1e16, 1.0, 1.0]       # the order of the additions shows (1e16 + 1 + 1 = 1e16)
    return X


@pytest.mark.parametrize("scale", [1e-300, 1e-8, 1.0, 1e150, 1e300])
def test_float_rows_are_numpys_bits(scale):
    with np.errstate(over="ignore", invalid="ignore"):
        X = _awkward_rows(np.random.default_rng(5), scale)
        assert np.array_equal(row_sums(X), X.sum(axis=1), equal_nan=True)
        assert np.array_equal(row_norms(X), np.linalg.norm(X, axis=1), equal_nan=True)


def test_non_finite_rows_propagate_as_numpy():
    X = np.array([[np.nan, 1.0, 2.0], [np.inf, -np.inf, 0.0], [np.inf, 1.0, 1.0], [0.0, 0.0, 0.0]])
    with np.errstate(invalid="ignore"):
        assert np.array_equal(row_sums(X), X.sum(axis=1), equal_nan=True)
        assert np.array_equal(row_norms(X), np.linalg.norm(X, axis=1), equal_nan=True)


def test_bool_rows_count_and_test():
    B = np.random.default_rng(2).random((10_000, 3)) < 0.4
    assert row_sums(B).dtype == B.sum(axis=1).dtype
    assert np.array_equal(row_sums(B), B.sum(axis=1))
    assert np.array_equal(any_in_rows(B), B.any(axis=1))
    assert np.array_equal(all_in_rows(B), B.all(axis=1))
    assert row_sums(np.ones((4, 3), dtype=bool)).tolist() == [3, 3, 3, 3]   # counts, not OR


def test_users_give_the_same_bits_on_a_real_mesh():
    V, F = load_shared("stanford-bunny.obj")
    N = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    assert np.array_equal(face_areas(V, F), 0.5 * np.linalg.norm(N, axis=1))
    length = np.linalg.norm(N, axis=1)
    expected = np.divide(N, length[:, None], out=np.zeros_like(N), where=length[:, None] > 0)
    assert np.array_equal(unit_rows(N), expected)
    for s in (1.0, 1e280, 1e-280):
        assert power_of_two_scale(V * s, F) == (
            1.0 if s == 1.0 else float(np.ldexp(1.0, int(np.frexp(np.abs(V * s)[F].max())[1]))))
