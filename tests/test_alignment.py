"""Closed-form alignment of point sets (``_alignment.umeyama``, ``Sim3.align``,
``SE3.align``) and ``examples/trajectory_alignment.py``.

References: ``evo``'s independent NumPy implementation of the same paper
(``evo.core.geometry.umeyama_alignment``, 1/n moments, one problem per call), similarities
drawn with ``scipy.spatial.transform.Rotation`` (not the library) for exact recovery, and
the objective itself for the degenerate inputs.

Compilation is most of this file's time: the problems are stacked into a few batch shapes
(batch indices are independent problems, which ``test_batched_problems_equal_the_single_
problems`` checks), sizes other than the batch's are padded with points of zero weight
(ignored exactly, ``test_zero_weights_ignore_points``), and dtypes are checked by tracing
(``jax.eval_shape``) where the values are checked elsewhere.
"""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from evo.core.geometry import umeyama_alignment
from scipy.spatial.transform import Rotation

from jaxlie_geo import SE3, Sim3
from jaxlie_geo._alignment import umeyama

REPO = Path(__file__).resolve().parents[1]
B, N = 64, 64  # the shape of the random problems: 64 problems of 64 points


def _similarity(rng: np.random.Generator, batch: tuple) -> tuple:
    """Random (R, t, s) in float64: Haar rotations, t uniform in [−2, 2]³, s in [e⁻¹, e]."""
    n = int(np.prod(batch))
    R = Rotation.random(n, random_state=rng).as_matrix().reshape(*batch, 3, 3)
    t = rng.uniform(-2.0, 2.0, (*batch, 3))
    s = np.exp(rng.uniform(-1.0, 1.0, batch))
    return R, t, s


def _apply(R, t, s, x):
    """s R x + t for x ``(*batch, n, 3)``, in float64."""
    R, t, s, x = (np.asarray(a, np.float64) for a in (R, t, s, x))
    return s[..., None, None] * np.einsum("...ij,...nj->...ni", R, x) + t[..., None, :]


def _objective(R, t, s, x, y):
    r = np.asarray(y, np.float64) - _apply(R, t, s, x)
    return np.sum(r * r, axis=(-2, -1))


def _assert_rotation(R, atol=1e-12):
    R = np.asarray(R, np.float64)
    assert np.all(np.isfinite(R))
    eye = np.broadcast_to(np.eye(3), R.shape)
    np.testing.assert_allclose(np.swapaxes(R, -1, -2) @ R, eye, rtol=0, atol=atol)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, rtol=0, atol=atol)


def _pad(x, n):
    """``(n_x, 3)`` points padded with zeros to ``(n, 3)``; weights 1 then 0."""
    out = np.zeros((n, 3))
    out[: len(x)] = x
    return out, (np.arange(n) < len(x)).astype(np.float64)


# ---------------------------------------------------------------------------------------
# (a) Agreement with evo.


@pytest.mark.parametrize("with_scale", [True, False])
def test_agrees_with_evo(with_scale):
    """64 random, unrelated source and target sets (about half the covariances have
    det < 0 and need the reflection correction, eq. 43), with various spreads and offsets:
    R, t, s within 1e-10 of evo's, in float64 (measured: 7e-14 at worst)."""
    rng = np.random.default_rng(0)
    x = rng.normal(size=(B, N, 3)) * rng.uniform(0.1, 10.0, (B, 1, 1)) + rng.normal(size=(B, 1, 3))
    y = rng.normal(size=(B, N, 3)) * 3.0 + rng.normal(size=(B, 1, 3)) * 10.0
    R, t, s = umeyama(x, y, with_scale=with_scale)
    assert R.dtype == t.dtype == s.dtype == jnp.float64
    dets = []
    for b in range(B):
        r_e, t_e, c_e = umeyama_alignment(x[b].T, y[b].T, with_scale)
        np.testing.assert_allclose(R[b], r_e, rtol=0, atol=1e-10)
        np.testing.assert_allclose(t[b], t_e, rtol=0, atol=1e-10)
        np.testing.assert_allclose(s[b], c_e, rtol=0, atol=1e-10)
        a, c = x[b] - x[b].mean(0), y[b] - y[b].mean(0)
        dets.append(np.linalg.det(c.T @ a))
    assert min(dets) < 0 < max(dets)  # both branches of S = diag(1, 1, ±1)
    _assert_rotation(R)


