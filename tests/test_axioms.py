"""The group axioms and the definitions of each operation, on every group × dtype, from one
evaluation of the operations per group and dtype on the shared regime batch
(``tests/_programs.py``).

References are independent of the library: the group laws themselves, the matrix
representation (numpy products, inverses and determinants), the generators written out in
conftest (``hat_ref``, ``vee_ref``), ``scipy.linalg.expm``, automatic differentiation of the
library's own composition (jaxlie's definition of ``jlog``) and, for ``sample_uniform``, the
Haar measure's known distributions (Kolmogorov–Smirnov tests).

The batch spans every angle regime (``_programs.regime_batch``); each property is also
checked on one unbatched element against the batched result, and every property runs again
on random batches of the same shape, one per seed of ``conftest.SEEDS`` (the same compiled
program).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg
from _programs import BATCH, Checks, regime_batch, results, run
from conftest import (
    LAYOUT,
    SE_GROUPS,
    assert_close,
    assert_rel_norm,
    expm_ref,
    has_scale,
    hat_ref,
    homogeneous_apply,
    identity_matrices,
    over_groups_dtypes,
    over_seeds,
    random_element,
    random_tangent,
    rotation_angle,
    rotation_params,
    to_np,
    vee_ref,
)

from jaxlie_geo import SO2, SO3


def _any_scales(dtype) -> np.ndarray:
    """Rotation-part scales for normalize: just above the smallest normal float to half the
    largest."""
    fi = np.finfo(dtype)
    return np.array([float(fi.tiny) * 2**10, 1e-30, 0.5**60, 2.0**60, 1e30, float(fi.max) / 2])


def _prepare(G, dtype, seed):
    d = regime_batch(G, dtype, seed)
    rng = np.random.default_rng(seed)
    n, k = G.space_dim, rotation_params(G)
    # from_matrix of an independent matrix: scipy's expm rounded to the dtype.
    d["x_pi"] = random_tangent(G, seed + 3, BATCH, dtype, max_angle=np.pi)
    d["M_ref"] = expm_ref(G, d["x_pi"]).astype(dtype)
    # vee of hat plus a symmetric part (traceless for Sim(3), whose σI is symmetric).
    A = rng.normal(size=(*BATCH, n, n))
    S = np.zeros((*BATCH, G.matrix_dim, G.matrix_dim))
    S[..., :n, :n] = A + np.swapaxes(A, -1, -2)
    if has_scale(G):
        S[..., :n, :n] -= (
            np.trace(S[..., :n, :n], axis1=-2, axis2=-1)[..., None, None] / n * np.eye(n)
        )
    d["X_sym"] = (hat_ref(G, d["y"]) + S).astype(dtype)
    d["hat_ref_x10"] = hat_ref(G, d["x10"]).astype(dtype)
    # normalize: rotation parts scaled by 0.5 … 2, and by the extreme scales.
    # A fixed draw (whatever the seed): at the smallest scales a small component of another
    # draw is subnormal in float32, which XLA on CPU flushes to zero.
    p7 = np.asarray(random_element(G, 7, BATCH, dtype).parameters())
    d["scale"] = rng.uniform(0.5, 2.0, size=BATCH).astype(dtype)
    flat = p7.reshape(-1, G.parameters_dim)[:5]
    scales = _any_scales(dtype)
    any_scale = np.repeat(flat[None], len(scales), axis=0)
    any_scale[..., :k] = (any_scale[..., :k].astype(np.float64) * scales[:, None, None]).astype(
        dtype
    )
    d["any_scale"] = any_scale
    exact = flat.copy()
    exact[..., :k] *= np.dtype(dtype).type(2.0**40)
    d["pow2"] = exact
    d["P0"] = flat
    bad = np.repeat(flat[:1], 3, axis=0)
    bad[0, :k] = 0.0
    bad[1, 0] = np.inf
    bad[2, 0] = np.nan
    d["bad"] = bad
    return d


@jax.jit
def _jlog_by_autodiff(T):
    """jaxlie's definition of jlog: d log(T @ exp(δ)) / dδ at δ = 0 (reverse mode, per
    element)."""
    G = type(T)

    def one(params):
        Ti = G(params)
        zero = jnp.zeros(G.tangent_dim, params.dtype)
        return jax.jacrev(lambda e: (Ti @ G.exp(e)).log())(zero)

    flat = T.parameters().reshape(-1, G.parameters_dim)
    return jax.vmap(one)(flat).reshape(*T.get_batch_axes(), G.tangent_dim, G.tangent_dim)


@jax.jit
def _normalize_gradients(P):
    """The gradient of the first normalized parameter at P's parameters and at 2⁻⁷⁰ times
    them (rescaled), which must agree."""
    G = type(P)
    q = P.parameters()

    def first(q):
        return G(q).normalize().parameters()[0, 0]

    tiny = jnp.asarray(2.0**-70, q.dtype)
    return jax.grad(first)(q), jax.grad(first)(q * tiny)


def _program(G, d):
    T, U, V, x, y, x10, p = (d[k] for k in ("T", "U", "V", "x", "y", "x10", "p"))
    dtype = x.dtype
    k = rotation_params(G)
    I_b = G.identity(BATCH, dtype=dtype)
    I_1 = G.identity(dtype=dtype)
    Tinv = T.inverse()
    Ad = T.adjoint()
    Ady = jnp.einsum("...ij,...j->...i", Ad, y)
    scaled = T.parameters().at[..., :k].multiply(d["scale"][..., None])
    Ns = G(scaled).normalize()
    Tx = G.exp(x)
    P0 = d["P0"]
    grad, grad_tiny = _normalize_gradients(G(P0))

    out = {
        # identity
        "I": I_b.as_matrix(),
        "I_log": I_b.log(),
        "I_inv": I_b.inverse().as_matrix(),
        "exp0": G.exp(jnp.zeros_like(x)).as_matrix(),
        "TI": (T @ I_b).as_matrix(),
        "IT": (I_b @ T).as_matrix(),
        "TI1": (T @ I_1).as_matrix(),
        "I1T": (I_1 @ T).as_matrix(),
        # inverse, associativity
        "T": T.as_matrix(),
        "T_Tinv": (T @ Tinv).as_matrix(),
        "Tinv_T": (Tinv @ T).as_matrix(),
        "Tinvinv": Tinv.inverse().as_matrix(),
        "Tinv": Tinv.as_matrix(),
        "assoc_l": ((T @ U) @ V).as_matrix(),
        "assoc_r": (T @ (U @ V)).as_matrix(),
        # exp and log
        "exp_x": Tx.as_matrix(),
        "log_exp_x": Tx.log(),
        "exp_log_exp_x": G.exp(Tx.log()).as_matrix(),
        "log_T": T.log(),
        "exp_log_T": G.exp(T.log()).as_matrix(),
        "exp_y": G.exp(y).as_matrix(),
        "exp_x10": G.exp(x10).as_matrix(),
        "hat_y": G.hat(y),
        "hat_x10": G.hat(x10),
        # matrices, hat and vee
        "from_matrix_T": G.from_matrix(T.as_matrix()).as_matrix(),
        "from_matrix_ref": G.from_matrix(d["M_ref"]).as_matrix(),
        "vee_hat_x10": G.vee(G.hat(x10)),
        "vee_hat_ref_x10": G.vee(d["hat_ref_x10"]),
        "vee_sym": G.vee(d["X_sym"]),
        # adjoint
        "Ad": Ad,
        "T_exp_y": (T @ G.exp(y)).as_matrix(),
        "exp_Ady_T": (G.exp(Ady) @ T).as_matrix(),
        "Ady": Ady,
        # actions and products
        "apply": T.apply(p),
        "matmul_p": T @ p,
        "apply_one_point": T.apply(p[0, 0]),
        "multiply": T.multiply(U).as_matrix(),
        "matmul_TU": (T @ U).as_matrix(),
        "U": U.as_matrix(),
        # normalize
        "T_params": T.parameters(),
        "normalize_T": T.normalize().parameters(),
        "normalize_scaled": Ns.parameters(),
        "normalize_twice": Ns.normalize().parameters(),
        "normalize_any_scale": G(d["any_scale"]).normalize().parameters(),
        "normalize_pow2": G(d["pow2"]).normalize().parameters(),
        "normalize_P0": G(P0).normalize().parameters(),
        "normalize_bad": G(d["bad"]).normalize().parameters(),
        "normalize_grad_tiny": grad_tiny,
        "normalize_grad": grad,
        # jlog
        "jlog_T": T.jlog(),
        "jlog_T_ad": _jlog_by_autodiff(T),
        "jlog_x": Tx.jlog(),
        "jlog_x_ad": _jlog_by_autodiff(Tx),
    }
    # Validity of what the operations make (a rotation part scaled by 1e3, normalized).
    big = G(T.parameters().at[..., :k].multiply(jnp.asarray(1e3, dtype))).normalize()
    made = {
        "T": T,
        "exp_y": G.exp(y),
        "product": T @ G.exp(y),
        "inverse": Tinv,
        "exp_log_T": G.exp(T.log()),
        "identity": I_b,
        "normalized": big,
    }
    out["valid"] = {name: E.is_valid() for name, E in made.items()}
    # One unbatched element through the same operations: equal to the batched result.
    T0, U0, x0, y0, p0 = T[0, 0], U[0, 0], x[0, 0], y[0, 0], p[0, 0]
    out["one"] = {
        "exp_x": G.exp(x0).as_matrix(),
        "log_exp_x": G.exp(x0).log(),
        "log_T": T0.log(),
        "T_Tinv": (T0 @ T0.inverse()).as_matrix(),
        "Tinv": T0.inverse().as_matrix(),
        "multiply": (T0 @ U0).as_matrix(),
        "apply": T0 @ p0,
        "Ad": T0.adjoint(),
        "jlog_T": T0.jlog(),
        "hat_y": G.hat(y0),
        "from_matrix_T": G.from_matrix(T0.as_matrix()).as_matrix(),
        "normalize_T": T0.normalize().parameters(),
        "TI": (T0 @ I_1).as_matrix(),
    }
    return out


def _angle_ok(G, x, limit=3.05):
    return rotation_angle(G, x) < limit


checks = Checks()


@checks.add
def identity_laws(G, dtype, d, o):
    """T I = I T = T for a batched and an unbatched identity; the identity is exactly the
    identity matrix, its log and inverse exactly zero and the identity, exp(0) exactly I."""
    eye = identity_matrices(G, BATCH)
    assert o["I"].dtype == dtype
    np.testing.assert_array_equal(o["I"], eye)
    for name in ("TI", "IT", "TI1", "I1T"):
        assert_close(o[name], o["T"], dtype, msg=name)
    np.testing.assert_array_equal(o["I_log"], np.zeros((*BATCH, G.tangent_dim)))
    np.testing.assert_array_equal(o["exp0"], eye)
    np.testing.assert_array_equal(o["I_inv"], eye)


@checks.add
def inverse_laws(G, dtype, d, o):
    """T T⁻¹ = T⁻¹ T = I and (T⁻¹)⁻¹ = T, as matrices; T⁻¹ is numpy's inverse."""
    eye = identity_matrices(G, BATCH)
    assert_close(o["T_Tinv"], eye, dtype, 2)
    assert_close(o["Tinv_T"], eye, dtype, 2)
    assert_close(o["Tinvinv"], o["T"], dtype, 2)
    assert_close(o["Tinv"], np.linalg.inv(to_np(o["T"])), dtype, 4)


