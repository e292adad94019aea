"""The batched factorizations of rendering._pinv against numpy's per-matrix references."""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from vibrofocus.rendering._pinv import SMALL_GRAM, SpectralPinv, gram_matrix, hpd_inverse


def random_stack(rng, n_freqs, n_rows, n_cols):
    return rng.standard_normal((n_freqs, n_rows, n_cols)) + 1j * rng.standard_normal((n_freqs, n_rows, n_cols))


def with_condition(rng, n_freqs, k, condition):
    """Hermitian positive definite matrices with condition number ``condition``."""
    q, _ = np.linalg.qr(random_stack(rng, n_freqs, k, k))
    eigenvalues = np.geomspace(1.0, 1.0 / condition, k)
    return (q * eigenvalues[None, None, :]) @ np.conj(np.swapaxes(q, 1, 2))


# Both sides of the size at which the vectorized sweep hands over to LAPACK.
@pytest.mark.parametrize("k", [1, 2, 4, SMALL_GRAM, SMALL_GRAM + 1, 20])
@pytest.mark.parametrize("condition", [1.0, 1e3, 1e6])
def test_hpd_inverse_inverts(rng, k, condition):
    A = with_condition(rng, 30, k, condition)
    inverse = hpd_inverse(A)
    # Backward-stable inverses leave a residual of about eps * cond.
    assert_allclose(inverse @ A, np.broadcast_to(np.eye(k), A.shape), rtol=0, atol=50 * k * 2.2e-16 * condition)


def test_hpd_inverse_leaves_its_input_alone(rng):
    for shape in [(1, 3, 3), (5, 1, 1)]:  # shapes whose moved axes need no copy to be contiguous
        A = with_condition(rng, shape[0], shape[1], 10.0)
        before = A.copy()
        hpd_inverse(A)
        assert np.array_equal(A, before)


@pytest.mark.parametrize("k", [3, SMALL_GRAM + 4])
def test_an_exactly_singular_matrix_spoils_only_its_own_inverse(rng, k):
    A = with_condition(rng, 3, k, 10.0)
    A[1] = 0.0  # LAPACK refuses the whole batch for it
    inverse = hpd_inverse(A)
    assert not np.all(np.isfinite(inverse[1]))
    for f in (0, 2):
        assert_allclose(inverse[f] @ A[f], np.eye(k), rtol=0, atol=1e-12)


def test_hpd_inverse_of_a_singular_matrix_is_not_finite_or_fails_the_bound(rng):
    v = random_stack(rng, 1, 4, 1)
    singular = v @ np.conj(np.swapaxes(v, 1, 2))  # rank one
    inverse = hpd_inverse(singular)
    # No exception: the caller's condition bound (||A||_F ||A^-1||_F) rejects it.
    norm = np.linalg.norm(singular[0]) * np.linalg.norm(inverse[0])
    assert not np.isfinite(norm) or norm > 1e12


@pytest.mark.parametrize("n_cols", [1, 4, SMALL_GRAM, SMALL_GRAM + 1, 32])
def test_gram_matrix_is_the_hermitian_product(rng, n_cols):
    H = random_stack(rng, 7, 40, n_cols)
    expected = np.stack([h.conj().T @ h for h in H])
    G = gram_matrix(H)
    assert_allclose(G, expected, rtol=1e-12, atol=1e-12 * np.abs(expected).max())
    assert np.array_equal(G, np.conj(np.swapaxes(G, 1, 2)))  # exactly Hermitian


def test_gram_matrix_of_a_strided_view(rng):
    H = random_stack(rng, 9, 30, 20)[::2, 3:, ::2]  # the layout a design reads from a larger H
    expected = np.stack([h.conj().T @ h for h in H])
    assert_allclose(gram_matrix(H), expected, rtol=1e-12, atol=1e-12 * np.abs(expected).max())


@pytest.mark.parametrize("shape", [(13, 4), (4, 13), (40, SMALL_GRAM + 2)])
def test_plain_pseudo_inverse_matches_numpy_through_every_route(rng, shape):
    H = random_stack(rng, 12, *shape)
    k = min(shape)
    H[3] = 0.0  # vanishes: zero drives
    lines = H if shape[0] >= shape[1] else np.swapaxes(H, 1, 2)  # columns of a tall H, rows of a wide one
    lines[5, :, 1] = lines[5, :, 0]  # rank deficient: SVD route
    lines[7, :, 1] = lines[7, :, 0] * (1 + 1e-6)  # ill conditioned: SVD route
    H[9] *= 1e-150  # tiny scale: inverted at unit trace, no underflow
    factors = SpectralPinv.factorize(H)
    assert 3 in np.flatnonzero(factors.zero_freqs)
    assert {5, 7} <= set(factors.svd_freqs.tolist())
    expected = np.stack([np.linalg.pinv(h) for h in H])
    rhs = random_stack(rng, 12, shape[0], 1)[:, :, 0]
    assert_allclose(factors.matrix(), expected, rtol=0, atol=1e-9 * np.abs(expected).max(axis=(1, 2), keepdims=True).max())
    got = factors.apply(rhs)
    want = np.einsum("fij,fj->fi", expected, rhs)
    scale = np.abs(want).max(axis=1, keepdims=True)
    assert_allclose(got / np.where(scale > 0, scale, 1.0), want / np.where(scale > 0, scale, 1.0), rtol=0, atol=1e-9)
    assert k == factors.singular_values.shape[1]
