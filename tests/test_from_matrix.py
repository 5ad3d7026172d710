"""``from_matrix``: the conversion of rotation matrices (default) and the projection onto
the nearest element in the Frobenius norm (``project=True``), against independent references.

* Near and at π, mpmath: the quaternion of the exact rotation (50 digits) whose rounded
  matrix the function receives (rounding the matrix moves the quaternion by O(ε)), up to
  sign.
* Noisy rotations: the orthogonal polar factor by Newton's iteration X ← (X + X⁻ᵀ)/2 in long
  double (64-bit significand), which for det M > 0 is the nearest rotation; also the SVD
  projection U diag(1, …, 1, det UVᵀ) Vᵀ in numpy float64, and scipy's ``from_matrix``
  (which projects a non-orthogonal matrix of positive determinant, and refuses the others).
* jaxlie 1.5's ``from_matrix`` (Shepperd's formulas) for rotation matrices.
* The hard cases (half turns, reflections, rank-deficient matrices): the SVD projection where
  the nearest rotation is unique, the minimal distance from the singular values where it is
  not.
* Derivatives: ``jax.jacfwd`` of the SVD projection written in JAX, and central differences;
  at rotations, the closed form Ṙ = R·hat(vee(RᵀṀ − ṀᵀR)/2) (the projection's derivative
  there), which the conversion must give too.
* The conversion off the rotations: its distance to the polar factor, which must shrink as
  the square of the deviation.

Errors are the largest entry error of the rotation matrix, in units of the input dtype's ε.
"""

import jax
import jax.numpy as jnp
import jaxlie as jaxlie_ref
import mpmath as mp
import numpy as np
import pytest
from _programs import BATCH
from conftest import (
    DTYPES,
    GROUPS,
    HALF_DTYPES,
    dtype_name,
    group_name,
    is_se,
    over_dtypes,
    over_groups,
    over_groups_dtypes,
    to_np,
)
from scipy.spatial.transform import Rotation

import jaxlie_geo as jl

mp.mp.dps = 50

NOISES = [0.0, 1e-6, 1e-3, 1e-1]
PLANAR_GROUPS = [G for G in GROUPS if G.space_dim == 2]
"""The groups whose rotation block is 2×2 (the atan2 formula)."""


def _exact(axis, angle):
    axis = [mp.mpf(a) for a in axis]
    n = mp.sqrt(mp.fsum(a * a for a in axis))
    u = [a / n for a in axis]
    h = mp.mpf(angle) / 2
    q = [mp.cos(h)] + [mp.sin(h) * a for a in u]
    w, x, y, z = q
    R = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ]
    return q, R


ANGLES = [
    0.0,
    1e-12,
    1e-3,
    1.0,
    3.0,
    mp.pi - mp.mpf("1e-2"),
    mp.pi - mp.mpf("1e-5"),
    mp.pi - mp.mpf("1e-7"),
    mp.pi,
]


def _rotations(n, count, seed):
    """``count`` random rotation matrices of size n (2 or 3), float64."""
    if n == 3:
        return Rotation.random(count, random_state=seed).as_matrix()
    t = np.random.default_rng(seed).uniform(-np.pi, np.pi, count)
    c, s = np.cos(t), np.sin(t)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


def _inv_transpose(X):
    """X⁻ᵀ for 2×2 or 3×3 matrices of any numpy float dtype (long double included), by
    cofactors."""
    if X.shape[-1] == 2:
        a, b, c, d = X[..., 0, 0], X[..., 0, 1], X[..., 1, 0], X[..., 1, 1]
        cof = np.stack([np.stack([d, -c], -1), np.stack([-b, a], -1)], -2)
    else:
        r0, r1, r2 = X[..., 0, :], X[..., 1, :], X[..., 2, :]
        cof = np.stack([np.cross(r1, r2), np.cross(r2, r0), np.cross(r0, r1)], -2)
    det = np.sum(X[..., 0, :] * cof[..., 0, :], axis=-1)
    return cof / det[..., None, None]