def test_agrees_with_evo_at_other_sizes_and_integer_weights():
    """Sizes 3, 4, 10 and 40 (padded to N with zero weights), and integer weights: weight k
    on a point is the same problem as the point repeated k times (k = 0: left out), which
    evo solves with uniform weights."""
    rng = np.random.default_rng(1)
    problems = []  # (x, y, k): points and integer weights
    for n in (3, 4, 10, 40):
        for _ in range(4):
            problems.append((rng.normal(size=(n, 3)), rng.normal(size=(n, 3)), np.ones(n, int)))
    for _ in range(4):
        k = rng.integers(0, 4, 12)
        problems.append((rng.normal(size=(12, 3)), 2.0 * rng.normal(size=(12, 3)) + 1.0, k))
    xs, ys, ws = [], [], []
    for x, y, k in problems:
        xp, w = _pad(x, N)
        w[: len(k)] = k
        xs.append(xp), ys.append(_pad(y, N)[0]), ws.append(w)
    R, t, s = umeyama(np.stack(xs), np.stack(ys), np.stack(ws))
    for i, (x, y, k) in enumerate(problems):
        r_e, t_e, c_e = umeyama_alignment(np.repeat(x, k, 0).T, np.repeat(y, k, 0).T, True)
        np.testing.assert_allclose(R[i], r_e, rtol=0, atol=1e-10)
        np.testing.assert_allclose(t[i], t_e, rtol=0, atol=1e-10)
        np.testing.assert_allclose(s[i], c_e, rtol=0, atol=1e-10)


# ---------------------------------------------------------------------------------------
# (b) Exact recovery from noiseless data.


def _noiseless(seed: int, rigid: bool = False):
    rng = np.random.default_rng(seed)
    R0, t0, s0 = _similarity(rng, (B,))
    if rigid:
        s0 = np.ones(B)
    x = rng.uniform(-1.0, 1.0, (B, N, 3))
    return x, _apply(R0, t0, s0, x), (R0, t0, s0)


@pytest.mark.parametrize("dtype", [jnp.float32, jnp.float64])
def test_recovers_a_known_similarity(dtype):
    """Noiseless points of 64 random similarities, rounded to ``dtype``: R, s and t within
    16 ulp (the rotation is the projection ``SO3.from_matrix(·, project=True)`` of the
    covariance), the dtype preserved."""
    eps = float(jnp.finfo(dtype).eps)
    x, y, (R0, t0, s0) = _noiseless(2)
    R, t, s = umeyama(jnp.asarray(x, dtype), jnp.asarray(y, dtype))
    assert R.dtype == t.dtype == s.dtype == dtype
    assert R.shape == (B, 3, 3) and t.shape == (B, 3) and s.shape == (B,)
    np.testing.assert_allclose(R, R0, rtol=0, atol=16 * eps)
    np.testing.assert_allclose(s, s0, rtol=16 * eps, atol=0)
    np.testing.assert_allclose(t, t0, rtol=0, atol=16 * eps * 2.0)  # |t| ≤ 2√3


def test_sim3_align_recovers_a_known_similarity():
    """``Sim3.align`` (float32; float64 traced for its dtype): the element of the data,
    within the tolerances of ``umeyama``. A problem whose target has no spread gets the
    least-squares scale 0, a log-scale of −inf, and maps every point onto the target."""
    eps = float(jnp.finfo(jnp.float32).eps)
    x, y, (R0, t0, s0) = _noiseless(3)
    y[0] = [1.0, -2.0, 0.5]  # problem 0: all target points equal
    T = Sim3.align(jnp.asarray(x, jnp.float32), jnp.asarray(y, jnp.float32))
    assert isinstance(T, Sim3) and T.parameters().dtype == jnp.float32
    np.testing.assert_allclose(T.rotation().as_matrix()[1:], R0[1:], rtol=0, atol=100 * eps)
    np.testing.assert_allclose(T.log_scale()[1:], np.log(s0[1:]), rtol=0, atol=16 * eps)
    np.testing.assert_allclose(T.translation()[1:], t0[1:], rtol=0, atol=16 * eps * 2.0)
    assert T.log_scale()[0] == -np.inf
    np.testing.assert_allclose(T[0] @ jnp.asarray(x[0], jnp.float32), y[0], rtol=0, atol=1e-6)
    shape = jax.eval_shape(Sim3.align, jnp.asarray(x), jnp.asarray(y))  # float64 stays
    assert shape.parameters().dtype == jnp.float64