@checks.add
def associativity(G, dtype, d, o):
    """(T U) V = T (U V), as matrices."""
    assert_close(o["assoc_l"], o["assoc_r"], dtype, 4)


@checks.add
def log_of_exp(G, dtype, d, o):
    """log(exp(x)) == x for |rotation angle| < π (every regime of the batch below 3.05); the
    rotation part to a relative error of 16 ulp (no absolute floor: small angles must not
    lose digits). At and near π, exp(log(exp x)) == exp x and log is finite."""
    x, y = to_np(d["x"]), o["log_exp_x"]
    assert y.dtype == dtype and y.shape == x.shape
    ok = _angle_ok(G, x)
    assert_close(y[ok], x[ok], dtype, 4)
    rot = LAYOUT[G][0]
    assert_rel_norm(y[ok][:, rot], x[ok][:, rot], dtype, ulps=16)
    assert np.all(np.isfinite(y))
    assert_close(o["exp_log_exp_x"], o["exp_x"], dtype, 8)
    assert np.all(rotation_angle(G, y) <= np.pi * (1 + 4 * float(np.finfo(dtype).eps)))


@checks.add
def exp_of_log(G, dtype, d, o):
    """exp(log T) == T (as matrices) for Haar-random T; the log is principal: its rotation
    angle is at most π."""
    x = o["log_T"]
    assert x.dtype == dtype and x.shape == (*BATCH, G.tangent_dim)
    assert_close(o["exp_log_T"], o["T"], dtype, 4)
    assert np.all(rotation_angle(G, x) <= np.pi * (1 + 4 * float(np.finfo(dtype).eps)))