def _polar(M):
    """Orthogonal polar factor of matrices with det > 0, the nearest rotation, by Newton's
    iteration X ← (X + X⁻ᵀ)/2 in long double (quadratic convergence; 12 steps)."""
    X = np.asarray(M, np.longdouble)
    for _ in range(12):
        X = 0.5 * (X + _inv_transpose(X))
    return X


def _svd_nearest(M):
    """U diag(1, …, 1, det UVᵀ) Vᵀ, numpy float64."""
    U, _, Vt = np.linalg.svd(np.asarray(M, np.float64))
    d = np.ones(U.shape[:-1])
    d[..., -1] = np.sign(np.linalg.det(U @ Vt))
    return (U * d[..., None, :]) @ Vt


def _min_distance(M):
    """min over rotations R of ‖R − M‖_F, from the singular values: the nearest rotation
    maximises tr(RᵀM) = σ₁ + … + σₙ₋₁ + sign(det M) σₙ."""
    s = np.linalg.svd(np.asarray(M, np.float64), compute_uv=False)
    n = s.shape[-1]
    best = s[..., :-1].sum(-1) + np.sign(np.linalg.det(np.asarray(M, np.float64))) * s[..., -1]
    return np.sqrt(np.maximum(n + np.sum(s * s, -1) - 2 * best, 0.0))


def _rotation_block(G, T):
    """The rotation matrix of an element: its own, or its ``rotation()``'s (the SE groups,
    Sim3 (without the scale) and SE23)."""
    return to_np((T.rotation() if hasattr(T, "rotation") else T).as_matrix())


def _err(got, want, dtype):
    """Largest entry error, in units of ε of ``dtype``."""
    diff = np.asarray(got, np.longdouble) - np.asarray(want, np.longdouble)
    return float(np.max(np.abs(diff))) / float(jnp.finfo(dtype).eps)


def _noisy(G, noise, dtype, seed, count=500):
    """(input matrices of ``dtype``, their rotation blocks as float64): rotations plus
    Gaussian noise; for SE groups a random translation and a random bottom row."""
    n, rng = G.space_dim, np.random.default_rng(seed)
    A = _rotations(n, count, seed) + noise * rng.normal(size=(count, n, n))
    M = A
    if G.matrix_dim > n:
        M = rng.normal(size=(count, G.matrix_dim, G.matrix_dim))
        M[:, :n, :n] = A
    M = M.astype(dtype)
    return M, M[:, :n, :n].astype(np.float64)


# ---------------------------------------------------------------------------------
# Valid and noisy rotations.


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("project", [False, True], ids=["convert", "project"])
def test_from_matrix_quaternion_near_pi(dtype, project):
    """``SO3.from_matrix`` of rotation matrices near π (rounded from mpmath's exact matrix)
    recovers mpmath's quaternion within 4 ulp (up to sign); ``SE3.from_matrix`` takes the same
    rotation path."""
    rng = np.random.default_rng(5)
    eps = np.finfo(dtype).eps
    worst = 0.0
    for angle in ANGLES:
        for _ in range(8):
            axis = rng.normal(size=3)
            q, R = _exact(axis, angle)
            M = np.array([[float(R[i][j]) for j in range(3)] for i in range(3)], dtype=dtype)
            got = np.asarray(jl.SO3.from_matrix(M, project=project).wxyz, dtype=np.float64)
            ref = np.array([float(c) for c in q])
            err = min(np.abs(got - ref).max(), np.abs(got + ref).max()) / eps
            worst = max(worst, err)
            # SE3 shares the rotation code path; check it is wired the same way.
            H = np.eye(4, dtype=dtype)
            H[:3, :3] = M
            H[:3, 3] = [1.0, -2.0, 3.0]
            T = jl.SE3.from_matrix(H, project=project)
            want = np.asarray(jl.SO3.from_matrix(M, project=project).wxyz)
            assert np.array_equal(np.asarray(T.rotation().wxyz), want)
    assert worst <= 4.0, f"{worst:.1f} ulp"