def test_se3_align_recovers_a_known_rigid_transform():
    """``SE3.align`` (float32; float64 traced for its dtype)."""
    eps = float(jnp.finfo(jnp.float32).eps)
    x, y, (R0, t0, _) = _noiseless(4, rigid=True)
    P = SE3.align(jnp.asarray(x, jnp.float32), jnp.asarray(y, jnp.float32))
    assert isinstance(P, SE3) and P.parameters().dtype == jnp.float32
    np.testing.assert_allclose(P.rotation().as_matrix(), R0, rtol=0, atol=100 * eps)
    np.testing.assert_allclose(P.translation(), t0, rtol=0, atol=16 * eps * 2.0)
    shape = jax.eval_shape(SE3.align, jnp.asarray(x), jnp.asarray(y))
    assert shape.parameters().dtype == jnp.float64


def test_far_from_the_origin_costs_no_accuracy():
    """The same problems 2·10⁵ units from the origin (map coordinates), in float32: the
    moments are taken relative to a data point, so only the rounding of the shifted inputs
    (ulp(2e5) = 0.016) is left, not a cancellation of the shift."""
    x, y, _ = _noiseless(5)
    shift = np.array([1e5, -2e5, 3e4])
    xd = jnp.asarray(x + shift, jnp.float32)
    yd = jnp.asarray(y + shift, jnp.float32)
    R, _, s = umeyama(xd, yd)
    # The reference: the float32-rounded inputs, shifted back exactly in float64.
    R_ref, _, s_ref = umeyama(
        np.asarray(xd, np.float64) - shift, np.asarray(yd, np.float64) - shift
    )
    np.testing.assert_allclose(R, R_ref, rtol=0, atol=1e-5)
    np.testing.assert_allclose(s, s_ref, rtol=1e-5, atol=0)


# ---------------------------------------------------------------------------------------
# (c) Batching and broadcasting.


def test_batched_problems_equal_the_single_problems():
    rng = np.random.default_rng(5)
    x, y = rng.normal(size=(2, 3, 7, 3)), rng.normal(size=(2, 3, 7, 3)) + 1.0
    w = rng.uniform(0.5, 2.0, (2, 3, 7))
    R, t, s = umeyama(x, y, w)
    assert R.shape == (2, 3, 3, 3) and t.shape == (2, 3, 3) and s.shape == (2, 3)
    for i in range(2):
        for j in range(3):
            Ri, ti, si = umeyama(x[i, j], y[i, j], w[i, j])
            np.testing.assert_allclose(R[i, j], Ri, rtol=0, atol=1e-13)
            np.testing.assert_allclose(t[i, j], ti, rtol=0, atol=1e-13)
            np.testing.assert_allclose(s[i, j], si, rtol=0, atol=1e-13)


def test_batch_axes_broadcast_without_rank_promotion():
    """One source and one set of weights against three targets, under
    ``jax_numpy_rank_promotion="raise"``: each result is that target's problem."""
    rng = np.random.default_rng(6)
    x, y, w = rng.normal(size=(7, 3)), rng.normal(size=(3, 7, 3)), rng.uniform(0, 1, 7)
    with jax.numpy_rank_promotion("raise"):
        R, t, s = umeyama(x, y, w)
    assert R.shape == (3, 3, 3) and t.shape == (3, 3) and s.shape == (3,)
    for j in range(3):
        Rj, tj, sj = umeyama(x, y[j], w)
        np.testing.assert_allclose(R[j], Rj, rtol=0, atol=1e-13)
        np.testing.assert_allclose(t[j], tj, rtol=0, atol=1e-13)
        np.testing.assert_allclose(s[j], sj, rtol=0, atol=1e-13)


# ---------------------------------------------------------------------------------------
# (d) Weights.