@checks.add
def exp_matches_scipy_expm(G, dtype, d, o):
    """exp(x) == expm(Σ xₖ Eₖ) (scipy, float64, generators from the documented ordering),
    and == expm(hat(x)) with the library's hat; for angles up to 3 and up to 10."""
    for x, got, hat in ((d["y"], o["exp_y"], o["hat_y"]), (d["x10"], o["exp_x10"], o["hat_x10"])):
        assert got.dtype == dtype
        factor = 2 + float(np.max(rotation_angle(G, x), initial=0.0))
        assert_close(got, expm_ref(G, x), dtype, factor)
        flat = to_np(hat).reshape(-1, G.matrix_dim, G.matrix_dim)
        via_hat = np.stack([scipy.linalg.expm(m) for m in flat]).reshape(hat.shape)
        assert_close(got, via_hat, dtype, factor)


@checks.add
def matrix_round_trip(G, dtype, d, o):
    """from_matrix(as_matrix(T)) == T; the matrix is a rigid motion (orthonormal rotation
    block with determinant +1, homogeneous last rows; s R for Sim(3)), checked with numpy."""
    M = o["T"]
    assert M.dtype == dtype and M.shape == (*BATCH, G.matrix_dim, G.matrix_dim)
    assert_close(o["from_matrix_T"], M, dtype, 2)
    n = G.space_dim
    A = to_np(M)[..., :n, :n]
    s = np.cbrt(np.linalg.det(A)) if has_scale(G) else np.ones(BATCH)
    R = A / s[..., None, None]
    assert_close(np.swapaxes(R, -1, -2) @ R, identity_matrices(G, BATCH)[..., :n, :n], dtype, 2)
    assert_close(np.linalg.det(R), np.ones(BATCH), dtype, 2)
    np.testing.assert_array_equal(to_np(M)[..., n:, :], identity_matrices(G, BATCH)[..., n:, :])