@over_groups_dtypes
@pytest.mark.parametrize("noise", NOISES)
def test_noisy_rotations_project_to_the_polar_factor(G, dtype, noise):
    """Rotations plus Gaussian noise (0, 1e-6, 1e-3, 1e-1), rounded to the dtype: the rotation
    is the nearest one (the long-double polar factor of the rounded block) within 4 ulp
    (measured at most 3.3, as_matrix's rounding included); the translation is the last
    column as is; the bottom row of the homogeneous matrix is ignored (random here)."""
    M, A = _noisy(G, noise, dtype, seed=11)
    T = G.from_matrix(M, project=True)
    assert _err(_rotation_block(G, T), _polar(A), dtype) <= 4.0
    if is_se(G):
        n = G.space_dim
        assert np.array_equal(np.asarray(T.translation()), M[:, :n, n])


@over_groups_dtypes
@pytest.mark.parametrize("noise", NOISES)
def test_noisy_rotations_match_the_svd_projection(G, dtype, noise):
    """The same inputs against the SVD projection in numpy float64: within 4 ulp of float32.
    In float64 the reference itself is the limit (LAPACK's U and V are each ill-determined
    when the singular values are nearly equal, and their product keeps some of it): within
    64 ulp (measured 22), while the SVD projection and the polar factor differ by up to 22."""
    M, A = _noisy(G, noise, dtype, seed=12)
    got = _rotation_block(G, G.from_matrix(M, project=True))
    assert _err(got, _svd_nearest(A), dtype) <= (4.0 if dtype == np.float32 else 64.0)


@over_dtypes
@pytest.mark.parametrize("noise", NOISES)
def test_agrees_with_scipy(dtype, noise):
    """scipy's ``Rotation.from_matrix`` projects a matrix of positive determinant onto the
    rotations too: the same rotation within 4 ulp of float32, 32 of float64 (scipy's own
    error: measured 22, and it and the polar factor differ by up to 22)."""
    M, A = _noisy(jl.SO3, noise, dtype, seed=13)
    got = _rotation_block(jl.SO3, jl.SO3.from_matrix(M, project=True))
    want = Rotation.from_matrix(A).as_matrix()
    assert _err(got, want, dtype) <= (4.0 if dtype == np.float32 else 32.0)


@over_dtypes
@pytest.mark.parametrize("project", [False, True], ids=["convert", "project"])
def test_rotations_agree_with_jaxlie(dtype, project):
    """For rotation matrices (20 000 random, half turns with w = 0 and near-identity ones
    included), the quaternion is jaxlie's (Shepperd's formulas) within 4 ulp, with the same
    sign (measured, largest component: the conversion 3.0 in float32 and 2.5 in float64 over
    10⁵ rotations; the projection 1.5 and 2.0)."""
    q = np.random.default_rng(11).normal(size=(20000, 4))
    q[:2000, 0] = 0.0
    q[2000:4000, 1:] *= 1e-4
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    M = np.asarray(jl.SO3(jnp.asarray(q, dtype)).as_matrix())
    ours = to_np(jl.SO3.from_matrix(M, project=project).wxyz)
    ref = to_np(jaxlie_ref.SO3.from_matrix(jnp.asarray(M)).wxyz)
    assert np.max(np.abs(ours - ref)) <= 4 * np.finfo(dtype).eps


# ---------------------------------------------------------------------------------
# Hard cases.


@over_dtypes
@pytest.mark.parametrize("project", [False, True], ids=["convert", "project"])
def test_half_turns(dtype, project):
    """Rotations by π: the diagonal ones give their quaternion exactly; one about a random
    axis (rounded from mpmath) is the nearest rotation to the rounded matrix (polar factor)
    within 4 ulp and has w within 4 ulp of 0."""
    for i in range(3):
        M = -np.eye(3, dtype=dtype)
        M[i, i] = 1.0
        want = np.zeros(4)
        want[1 + i] = 1.0
        assert np.array_equal(to_np(jl.SO3.from_matrix(M, project=project).wxyz), want)
    for seed in range(8):
        _, R = _exact(np.random.default_rng(seed).normal(size=3), mp.pi)
        M = np.array([[float(R[i][j]) for j in range(3)] for i in range(3)], dtype=dtype)
        T = jl.SO3.from_matrix(M, project=project)
        assert _err(to_np(T.as_matrix()), _polar(M.astype(np.float64)), dtype) <= 4.0
        assert abs(float(T.wxyz[0])) <= 4 * np.finfo(dtype).eps