def test_zero_weights_ignore_points():
    """Points of zero weight, even with inf or NaN coordinates, change nothing: the result
    is that of the remaining points; a common factor on the weights changes nothing."""
    rng = np.random.default_rng(7)
    x, y = rng.normal(size=(7, 3)), rng.normal(size=(7, 3)) * 0.5 + 2.0
    w = rng.uniform(0.5, 2.0, 7)
    w[[0, 3, 6]] = 0.0
    x[3], y[6], x[0, 1] = np.nan, np.inf, -np.inf
    keep = w > 0
    R, t, s = umeyama(x, y, w)
    Rk, tk, sk = umeyama(x[keep], y[keep], w[keep])
    for a, b in ((R, Rk), (t, tk), (s, sk)):
        assert np.all(np.isfinite(a))
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-13)
    R3, t3, s3 = umeyama(x, y, 3.0 * w)
    np.testing.assert_allclose(R3, R, rtol=0, atol=1e-13)
    np.testing.assert_allclose(t3, t, rtol=0, atol=1e-13)
    np.testing.assert_allclose(s3, s, rtol=0, atol=1e-13)


# ---------------------------------------------------------------------------------------
# (e) jit, dtypes and the degenerate inputs.


def test_inside_jit_and_dtypes():
    """Under a user's ``jax.jit`` the result is the eager one; integer points become the
    default float type, integer weights take the points' dtype, float32 stays float32."""
    rng = np.random.default_rng(8)
    x = rng.integers(-5, 5, (6, 3))
    y = 2 * x + 1
    R, t, s = jax.jit(lambda a, b: umeyama(a, b))(x, y)
    assert R.dtype == jnp.float64  # the default float type with x64 on
    np.testing.assert_allclose(R, np.eye(3), rtol=0, atol=1e-14)
    np.testing.assert_allclose(t, np.ones(3), rtol=0, atol=1e-13)
    np.testing.assert_allclose(s, 2.0, rtol=1e-14)
    f32 = jax.ShapeDtypeStruct((6, 3), jnp.float32)
    for args in ((f32, f32), (f32, f32, jax.ShapeDtypeStruct((6,), jnp.int32))):
        for out in jax.eval_shape(umeyama, *args):
            assert out.dtype == jnp.float32
    assert jax.eval_shape(Sim3.align, f32, f32).parameters().dtype == jnp.float32


def _degenerate_batch():
    """Degenerate problems of 5 points (fewer, padded with zero weights), one per row:
    name → (source, target, weights)."""
    rng = np.random.default_rng(9)
    R0, t0, s0 = (a[0] for a in _similarity(rng, (1,)))
    y = rng.normal(size=(5, 3))
    line = np.outer(np.linspace(-1.0, 2.0, 5), [0.3, -1.0, 0.7]) + [1.0, 2.0, 3.0]
    mirror = rng.normal(size=(5, 3)) * [3.0, 2.0, 1.0]
    nan_points = rng.normal(size=(5, 3))
    nan_points[0] = np.nan
    one = np.ones(5)
    # 0.1 summed with weights 1/5 is not exact: the spread must still come out 0.
    same = np.tile([[0.1, 0.2, 0.3]], (5, 1))
    return {
        "coincident source": (same, y, one),
        "coincident target": (y, np.tile([[1.0, -2.0, 0.5]], (5, 1)), one),
        "zero weights": (nan_points, y, np.zeros(5)),
        "collinear": (line, _apply(R0, t0, s0, line), one),
        "collinear rigid": (line, _apply(R0, t0, 1.0, line), one),
        "mirror image": (mirror, mirror * [1.0, 1.0, -1.0], one),
        "one point": (y, y[::-1] + 1.0, np.eye(5)[2]),
    }, (R0, t0, s0)