@checks.add
def from_matrix_of_independent_matrix(G, dtype, d, o):
    """from_matrix of scipy's expm (rounded to the dtype, angles up to π) reproduces it."""
    assert o["from_matrix_ref"].dtype == dtype
    assert_close(o["from_matrix_ref"], d["M_ref"], dtype, 4)


@checks.add
def hat_vee(G, dtype, d, o):
    """hat places the coordinates on the generators of conftest exactly (``hat_ref``), and
    vee reads them back exactly, from the library's hat and from the reference one."""
    X = o["hat_x10"]
    assert X.dtype == dtype and X.shape == (*BATCH, G.matrix_dim, G.matrix_dim)
    np.testing.assert_array_equal(to_np(X), hat_ref(G, d["x10"]))
    assert o["vee_hat_x10"].dtype == dtype
    np.testing.assert_array_equal(to_np(o["vee_hat_x10"]), to_np(d["x10"]))
    np.testing.assert_array_equal(to_np(o["vee_hat_ref_x10"]), to_np(d["x10"]))


@checks.add
def vee_ignores_symmetric_part_of_rotation_block(G, dtype, d, o):
    """vee reads the generator coefficients (documented: the symmetric part is ignored; for
    Sim(3), whose σI is symmetric, the traceless symmetric part)."""
    assert_close(o["vee_sym"], vee_ref(G, d["X_sym"]), dtype)
    assert_close(o["vee_sym"], d["y"], dtype, 4)