@over_dtypes
def test_reflection_gives_the_det_corrected_svd_projection(dtype):
    """A reflection (det < 0) with distinct singular values (3, 2, 1): the nearest rotation
    is U diag(1, 1, −1) Vᵀ, unique, with conditioning κ = (3 + 2 − 1)/(2 − 1) = 4; within
    4 κ ulp of the numpy float64 SVD projection (float64: 16 κ, the reference's limit)."""
    U = Rotation.random(50, random_state=3).as_matrix() * np.array([1.0, 1.0, -1.0])
    V = Rotation.random(50, random_state=4).as_matrix()
    M = ((U * np.array([3.0, 2.0, 1.0])) @ np.swapaxes(V, -1, -2)).astype(dtype)
    assert np.all(np.linalg.det(M.astype(np.float64)) < 0)
    want = _svd_nearest(M)
    got = to_np(jl.SO3.from_matrix(M, project=True).as_matrix())
    assert _err(got, want, dtype) <= (16.0 if dtype == np.float32 else 64.0)


@over_dtypes
def test_orthogonal_reflections_give_a_nearest_rotation(dtype):
    """An orthogonal reflection has a whole set of nearest rotations (those at distance 2):
    the result is one of them, for −R and R diag(1, 1, −1); diag(1, 1, −1) gives the
    identity and −I the half turn about x, as documented."""
    R = Rotation.random(200, random_state=5).as_matrix()
    for M in (-R, R * np.array([1.0, 1.0, -1.0])):
        M = M.astype(dtype)
        got = to_np(jl.SO3.from_matrix(M, project=True).as_matrix())
        dist = np.linalg.norm(got - M.astype(np.float64), axis=(-2, -1))
        np.testing.assert_allclose(dist, 2.0, rtol=0, atol=8 * np.finfo(dtype).eps)
        np.testing.assert_allclose(
            got @ np.swapaxes(got, -1, -2),
            np.broadcast_to(np.eye(3), got.shape),
            atol=4 * np.finfo(dtype).eps,
        )
    assert np.array_equal(
        to_np(jl.SO3.from_matrix(np.diag([1.0, 1.0, -1.0]).astype(dtype), project=True).wxyz),
        [1, 0, 0, 0],
    )
    minus_i = jl.SO3.from_matrix(-np.eye(3, dtype=dtype), project=True)
    assert np.array_equal(to_np(minus_i.wxyz), [0, 1, 0, 0])


@pytest.mark.parametrize("dtype", DTYPES + HALF_DTYPES, ids=dtype_name)
def test_rank_deficient_matrices(dtype):
    """The zero matrix and diag(1, 0, 0) (every rotation, every rotation about x, is nearest)
    give the identity, exactly; diag(1, 1, 0) its unique nearest rotation, the identity."""
    for diag in ([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0]):
        q = jl.SO3.from_matrix(jnp.diag(jnp.asarray(diag, dtype)), project=True).wxyz
        assert q.dtype == dtype and np.array_equal(to_np(q), [1, 0, 0, 0]), (diag, q)