@pytest.mark.parametrize("with_scale", [True, False])
def test_degenerate_inputs_give_the_documented_results(with_scale):
    """All finite, R a rotation, and the documented minimiser:

    * coincident source points: R = I, s = 1, t = μ_y − μ_x;
    * coincident target points: R = I, s = 0 (rigid: s = 1), t = μ_y − s μ_x;
    * zero total weight (a NaN point among them): the identity;
    * collinear: R is one of the rotations that fit the line (noiseless data: objective 0),
      s the true scale;
    * a mirror image: the best rotation, no rotation of a dense search does better;
    * a single point (the others of zero weight): R = I, s = 1, t = y − x."""
    problems, (R0, t0, s0) = _degenerate_batch()
    names = list(problems)
    x, y, w = (np.stack([problems[n][i] for n in names]) for i in range(3))
    R, t, s = (np.asarray(a) for a in umeyama(x, y, w, with_scale=with_scale))
    for a in (R, t, s):
        assert np.all(np.isfinite(a))
    _assert_rotation(R)
    got = {n: (R[i], t[i], s[i]) for i, n in enumerate(names)}
    eye = np.eye(3)

    Ri, ti, si = got["coincident source"]
    xi, yi = problems["coincident source"][:2]
    np.testing.assert_array_equal(Ri, eye)
    assert si == 1.0
    np.testing.assert_allclose(ti, yi.mean(0) - xi[0], rtol=0, atol=1e-15)

    Ri, ti, si = got["coincident target"]
    xi, yi = problems["coincident target"][:2]
    np.testing.assert_array_equal(Ri, eye)
    assert si == (0.0 if with_scale else 1.0)
    np.testing.assert_allclose(ti, yi[0] - si * xi.mean(0), rtol=0, atol=1e-15)

    Ri, ti, si = got["zero weights"]
    np.testing.assert_array_equal(Ri, eye)
    np.testing.assert_array_equal(ti, np.zeros(3))
    assert si == 1.0

    for name in ("collinear", "collinear rigid") if with_scale else ("collinear rigid",):
        xi, yi = problems[name][:2]
        assert _objective(*got[name], xi, yi) < 1e-24
    if with_scale:
        np.testing.assert_allclose(got["collinear"][2], s0, rtol=1e-13)

    xi, yi = problems["mirror image"][:2]
    best = _objective(*got["mirror image"], xi, yi)
    Rs = Rotation.random(20000, random_state=np.random.default_rng(10)).as_matrix()
    a, b = xi - xi.mean(0), yi - yi.mean(0)  # best t (and s) of each trial rotation
    tr = np.einsum("kij,nj,ni->k", Rs, a, b)
    s_k = np.maximum(tr, 0) / np.sum(a * a) if with_scale else np.ones_like(tr)
    others = np.sum(b * b) - 2 * s_k * tr + s_k**2 * np.sum(a * a)
    assert best <= others.min() + 1e-12

    Ri, ti, si = got["one point"]
    np.testing.assert_array_equal(Ri, eye)
    assert si == 1.0
    xi, yi = problems["one point"][:2]
    np.testing.assert_allclose(ti, yi[2] - xi[2], rtol=0, atol=1e-15)


@pytest.mark.parametrize("n", [0, 1, 2])
def test_fewer_than_three_points(n):
    """N = 0: the identity; N = 1: R = I, s = 1, t = y − x; N = 2 (collinear): a rotation
    that maps the segment onto the target's, the true scale."""
    rng = np.random.default_rng(11)
    R0, t0, s0 = (a[0] for a in _similarity(rng, (1,)))
    x = rng.normal(size=(n, 3))
    y = _apply(R0, t0, s0, x)
    R, t, s = (np.asarray(a) for a in umeyama(x, y))
    _assert_rotation(R)
    assert np.all(np.isfinite(t)) and np.isfinite(s)
    if n < 2:
        np.testing.assert_array_equal(R, np.eye(3))
        assert s == 1.0
        np.testing.assert_allclose(t, (y - x)[0] if n else np.zeros(3), rtol=0, atol=1e-15)
    else:
        np.testing.assert_allclose(s, s0, rtol=1e-13)
        assert _objective(R, t, s, x, y) < 1e-24


def test_coplanar_points_determine_the_rotation():
    """Three points (a plane: rank Σ_xy = 2): R is unique and recovered whichever sign
    det U det V takes (eq. 43)."""
    rng = np.random.default_rng(12)
    R0, t0, s0 = _similarity(rng, (16,))
    x = rng.normal(size=(16, 3, 3))
    R, t, s = umeyama(x, _apply(R0, t0, s0, x))
    np.testing.assert_allclose(R, R0, rtol=0, atol=1e-11)
    np.testing.assert_allclose(s, s0, rtol=1e-12)
    np.testing.assert_allclose(t, t0, rtol=0, atol=1e-11)