@checks.add
def adjoint_identity(G, dtype, d, o):
    """M hat(x) M⁻¹ == hat(Ad x), and T exp(x) == exp(Ad x) T."""
    Ad = o["Ad"]
    assert Ad.dtype == dtype and Ad.shape == (*BATCH, G.tangent_dim, G.tangent_dim)
    M = to_np(o["T"])
    lhs = M @ hat_ref(G, d["y"]) @ np.linalg.inv(M)
    Adx = np.einsum("...ij,...j->...i", to_np(Ad), to_np(d["y"]))
    assert_close(hat_ref(G, Adx), lhs, dtype, 8)
    assert_close(o["T_exp_y"], o["exp_Ady_T"], dtype, 8)


@checks.add
def apply_is_matrix_action(G, dtype, d, o):
    """T.apply(p) == M p (SO) or (M [p; 1])[:n] (SE) in numpy; ``T @ p`` is the same call,
    and an unbatched point broadcasts against the batch."""
    got = o["apply"]
    assert got.dtype == dtype and got.shape == (*BATCH, G.space_dim)
    assert_close(got, homogeneous_apply(G, o["T"], d["p"]), dtype, 4)
    np.testing.assert_array_equal(o["matmul_p"], got)
    p0 = np.broadcast_to(to_np(d["p"][0, 0]), (*BATCH, G.space_dim))
    assert_close(o["apply_one_point"], homogeneous_apply(G, o["T"], p0), dtype, 4)


@checks.add
def multiply_is_matrix_product(G, dtype, d, o):
    """T.multiply(U) is the numpy product of the matrices; ``T @ U`` is the same call."""
    assert o["multiply"].dtype == dtype
    assert_close(o["multiply"], to_np(o["T"]) @ to_np(o["U"]), dtype, 4)
    np.testing.assert_array_equal(o["matmul_TU"], o["multiply"])


@checks.add
def normalize(G, dtype, d, o):
    """normalize is a projection: unit elements are fixed, a rotation part scaled by 0.5 … 2
    is brought back to the same element, and normalizing twice changes nothing."""
    k = rotation_params(G)
    p = o["T_params"]
    assert o["normalize_T"].dtype == dtype
    assert_close(o["normalize_T"], p, dtype, 2)
    assert_close(o["normalize_scaled"], p, dtype, 4)
    assert_close(o["normalize_twice"], o["normalize_scaled"], dtype, 2)
    norms = np.linalg.norm(to_np(o["normalize_scaled"])[..., :k], axis=-1)
    assert_close(norms, np.ones(BATCH), dtype, 2)


@checks.add
def normalize_any_scale(G, dtype, d, o):
    """A rotation part scaled by anything from just above the smallest normal float to the
    largest normalizes to the same element: the sum of squares would overflow (float32 3e38:
    the plain formula returned 0) or underflow (1e-30: inf and NaN) without the power-of-two
    scaling. Scaling by a power of two changes nothing, bit for bit. Zero and non-finite
    rotation parts give NaN in every rotation component; the derivative scales with the
    input."""
    k = rotation_params(G)
    want = o["normalize_P0"]
    for got, scale in zip(o["normalize_any_scale"], _any_scales(dtype)):
        assert_close(got, want, dtype, 4, msg=f"scale {scale:g}")
    np.testing.assert_array_equal(o["normalize_pow2"], want)
    bad = o["normalize_bad"]
    assert np.isnan(bad[:, :k]).all()
    np.testing.assert_array_equal(bad[:, k:], d["bad"][:, k:])
    assert_close(
        o["normalize_grad_tiny"] * np.dtype(dtype).type(2.0**-70), o["normalize_grad"], dtype, 4
    )