@over_dtypes
def test_random_rank_one_and_two(dtype):
    """Rank 2 (singular values σ₁ > σ₂ > 0 = σ₃): the nearest rotation is unique (κ =
    (σ₁ + σ₂)/σ₂): the SVD projection within 4 κ ulp (float64: 16 κ). Rank 1: not unique;
    the result is at the minimal distance."""
    rng = np.random.default_rng(6)
    U = Rotation.random(100, random_state=7).as_matrix()
    V = Rotation.random(100, random_state=8).as_matrix()
    s = np.stack([rng.uniform(1.0, 2.0, 100), rng.uniform(0.25, 1.0, 100), np.zeros(100)], -1)
    M = ((U * s[:, None, :]) @ np.swapaxes(V, -1, -2)).astype(dtype)
    kappa = (s[:, 0] + s[:, 1]) / s[:, 1]
    got = to_np(jl.SO3.from_matrix(M, project=True).as_matrix())
    err = np.abs(got - _svd_nearest(M)).max(axis=(-2, -1)) / np.finfo(dtype).eps
    assert np.all(err <= (4.0 if dtype == np.float32 else 16.0) * kappa), err.max()
    M1 = (U[:, :, :1] * V[:, None, :, 0] * s[:, None, :1]).astype(dtype)
    got = to_np(jl.SO3.from_matrix(M1, project=True).as_matrix())
    dist = np.linalg.norm(got - M1.astype(np.float64), axis=(-2, -1))
    np.testing.assert_allclose(dist, _min_distance(M1), rtol=0, atol=16 * np.finfo(dtype).eps)


def _hard_matrices():
    R = Rotation.random(random_state=9).as_matrix()
    return {
        "zero": np.zeros((3, 3)),
        "rank 1": np.outer([1.0, 2.0, 0.5], [0.3, -1.0, 2.0]),
        "rank 2": np.diag([2.0, 1.0, 0.0]) @ R,
        "half turn": np.diag([1.0, -1.0, -1.0]),
        "reflection": -R,
        "noise 0.1": R + 0.1 * np.random.default_rng(9).normal(size=(3, 3)),
    }


@over_dtypes
@pytest.mark.parametrize("case", list(_hard_matrices()))
@pytest.mark.parametrize("project", [False, True], ids=["convert", "project"])
def test_no_nan_in_values_or_derivatives(dtype, case, project):
    """Every hard case gives a unit quaternion and finite forward- and reverse-mode
    derivatives, with either setting (where the nearest rotation is not unique the
    projection's derivative does not exist; the result is then finite, 0 where the system
    is exactly singular)."""
    M = jnp.asarray(_hard_matrices()[case], dtype)
    q = jl.SO3.from_matrix(M, project=project).wxyz
    assert abs(float(jnp.linalg.norm(q.astype(jnp.float64))) - 1.0) <= 4 * jnp.finfo(dtype).eps
    f = lambda m: jl.SO3.from_matrix(m, project=project).wxyz  # noqa: E731
    for J in (jax.jacfwd(f)(M), jax.jacrev(f)(M)):
        assert J.dtype == dtype and bool(jnp.all(jnp.isfinite(J))), (case, J)


@pytest.mark.parametrize("G", PLANAR_GROUPS, ids=group_name)
def test_planar_nearest_rotation(G):
    """SO2/SE2 (and, for the formula, the 2×2 block): θ = atan2(m10 − m01, m00 + m11) for any
    2×2 block, reflections included (the SVD projection with the det correction, wherever
    (m00 + m11, m10 − m01) ≠ 0); the zero block and reflections [[a, b], [b, −a]] give the
    identity; −I the half turn with angle +π with ``project=True``, and with the conversion
    jaxlie's sign of the zero below the diagonal."""
    n = G.matrix_dim
    A = np.random.default_rng(10).normal(size=(300, 2, 2))
    M = np.random.default_rng(11).normal(size=(300, n, n))
    M[:, :2, :2] = A
    got = _rotation_block(G, G.from_matrix(M, project=True))
    assert _err(got, _svd_nearest(A), np.float64) <= 16.0
    for block in (np.zeros((2, 2)), np.array([[0.3, 2.0], [2.0, -0.3]]), -np.eye(2)):
        H = np.eye(n)
        H[:2, :2] = block
        for project, minus_pi in ((True, np.pi), (False, -np.pi)):
            T = G.from_matrix(H, project=project)
            rot = T.rotation() if is_se(G) else T
            want = minus_pi if block[0, 0] < 0 else 0.0
            assert float(rot.as_radians()) == want, (block, rot, project)
    # The conversion signs a zero sine as m10, as jaxlie's first column: −I with −0.0 (as
    # numpy writes -np.eye(2)) is the angle −π there, +0.0 the angle π.
    for zero in (0.0, -0.0):
        M = np.array([[-1.0, zero], [zero, -1.0]])  # m10 − m01 = +0.0 for either zero
        ours = jl.SO2.from_matrix(M).unit_complex
        ref = jaxlie_ref.SO2.from_matrix(jnp.asarray(M)).unit_complex
        assert np.array_equal(np.signbit(to_np(ours)), np.signbit(to_np(ref))), (ours, ref)
        np.testing.assert_array_equal(to_np(ours), to_np(ref))