def test_derivatives_match_finite_differences():
    """``jax.grad`` of a function of (R, t, s) against central differences, in float64, for
    generic weighted data and for noiseless data on a cube's corners, whose covariance
    has three equal singular values (the SVD's factors have no derivative there, the
    minimiser has)."""
    rng = np.random.default_rng(14)
    R0, t0, s0 = _similarity(rng, (2,))
    cube = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], float)
    x = np.stack([rng.normal(size=(8, 3)), cube])
    y = _apply(R0, t0, s0, x) + np.stack([0.1 * rng.normal(size=(8, 3)), np.zeros((8, 3))])
    w = np.stack([rng.uniform(0.5, 2.0, 8), np.ones(8)])
    c = rng.normal(size=13)

    @jax.jit
    def f(x, y, w):
        R, t, s = umeyama(x, y, w)
        return jnp.sum(R.reshape(2, 9) @ c[:9] + t @ c[9:12] + c[12] * s)

    grads = jax.jit(jax.grad(f, argnums=(0, 1, 2)))(x, y, w)
    for g in grads:
        assert np.all(np.isfinite(g))
    h = 1e-6
    for _ in range(3):
        d = [rng.normal(size=a.shape) for a in (x, y, w)]
        fd = (
            f(*(a + h * da for a, da in zip((x, y, w), d)))
            - f(*(a - h * da for a, da in zip((x, y, w), d)))
        ) / (2 * h)
        ad = sum(np.sum(g * da) for g, da in zip(grads, d))
        np.testing.assert_allclose(ad, fd, rtol=1e-7, atol=1e-8)


# ---------------------------------------------------------------------------------------
# (f) Shape errors at trace time.

S = jax.ShapeDtypeStruct
F = "float32"


@pytest.mark.parametrize(
    "args, message",
    [
        (
            (S((5, 2), F), S((5, 3), F)),
            r"`source` must have shape \(\*batch, N, 3\), got shape \(5, 2\)",
        ),
        (
            (S((3,), F), S((5, 3), F)),
            r"`source` must have shape \(\*batch, N, 3\), got shape \(3,\)",
        ),
        (
            (S((5, 3), F), S((5, 4), F)),
            r"`target` must have shape \(\*batch, N, 3\), got shape \(5, 4\)",
        ),
        (
            (S((5, 3), F), S((6, 3), F)),
            r"`source` and `target` must hold the same number N of points, got shapes "
            r"\(5, 3\) and \(6, 3\)",
        ),
        (
            (S((5, 3), F), S((5, 3), F), S((4,), F)),
            r"`weights` must have shape \(\*batch, N\) with N = 5 .* got shape \(4,\)",
        ),
        ((S((5, 3), F), S((5, 3), F), S((), F)), r"`weights` must have shape .* got shape \(\)"),
        (
            (S((2, 5, 3), F), S((3, 5, 3), F)),
            r"batch axes of source, target and weights \(2,\) and \(3,\) and \(\) do not broadcast",
        ),
        ((S((5, 3), "complex64"), S((5, 3), F)), r"`source` must be real"),
    ],
)
def test_shape_errors_at_trace_time(args, message):
    with pytest.raises(ValueError, match="umeyama: " + message):
        jax.eval_shape(umeyama, *args)


@pytest.mark.parametrize("G", [Sim3, SE3])
def test_align_errors_name_the_method(G):
    with pytest.raises(ValueError, match=rf"{G.__name__}\.align: `target` must have shape"):
        G.align(np.zeros((4, 3)), np.zeros((4, 2)))
    with pytest.raises(ValueError, match=rf"{G.__name__}\.align: `weights` must have shape"):
        G.align(np.zeros((4, 3)), np.zeros((4, 3)), np.ones(3))


# ---------------------------------------------------------------------------------------
# The example.


def test_example_quick(tmp_path, capsys):
    """``examples/trajectory_alignment.py --quick``, in process: the absolute trajectory
    error falls from the raw estimate to the SE3 alignment, and by far more to the Sim3
    alignment (only the drift is left); the picture is written."""
    spec = importlib.util.spec_from_file_location(
        "trajectory_alignment", REPO / "examples" / "trajectory_alignment.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    png = tmp_path / "pictures" / "alignment.png"  # parent does not exist yet
    ate = module.main(["--quick", "--out", str(png)])
    out = capsys.readouterr().out
    for label in ("before alignment", "after SE3 alignment", "after Sim3 alignment"):
        match = re.search(rf"ATE {label}\s+([\d.]+) m", out)
        assert match, out
        assert float(match.group(1)) == pytest.approx(ate[label], abs=6e-4)
    assert ate["before alignment"] > ate["after SE3 alignment"] > 5 * ate["after Sim3 alignment"]
    data = png.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 20_000