@checks.add
def jlog_matches_autodiff(G, dtype, d, o):
    """jlog == jax.jacrev(lambda δ: (T @ exp(δ)).log())(0) (jaxlie's definition), for
    Haar-random T and at every regime of the batch (zero, 1e-12, pure and long translations,
    π − 1e-6; not at exactly π, where log is not differentiable), and finite there."""
    J = o["jlog_T"]
    assert J.dtype == dtype and J.shape == (*BATCH, G.tangent_dim, G.tangent_dim)
    assert_close(J, o["jlog_T_ad"], dtype, 16)
    ok = rotation_angle(G, o["log_exp_x"]) < 3.1
    assert np.all(np.isfinite(o["jlog_x"][ok]))
    assert_close(o["jlog_x"][ok], o["jlog_x_ad"][ok], dtype, 16)


@checks.add
def elements_the_operations_make_are_valid(G, dtype, d, o):
    """Drawn elements, exponentials of tangents (angles up to 3), their products, inverses
    and logs' exponentials, the identity, and a rescaled element after ``normalize``, are
    valid at the default tolerance; the result is boolean, of the batch shape."""
    for name, valid in o["valid"].items():
        assert valid.dtype == np.bool_ and valid.shape == BATCH, name
        assert np.all(valid), name


@checks.add
def unbatched_equals_batched(G, dtype, d, o):
    """Each operation on one unbatched element equals the batched result's first element
    (same dtype, no batch axes)."""
    for name, got in o["one"].items():
        want = o[name][0, 0]
        assert got.dtype == dtype and got.shape == want.shape, name
        assert_close(got, want, dtype, 2, msg=name)


@over_groups_dtypes
@pytest.mark.parametrize("prop", list(checks))
def test_property(G, dtype, prop):
    """Each property on the regime batch (one program per group and dtype)."""
    d, o = results(_prepare, _program, G, dtype)
    checks[prop](G, dtype, d, o)


@over_groups_dtypes
@over_seeds
def test_properties_on_random_batches(G, dtype, seed):
    """Every property on random batches of the same shape (the same compiled program)."""
    d = _prepare(G, dtype, seed)
    checks.run_all(G, dtype, d, run(_program, G, d))


# ---------------------------------------------------------------------------------
# Random elements.


def test_sample_uniform_is_haar():
    """sample_uniform draws from the Haar measure, checked by Kolmogorov–Smirnov tests
    (20 000 draws, fixed key): the rotation angle has CDF θ/(2π) on [0, 2π) for SO(2) and
    (θ − sin θ)/π on [0, π] for SO(3); and a Haar rotation maps a fixed vector to a uniform
    point of the sphere, whose z has CDF (1 + z)/2. SE translations are uniform in [-1, 1]."""
    import scipy.stats

    key = jax.random.PRNGKey(3)
    n = 20000
    th = np.mod(to_np(SO2.sample_uniform(key, (n,)).as_radians()), 2 * np.pi)
    assert scipy.stats.kstest(th, lambda x: x / (2 * np.pi)).pvalue > 1e-3
    R = SO3.sample_uniform(key, (n,))
    angle = np.linalg.norm(to_np(R.log()), axis=-1)
    assert scipy.stats.kstest(angle, lambda x: (x - np.sin(x)) / np.pi).pvalue > 1e-3
    z = to_np(R.apply(jnp.array([1.0, 0.0, 0.0])))[:, 2]
    assert scipy.stats.kstest(z, lambda x: (1 + x) / 2).pvalue > 1e-3
    for G in SE_GROUPS:
        t = to_np(G.sample_uniform(key, (n,)).translation()).ravel()
        assert scipy.stats.kstest(t, lambda x: (x + 1) / 2).pvalue > 1e-3