# ---------------------------------------------------------------------------------
# Derivatives, batches, dtypes.


def _svd_nearest_jax(M):
    U, _, Vt = jnp.linalg.svd(M, full_matrices=False)  # square: the same; jax 0.5.3's JVP
    d = jnp.sign(jnp.linalg.det(U @ Vt))
    n = M.shape[-1]
    D = jnp.diag(jnp.concatenate([jnp.ones(n - 1, M.dtype), d[None]]))
    return U @ D @ Vt


@over_groups
def test_derivative_matches_the_svd_projection(G):
    """The Jacobian of the rotation block of ``from_matrix`` (forward and reverse mode) is that
    of the SVD projection (``jax.jacfwd`` through ``jnp.linalg.svd``, differentiable where
    the singular values are distinct) within 1e-12, and central differences within 1e-8, on
    noisy rotations and a reflection; the translation's is the identity."""
    n, N = G.space_dim, G.matrix_dim
    rng = np.random.default_rng(12)
    blocks = [_rotations(n, 1, 13)[0] + 0.1 * rng.normal(size=(n, n)), rng.normal(size=(n, n))]
    if n == 3:
        blocks.append(np.diag([3.0, 2.0, -1.0]) @ _rotations(3, 1, 14)[0])
    for A in blocks:
        M = rng.normal(size=(N, N))
        M[:n, :n] = A
        M = jnp.asarray(M)

        def f(m):
            T = G.from_matrix(m, project=True)
            R = T.rotation() if hasattr(T, "rotation") else T
            return jnp.concatenate([R.as_matrix(), T.as_matrix()[:n, n:]], axis=-1)

        want = jax.jacfwd(_svd_nearest_jax)(M[:n, :n])
        outside = np.ones((N, N), bool)
        outside[:n, :n] = False
        for J in (jax.jacfwd(f)(M), jax.jacrev(f)(M)):
            np.testing.assert_allclose(J[:, :n, :n, :n], want, rtol=0, atol=1e-12)
            np.testing.assert_array_equal(J[:, :n][..., outside], 0.0)  # other entries
            if is_se(G):  # the translation column: the input's last column
                want_t = np.zeros((n, N, N))
                want_t[np.arange(n), np.arange(n), n] = 1.0
                np.testing.assert_array_equal(J[:, n], want_t)
        h = 1e-6
        fd = np.zeros((n, n, n, n))
        for i in range(n):
            for j in range(n):
                E = jnp.zeros((N, N)).at[i, j].set(h)
                fd[:, :, i, j] = (f(M + E) - f(M - E))[:, :n] / (2 * h)
        np.testing.assert_allclose(fd, want, rtol=0, atol=1e-8)


@over_groups_dtypes
@pytest.mark.parametrize("batch", [(), BATCH], ids=["b0", "b4x8"])
def test_batched_jitted_and_vmapped(G, batch, dtype):
    """Any leading batch axes; dtype in = dtype out; the same numbers eagerly, under ``jit``
    and under ``vmap`` over the first axis."""
    n = G.matrix_dim
    M = np.random.default_rng(15).normal(size=(*batch, n, n))
    M[..., : G.space_dim, : G.space_dim] += 2 * np.eye(G.space_dim)
    M = M.astype(dtype)
    T = G.from_matrix(M)
    assert T.get_batch_axes() == batch and T.parameters().dtype == dtype
    np.testing.assert_array_equal(jax.jit(G.from_matrix)(M).parameters(), T.parameters())
    if batch:
        # The batched and the vmapped programs may round differently: a few ulp apart.
        V = jax.vmap(G.from_matrix)(jnp.asarray(M))
        eps = float(jnp.finfo(dtype).eps)
        np.testing.assert_allclose(V.parameters(), T.parameters(), rtol=0, atol=4 * eps)


# ---------------------------------------------------------------------------------
# The conversion (project=False) off and on the rotations.


def _hat(w):
    x, y, z = w[..., 0], w[..., 1], w[..., 2]
    o = np.zeros_like(x)
    return np.stack(
        [np.stack([o, -z, y], -1), np.stack([z, o, -x], -1), np.stack([-y, x, o], -1)], -2
    )


def _switch_rotations():
    """Rotations on the branch switches of Day's choice (m00 = m11 with m22 < 0, m00 = −m11
    with m22 ≥ 0, m22 = 0) and the three diagonal half turns, float64."""
    out = [np.diag(d) for d in ([1.0, -1.0, -1.0], [-1.0, 1.0, -1.0], [-1.0, -1.0, 1.0])]
    for angle in (0.3, 2.0, np.pi - 1e-3, np.pi):
        # About a diagonal axis in the xy-plane: m00 = m11; rotations about z: m00 = −m11
        # only at ±π/2, so also the quarter turn; about x by π/2: m22 = 0.
        for axis in ([1.0, 1.0, 0.0], [1.0, -1.0, 0.3], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]):
            out.append(
                Rotation.from_rotvec(angle * np.asarray(axis) / np.linalg.norm(axis)).as_matrix()
            )
    # The quarter turns about x and z with exact entries: m22 = 0 and m00 = −m11 = 0 exactly.
    out.append(np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]))
    out.append(np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]))
    return np.stack(out)


@pytest.mark.parametrize("G", [jl.SO3, jl.SE3], ids=group_name)
def test_conversion_is_second_order_near_the_rotations(G):
    """For M = R + εN (N Gaussian), the conversion's rotation is within 8ε² of the polar
    factor (measured 6.3ε², largest entry over 500; Shepperd's formulas alone are 1.4ε off):
    shrinking ε by 10 shrinks the error by 100, down to rounding. float64."""
    R = Rotation.random(500, random_state=21).as_matrix()
    N = np.random.default_rng(22).normal(size=R.shape)
    for eps in (1e-2, 1e-3, 1e-4):
        A = R + eps * N
        M = (
            A
            if G is jl.SO3
            else np.concatenate(
                [
                    np.concatenate([A, np.ones((500, 3, 1))], -1),
                    np.tile([[[0, 0, 0, 1.0]]], (500, 1, 1)),
                ],
                -2,
            )
        )
        got = _rotation_block(G, G.from_matrix(M))
        err = float(np.max(np.abs(got - _polar(A))))
        assert err <= 8 * eps * eps, (eps, err)


def test_conversion_of_a_similarity_is_second_order():
    """Sim3: M = s(R + εN) with s from 1e-3 to 1e3: the scale and the rotation are the
    nearest similarity's (the polar factor, and tr(RᵀM)/3) within 4ε² relative (measured
    3.3ε²)."""
    R = Rotation.random(200, random_state=23).as_matrix()
    s = np.exp(np.random.default_rng(24).uniform(np.log(1e-3), np.log(1e3), 200))
    N = np.random.default_rng(25).normal(size=R.shape)
    for eps in (1e-2, 1e-3):
        A = s[:, None, None] * (R + eps * N)
        M = np.zeros((200, 4, 4))
        M[:, :3, :3], M[:, 3, 3] = A, 1.0
        T = jl.Sim3.from_matrix(M)
        P = _polar(R + eps * N)  # of A/s: the polar factor is scale-invariant
        s_ref = np.sum(np.asarray(P, np.float64) * A, axis=(-2, -1)) / 3
        assert float(np.max(np.abs(to_np(T.rotation().as_matrix()) - P))) <= 4 * eps * eps
        assert float(np.max(np.abs(to_np(T.scale()) / s_ref - 1))) <= 4 * eps * eps


@pytest.mark.parametrize("mode", ["jacfwd", "jacrev"])
def test_conversion_derivative_at_rotations_is_exact(mode):
    """At rotations (random ones, the diagonal half turns and rotations on each branch
    switch of Day's choice), the derivative of the conversion's rotation matrix with
    respect to the input matrix is the projection's, in closed form: along Ṁ,
    Ṙ = R·hat(ω) with ω = vee(RᵀṀ − ṀᵀR)/2; within 1e-12 in float64, finite everywhere
    (a square root of each candidate before the choice would give NaN at half turns)."""
    Rs = np.concatenate([Rotation.random(20, random_state=26).as_matrix(), _switch_rotations()])
    diff = jax.jacfwd if mode == "jacfwd" else jax.jacrev
    J = jax.vmap(diff(lambda m: jl.SO3.from_matrix(m).as_matrix()))(jnp.asarray(Rs))
    J = np.asarray(J)  # (batch, 3, 3 | 3, 3)
    assert np.all(np.isfinite(J))
    for k in range(3):
        for l in range(3):
            E = np.zeros((3, 3))
            E[k, l] = 1.0
            X = np.swapaxes(Rs, -1, -2) @ E
            S = 0.5 * (X - np.swapaxes(X, -1, -2))
            w = np.stack([S[:, 2, 1], S[:, 0, 2], S[:, 1, 0]], -1)
            np.testing.assert_allclose(J[:, :, :, k, l], Rs @ _hat(w), rtol=0, atol=1e-12)


@over_dtypes
def test_conversion_far_from_the_rotations_is_a_rotation(dtype):
    """Matrices far from any rotation (Gaussian, scaled by 1e-3 to 1e3) give unit
    quaternions (within 4 ulp), finite."""
    rng = np.random.default_rng(27)
    M = rng.normal(size=(1000, 3, 3)) * np.exp(rng.uniform(-7, 7, (1000, 1, 1)))
    q = to_np(jl.SO3.from_matrix(jnp.asarray(M, dtype)).wxyz).astype(np.float64)
    assert np.all(np.isfinite(q))
    np.testing.assert_allclose(
        np.linalg.norm(q, axis=-1), 1.0, rtol=0, atol=4 * np.finfo(dtype).eps
    )


@over_dtypes
def test_conversion_of_a_similarity_over_the_whole_scale_range(dtype):
    """Sim3's scale from ‖M‖_F/√3 holds over the dtype's range: log-scales ±80 (float32
    scales from 2e-35 to 6e34) come back within 4 ulp of 80, the rotation within 8 ulp, from
    the matrix of the element."""
    eps = float(jnp.finfo(dtype).eps)
    for sigma in (-80.0, -40.0, 40.0, 80.0):
        T = jl.Sim3.exp(jnp.asarray([0.1, 0.2, 0.3, 0.4, 0.5, 0.6, sigma], dtype))
        U = jl.Sim3.from_matrix(T.as_matrix())
        assert abs(float(U.log_scale()) - sigma) <= 4 * eps * 80, (sigma, U.log_scale())
        err = np.abs(to_np(U.rotation().as_matrix()) - to_np(T.rotation().as_matrix())).max()
        assert err <= 8 * eps, (sigma, err)


@pytest.mark.parametrize("project", [False, True], ids=["convert", "project"])
def test_non_finite_matrices_give_nan(project):
    """A NaN or inf entry gives a NaN quaternion with either setting, never a silent
    rotation."""
    for bad in (np.nan, np.inf):
        M = np.eye(3)
        M[1, 2] = bad
        assert np.all(np.isnan(to_np(jl.SO3.from_matrix(M, project=project).wxyz))), bad
