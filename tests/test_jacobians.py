"""Jacobians of the exponential (``jac_right``, ``jac_left``, their inverses), ``ad``,
``jlog`` and the operation Jacobians of ``jaxlie_geo.jacobians``.

Conventions under test (right perturbations, Solà et al. 2018):

* ``exp(x + δ) ≈ exp(x) @ exp(J_r(x) δ)`` and ``exp(x + δ) ≈ exp(J_l(x) δ) @ exp(x)``;
  ``J_l(x) = Ad(exp x) J_r(x) = J_r(−x)``;
* ``ad(x)`` is the matrix of ``y ↦ vee([hat x, hat y])``;
* ``T.jlog() = jac_right_inv(T.log())``.

Accuracy references are independent of the library. The generators ``E_i`` are the
matrices written out in ``conftest.GENERATORS`` (entries 0 and ±1); in mpmath (``DPS``
digits, from the exact value of every stored float) ``hat(x) = Σ xᵢ Eᵢ`` and column j of
``ad(x)`` is ``vee([hat x, E_j])``, with ``vee`` the projection on the orthogonal
generators, so ``ad`` is exact. Then

    J_r(x) = Σ_k (−ad x)^k / (k+1)!,   J_l(x) = Σ_k (+ad x)^k / (k+1)!,

summed until the terms are below 10^-(DPS−5) of the sum, and ``J_r⁻¹``, ``J_l⁻¹`` are the
mpmath inverses of those sums. ``test_reference_convention`` checks the series against
``mpmath.expm`` (``exp(x + hδ) = exp(x) exp(h J_r δ) + O(h²)`` and
``J_l = expm(ad x) J_r``).

Error measure, per matrix: ``‖got − ref‖ / (eps · max(1, ‖ref‖))`` with ``‖·‖`` the
largest absolute entry (ref kept as a double-double, so the measure is exact to far
below 0.01 ulp); bound 8 ulp. Inputs: rotation angles exactly 0, tiny (1e-30..1e-8),
small (1e-4..0.1), mid (0.1..2), near π (π−1e-2..π−1e-6) and, for ``jac_right`` and
``jac_left`` only (the inverses are singular at 2π), 3..6 rad; translation
norms 0, 1, 1e3 (SE2, SE3); ``N_PER`` samples per cell (band end points included); float32
and float64 (each with its own stored inputs); all cases of a group and dtype in one
batched call.
"""

from __future__ import annotations

import functools
import math
from typing import Callable, Dict, List, Tuple

import jax
import jax.numpy as jnp
import mpmath as mp
import numpy as np
import pytest
import scipy.linalg
from _diskcache import disk_cached
from conftest import (
    EPS,
    GENERATORS,
    GROUPS,
    LAYOUT,
    SCALE_INDEX,
    dtype_name,
    hat_ref,
    over_groups,
    over_groups_dtypes,
    over_groups_float64,
    over_non_abelian_groups,
    to_np,
    vee_ref,
)

from jaxlie_geo import jacobians

DPS = 50
N_PER = 3
BOUND_ULP = 8.0

REGIMES = ("zero", "tiny", "small", "mid", "near_pi", "beyond")
JAC_NAMES = ("jac_right", "jac_left", "jac_right_inv", "jac_left_inv")
# The inverses are checked where the series inverse is well conditioned (below π);
# J_r and J_l everywhere, 3..6 rad included.
REGIMES_OF = {
    "jac_right": REGIMES,
    "jac_left": REGIMES,
    "jac_right_inv": REGIMES[:-1],
    "jac_left_inv": REGIMES[:-1],
}


# ---------------------------------------------------------------------------------
# Inputs.


def _angles(regime: str, rng: np.random.Generator, n: int) -> np.ndarray:
    """``n`` angles of a regime; the band's end points first, then log-uniform draws."""

    def band(lo: float, hi: float, log: bool = True) -> np.ndarray:
        u = rng.uniform(size=max(n - 2, 0))
        mid = np.exp(np.log(lo) + u * (np.log(hi) - np.log(lo))) if log else lo + u * (hi - lo)
        return np.concatenate([[lo, hi], mid])[:n]

    if regime == "zero":
        return np.zeros(n)
    if regime == "tiny":
        return band(1e-30, 1e-8)
    if regime == "small":
        return band(1e-4, 0.1)
    if regime == "mid":
        return band(0.1, 2.0)
    if regime == "near_pi":
        return math.pi - band(1e-6, 1e-2)
    if regime == "beyond":
        return band(3.0, 6.0, log=False)
    raise ValueError(regime)


def _flush(x: np.ndarray) -> np.ndarray:
    """Subnormals to zero, as XLA on CPU sees them."""
    return np.where(np.abs(x) < np.finfo(x.dtype).tiny, np.zeros_like(x), x)


@functools.lru_cache(maxsize=None)
def _cases(G: type, dtype_name: str) -> Tuple[np.ndarray, List[Tuple[str, float]]]:
    """Stored tangents (``dtype``) and, per tangent, (regime, translation norm)."""
    rng = np.random.default_rng(1234 + 17 * GROUPS.index(G) + (dtype_name == "float32"))
    rot, trans = LAYOUT[G]
    rot_dim = rot.stop - rot.start
    sizes = (0.0, 1.0, 1e3) if trans is not None else (0.0,)
    rows, meta = [], []
    for regime in REGIMES:
        for size in sizes:
            for angle in _angles(regime, rng, N_PER):
                x = np.zeros(G.tangent_dim)
                d = rng.normal(size=rot_dim)
                x[rot] = angle * d / np.linalg.norm(d)
                if trans is not None:
                    t = rng.normal(size=len(trans))
                    x[trans] = size * t / np.linalg.norm(t)
                if G in SCALE_INDEX:
                    x[SCALE_INDEX[G]] = rng.normal()
                rows.append(x)
                meta.append((regime, size))
    X = _flush(np.asarray(rows).astype(dtype_name))
    return X, meta


# ---------------------------------------------------------------------------------
# High-precision references (mpmath), from the generators alone.


def _mp_gens(G: type) -> List[mp.matrix]:
    return [mp.matrix(E.tolist()) for E in GENERATORS[G]]


def _mp_hat(G: type, x: List[mp.mpf]) -> mp.matrix:
    gens = _mp_gens(G)
    out = mp.zeros(G.matrix_dim, G.matrix_dim)
    for xi, E in zip(x, gens):
        out += xi * E
    return out


def _mp_vee(G: type, M: mp.matrix) -> List[mp.mpf]:
    out = []
    n = G.matrix_dim
    for E in _mp_gens(G):
        num = mp.fsum(M[i, j] * E[i, j] for i in range(n) for j in range(n))
        den = mp.fsum(E[i, j] ** 2 for i in range(n) for j in range(n))
        out.append(num / den)
    return out


def mp_ad(G: type, x: List[mp.mpf]) -> mp.matrix:
    """Columns vee([hat x, E_j]), exact."""
    X = _mp_hat(G, x)
    k = G.tangent_dim
    A = mp.zeros(k, k)
    for j, E in enumerate(_mp_gens(G)):
        col = _mp_vee(G, X * E - E * X)
        for i in range(k):
            A[i, j] = col[i]
    return A


def _max_abs(M: mp.matrix) -> mp.mpf:
    return max(abs(M[i, j]) for i in range(M.rows) for j in range(M.cols))


def mp_series(A: mp.matrix, sign: int) -> mp.matrix:
    """Σ_k (sign·A)^k / (k+1)!."""
    k = A.rows
    S = mp.eye(k)
    term = mp.eye(k)
    tol = mp.mpf(10) ** (-(mp.mp.dps - 5))
    n = 0
    while True:
        n += 1
        term = (term * A) * (mp.mpf(sign) / (n + 1))
        S += term
        if n > 3 and _max_abs(term) <= tol * max(1, _max_abs(S)):
            return S


def _hi_lo(M: mp.matrix) -> Tuple[np.ndarray, np.ndarray]:
    hi = np.array([[float(M[i, j]) for j in range(M.cols)] for i in range(M.rows)])
    lo = np.array([[float(M[i, j] - hi[i, j]) for j in range(M.cols)] for i in range(M.rows)])
    return hi, lo


@disk_cached
def _references(G: type, dtype_name: str) -> Dict[str, Tuple[np.ndarray, np.ndarray]]:
    """name -> (hi, lo), each (n_cases, k, k); NaN where a function is not checked."""
    X, meta = _cases(G, dtype_name)
    k = G.tangent_dim
    out = {name: (np.full((len(X), k, k), np.nan), np.zeros((len(X), k, k))) for name in JAC_NAMES}
    out["ad"] = (np.zeros((len(X), k, k)), np.zeros((len(X), k, k)))
    with mp.workdps(DPS):
        for c, (x, (regime, _)) in enumerate(zip(X, meta)):
            xm = [mp.mpf(float(v)) for v in x]  # exact: every float is a dyadic rational
            A = mp_ad(G, xm)
            out["ad"][0][c] = _hi_lo(A)[0]
            Jr, Jl = mp_series(A, -1), mp_series(A, +1)
            refs = {"jac_right": Jr, "jac_left": Jl}
            if regime in REGIMES_OF["jac_right_inv"]:
                refs.update(jac_right_inv=mp.inverse(Jr), jac_left_inv=mp.inverse(Jl))
            for name, M in refs.items():
                hi, lo = _hi_lo(M)
                out[name][0][c], out[name][1][c] = hi, lo
    return out


def ulp_errors(got: np.ndarray, hi: np.ndarray, lo: np.ndarray, dtype) -> np.ndarray:
    """‖got − ref‖ / (eps · max(1, ‖ref‖)) per matrix, max-abs-entry norm; inf if not finite."""
    got = np.asarray(got, np.float64)
    diff = np.abs((got - hi) - lo).reshape(len(got), -1).max(axis=-1)
    scale = np.maximum(1.0, np.abs(hi).reshape(len(got), -1).max(axis=-1))
    err = diff / (EPS[jnp.dtype(dtype)] * scale)
    finite = np.isfinite(got).reshape(len(got), -1).all(axis=-1)
    return np.where(finite, err, np.inf)


# ---------------------------------------------------------------------------------
# The reference itself: the series satisfy the defining relations under mpmath.expm.


@over_non_abelian_groups
@pytest.mark.parametrize("angle", [0.7, 2.9, 4.5])
def test_reference_convention(G, angle):
    """The mpmath series satisfy the defining relations under ``mpmath.expm``:
    exp(x + hδ) = exp(x) exp(h J_r δ) + O(h²) = exp(h J_l δ) exp(x) + O(h²), J_l = expm(ad x) J_r,
    and ad(x) y = vee([hat x, hat y]). The non-abelian groups (an abelian group's Jacobians
    are the identity and its ad zero: nothing to check)."""
    rng = np.random.default_rng(5)
    rot, trans = LAYOUT[G]
    x = rng.normal(size=G.tangent_dim)
    x[rot] *= angle / np.linalg.norm(x[rot])
    d = rng.normal(size=G.tangent_dim)
    with mp.workdps(60):
        xm = [mp.mpf(float(v)) for v in x]
        dm = [mp.mpf(float(v)) for v in d]
        A = mp_ad(G, xm)
        Jr, Jl = mp_series(A, -1), mp_series(A, +1)
        h = mp.mpf("1e-25")
        lhs = mp.expm(_mp_hat(G, [a + h * b for a, b in zip(xm, dm)]))
        Jd = Jr * mp.matrix(dm)
        rhs = mp.expm(_mp_hat(G, xm)) * mp.expm(_mp_hat(G, [h * Jd[i] for i in range(len(dm))]))
        assert _max_abs(lhs - rhs) / h < mp.mpf("1e-20")
        Jld = Jl * mp.matrix(dm)
        rhs_l = mp.expm(_mp_hat(G, [h * Jld[i] for i in range(len(dm))])) * mp.expm(_mp_hat(G, xm))
        assert _max_abs(lhs - rhs_l) / h < mp.mpf("1e-20")
        assert _max_abs(Jl - mp.expm(A) * Jr) < mp.mpf("1e-40")
    # ad(x) y = vee([hat x, hat y]) with numpy's hat/vee references from conftest.
    y = rng.normal(size=G.tangent_dim)
    X, Y = hat_ref(G, x), hat_ref(G, y)
    A64 = np.array(A.tolist(), dtype=float)
    np.testing.assert_allclose(A64 @ y, vee_ref(G, X @ Y - Y @ X), rtol=1e-14, atol=1e-14)


# ---------------------------------------------------------------------------------
# Accuracy: every Jacobian within 8 ulp of the high-precision series.


def _report(G, dtype, name, X, meta, err, top: int = 6) -> str:
    order = np.argsort(-np.nan_to_num(err, nan=-1.0))[:top]
    worst = f"worst {err[order[0]]:.2f} ulp > {BOUND_ULP}"
    lines = [f"{G.__name__}.{name} {dtype_name(dtype)}: {worst}"]
    for c in order:
        regime, size = meta[c]
        lines.append(
            f"  {err[c]:8.2f} ulp  regime={regime} |t|={size:g} "
            f"angle={np.linalg.norm(np.asarray(X[c], np.float64)[LAYOUT[G][0]]):.17g} "
            f"x={np.asarray(X[c]).tolist()}"
        )
    return "\n".join(lines)


@over_groups_dtypes
@pytest.mark.parametrize("name", JAC_NAMES)
def test_jacobian_accuracy(G, dtype, name):
    """Each Jacobian, in one batched call over every case of the grid, is within ``BOUND_ULP``
    of the mpmath series, in the input dtype."""
    X, meta = _cases(G, dtype_name(dtype))
    hi, lo = _references(G, dtype_name(dtype))[name]
    keep = np.array([m[0] in REGIMES_OF[name] for m in meta])
    got = getattr(G, name)(jnp.asarray(X))  # one batched call over every case
    assert got.dtype == dtype and got.shape == (len(X), G.tangent_dim, G.tangent_dim)
    err = ulp_errors(np.asarray(got)[keep], hi[keep], lo[keep], dtype)
    X, meta = X[keep], [m for m, k in zip(meta, keep) if k]
    assert np.all(err <= BOUND_ULP), _report(G, dtype, name, X, meta, err)


@over_groups_dtypes
def test_ad_exact(G, dtype):
    """ad(x) equals vee([hat x, E_j]) column by column, exactly (entries are ±xᵢ)."""
    X, _ = _cases(G, dtype_name(dtype))
    got = G.ad(jnp.asarray(X))
    assert got.dtype == dtype
    np.testing.assert_array_equal(to_np(got), _references(G, dtype_name(dtype))["ad"][0])


@over_groups_dtypes
def test_products_are_identity(G, dtype):
    """J_r J_r⁻¹ = I and J_l J_l⁻¹ = I, to rounding (relative to ‖J‖‖J⁻¹‖)."""
    X, meta = _cases(G, dtype_name(dtype))
    keep = np.array([m[0] in REGIMES_OF["jac_right_inv"] for m in meta])
    x = jnp.asarray(X[keep])
    eye = np.eye(G.tangent_dim)
    for fwd, inv in (("jac_right", "jac_right_inv"), ("jac_left", "jac_left_inv")):
        J, Ji = to_np(getattr(G, fwd)(x)), to_np(getattr(G, inv)(x))
        res = np.abs(J @ Ji - eye).max(axis=(-1, -2))
        scale = np.abs(J).sum(-1).max(-1) * np.abs(Ji).sum(-1).max(-1)
        ulps = res / (EPS[jnp.dtype(dtype)] * scale)
        assert np.all(ulps <= 16), (fwd, ulps.max(), X[keep][np.argmax(ulps)])


# ---------------------------------------------------------------------------------
# Identities between the Jacobians, jlog, Ad and ad.


def _tangents(G, dtype, n=16, seed=0, max_angle=3.0, tscale=2.0):
    rng = np.random.default_rng(seed)
    rot, trans = LAYOUT[G]
    x = rng.normal(size=(n, G.tangent_dim))
    ang = rng.uniform(0, max_angle, size=n)
    x[:, rot] *= (ang / np.linalg.norm(x[:, rot], axis=-1))[:, None]
    if trans is not None:
        x[:, trans] *= tscale
    return jnp.asarray(x, dtype)


def _tol(dtype, ulps):
    e = EPS[jnp.dtype(dtype)]
    return {"rtol": ulps * e, "atol": ulps * e}


@over_groups_dtypes
def test_left_right_relations(G, dtype):
    """J_l(x) = J_r(−x) = Ad(exp x) J_r(x); J_l⁻¹(x) = J_r⁻¹(−x)."""
    x = _tangents(G, dtype)
    Jl, Jr = to_np(G.jac_left(x)), to_np(G.jac_right(x))
    scale = max(1.0, np.abs(Jl).max())
    np.testing.assert_allclose(Jl, to_np(G.jac_right(-x)), **_tol(dtype, 8 * scale))
    Ad = to_np(G.exp(x).adjoint())
    np.testing.assert_allclose(Jl, Ad @ Jr, **_tol(dtype, 32 * scale))
    np.testing.assert_allclose(
        to_np(G.jac_left_inv(x)), to_np(G.jac_right_inv(-x)), **_tol(dtype, 8 * scale)
    )


@over_groups_dtypes
def test_ad_is_bracket_and_generates_adjoint(G, dtype):
    """ad(x) y = vee([hat x, hat y]) with the library's hat/vee; Ad(exp x) = expm(ad x)."""
    x, y = _tangents(G, dtype, seed=1), _tangents(G, dtype, seed=2)
    X, Y = G.hat(x), G.hat(y)
    got = jnp.einsum("...ij,...j->...i", G.ad(x), y)
    np.testing.assert_allclose(to_np(got), to_np(G.vee(X @ Y - Y @ X)), **_tol(dtype, 16))
    ref = np.stack([scipy.linalg.expm(a) for a in to_np(G.ad(x))])
    np.testing.assert_allclose(to_np(G.exp(x).adjoint()), ref, **_tol(dtype, 64))


@over_groups_dtypes
def test_jlog_is_jac_right_inv_of_log(G, dtype):
    """``T.jlog() == jac_right_inv(T.log())``."""
    T = G.exp(_tangents(G, dtype, seed=3))
    got, want = to_np(T.jlog()), to_np(G.jac_right_inv(T.log()))
    np.testing.assert_allclose(got, want, **_tol(dtype, 2 * max(1.0, np.abs(want).max())))


@over_groups
@pytest.mark.parametrize("name", (*JAC_NAMES, "ad"))
def test_batched_and_jit(G, name):
    """Batch shapes (), (3,), (2, 4) agree element by element; jit gives the same (float32:
    the batch logic does not depend on the dtype)."""
    dtype = jnp.float32
    f = getattr(G, name)
    x = _tangents(G, dtype, n=8, seed=5).reshape(2, 4, G.tangent_dim)
    k = G.tangent_dim
    out = f(x)
    assert out.shape == (2, 4, k, k) and out.dtype == dtype
    for i in range(2):
        for j in range(4):
            np.testing.assert_allclose(to_np(f(x[i, j])), to_np(out[i, j]), **_tol(dtype, 2))
    np.testing.assert_allclose(
        to_np(jax.jit(lambda t: f(t))(x[0, :3])), to_np(out[0, :3]), **_tol(dtype, 2)
    )
    np.testing.assert_allclose(
        to_np(jax.jit(jax.vmap(f))(x.reshape(8, k))), to_np(out.reshape(8, k, k)), **_tol(dtype, 2)
    )


@over_groups_float64
@pytest.mark.parametrize("name", (*JAC_NAMES, "ad"))
def test_differentiable_at_zero(G, dtype, name):
    """jacfwd (and jacrev) through the Jacobians are finite at 0 and tiny angles, and at 0
    equal the first-order terms: dJ_r = −½ ad, dJ_l = +½ ad, dJ_r⁻¹ = +½ ad, dJ_l⁻¹ = −½ ad."""
    f = getattr(G, name)
    k = G.tangent_dim
    # d ad(x)/dx_i = ad(e_i) (linear); the first-order term of each series is ∓½ ad.
    coef = {
        "jac_right": -0.5,
        "jac_left": 0.5,
        "jac_right_inv": 0.5,
        "jac_left_inv": -0.5,
        "ad": 1.0,
    }[name]
    ad_e = np.moveaxis(to_np(G.ad(jnp.eye(k, dtype=dtype))), 0, -1)  # (k, k, k_in)
    # Forward mode: d(f, f')/dx gives f' and f'' in one program; reverse mode in another.
    fwd = jax.jit(jax.jacfwd(lambda x: (f(x), jax.jacfwd(f)(x))))
    rev = jax.jit(jax.jacrev(f))
    for x in (jnp.zeros(k, dtype), jnp.full(k, 1e-20, dtype)):
        (d_fwd, h), d_rev = fwd(x), rev(x)
        for mode, d in (("jacfwd", to_np(d_fwd)), ("jacrev", to_np(d_rev))):
            assert d.shape == (k, k, k) and np.all(np.isfinite(d)), (name, mode)
            np.testing.assert_allclose(d, coef * ad_e, **_tol(dtype, 4))
        if not np.any(x):  # second derivatives are finite at 0 too
            assert np.all(np.isfinite(to_np(h)))


@over_groups_float64
def test_jlog_differentiable_at_identity(G, dtype):
    """d jlog(I exp(e)) / de at e = 0 is finite and equals ½ ad(eᵢ) (the first-order term of
    J_r⁻¹)."""
    k = G.tangent_dim
    T = G.identity(dtype=dtype)
    d = to_np(jax.jit(jax.jacfwd(lambda e: (T @ G.exp(e)).jlog()))(jnp.zeros(k, dtype)))
    assert np.all(np.isfinite(d))
    ad_e = np.moveaxis(to_np(G.ad(jnp.eye(k, dtype=dtype))), 0, -1)
    np.testing.assert_allclose(d, 0.5 * ad_e, **_tol(dtype, 4))


# ---------------------------------------------------------------------------------
# Operation Jacobians against jax.jacfwd of the defining maps.


def _elements(G, dtype, batch, seed, max_angle=2.5, tscale=2.0):
    n = int(np.prod(batch)) if batch else 1
    x = _tangents(G, dtype, n=n, seed=seed, max_angle=max_angle, tscale=tscale)
    return G.exp(x.reshape(*batch, G.tangent_dim))


def _flat_broadcast(a, b):
    """Broadcast two elements (or an element and an array) to a common batch, flattened."""
    pa = a.parameters()
    pb = b.parameters() if hasattr(b, "parameters") else b
    batch = jnp.broadcast_shapes(pa.shape[:-1], pb.shape[:-1])
    pa = jnp.broadcast_to(pa, (*batch, pa.shape[-1])).reshape(-1, pa.shape[-1])
    pb = jnp.broadcast_to(pb, (*batch, pb.shape[-1])).reshape(-1, pb.shape[-1])
    return batch, type(a)(pa), (type(b)(pb) if hasattr(b, "parameters") else pb)


def _autodiff(f: Callable, a, b, batch):
    """vmap of jacfwd of f(a, b, δ_a, δ_b) at δ = 0 w.r.t. (δ_a, δ_b), reshaped to batch."""
    G = type(a)
    dt = a.parameters().dtype

    def one(a1, b1):
        za = jnp.zeros(G.tangent_dim, dt)
        zb = jnp.zeros(G.tangent_dim if hasattr(b1, "parameters") else b1.shape[-1], dt)
        return jax.jacfwd(lambda da, db: f(a1, b1, da, db), argnums=(0, 1))(za, zb)

    Ja, Jb = jax.jit(jax.vmap(one))(a, b)
    return Ja.reshape(*batch, *Ja.shape[1:]), Jb.reshape(*batch, *Jb.shape[1:])


def _rplus(T, d):
    return T @ type(T).exp(d)


OPERATION_MAPS = {
    # f(X ⊕ δ) compared with f(X) on the right: log(f(X)⁻¹ f(X ⊕ δ)); vectors additively.
    "compose": lambda a, b, da, db: ((a @ b).inverse() @ (_rplus(a, da) @ _rplus(b, db))).log(),
    "between": lambda a, b, da, db: (
        (a.inverse() @ b).inverse() @ (_rplus(a, da).inverse() @ _rplus(b, db))
    ).log(),
    "rminus": lambda a, b, da, db: (_rplus(a, da).inverse() @ _rplus(b, db)).log(),
    "apply": lambda T, p, dT, dp: _rplus(T, dT) @ (p + dp),
}


@over_groups_dtypes
@pytest.mark.parametrize(
    "op", ["compose", "between", "rminus", "apply", "rplus", "inverse", "exp", "log"]
)
def test_operation_jacobians(G, dtype, op):
    """Each function of jaxlie_geo.jacobians equals jacfwd of its defining map, with the
    arguments' batch axes (3, 1) and (4,) broadcast to (3, 4)."""
    k = G.tangent_dim
    a = _elements(G, dtype, (3, 1), seed=10)
    if op in ("compose", "between", "rminus"):
        b = _elements(G, dtype, (4,), seed=11)
        got = getattr(jacobians, op)(a, b)
        batch, fa, fb = _flat_broadcast(a, b)
        want = _autodiff(OPERATION_MAPS[op], fa, fb, batch)
    elif op == "apply":
        p = jnp.asarray(np.random.default_rng(12).normal(size=(4, G.space_dim)) * 3, dtype)
        got = jacobians.apply(a, p)
        batch, fa, fp = _flat_broadcast(a, p)
        want = _autodiff(OPERATION_MAPS[op], fa, fp, batch)
    elif op == "rplus":
        d = _tangents(G, dtype, n=4, seed=13, max_angle=2.0)
        got = jacobians.rplus(a, d)
        batch, fa, fd = _flat_broadcast(a, d)
        f = lambda a1, d1, da, dd: (
            _rplus(a1, d1).inverse() @ _rplus(a1, da) @ G.exp(d1 + dd)
        ).log()
        want = _autodiff(f, fa, fd, batch)
    elif op == "inverse":
        got = (jacobians.inverse(a),)
        z = jnp.zeros(k, dtype)
        f = lambda a1: jax.jacfwd(lambda d: (a1 @ _rplus(a1, d).inverse()).log())(z)
        want = (jax.jit(jax.vmap(f))(a.reshape(3)).reshape(3, 1, k, k),)
    elif op == "exp":
        x = _tangents(G, dtype, n=4, seed=14)
        got = (jacobians.exp(G, x),)
        z = jnp.zeros(k, dtype)
        f = lambda x1: jax.jacfwd(lambda d: (G.exp(x1).inverse() @ G.exp(x1 + d)).log())(z)
        want = (jax.jit(jax.vmap(f))(x),)
    elif op == "log":
        got = (jacobians.log(a),)
        z = jnp.zeros(k, dtype)
        f = lambda a1: jax.jacfwd(lambda d: _rplus(a1, d).log())(z)
        want = (jax.jit(jax.vmap(f))(a.reshape(3)).reshape(3, 1, k, k),)
    if not isinstance(got, tuple):
        got = (got,)
    assert len(got) == len(want)
    for i, (g, w) in enumerate(zip(got, want)):
        assert g.shape == w.shape, (op, i, g.shape, w.shape)
        assert g.dtype == dtype, (op, i, g.dtype)
        scale = max(1.0, float(np.abs(to_np(w)).max()))
        np.testing.assert_allclose(
            to_np(g), to_np(w), **_tol(dtype, 256 * scale), err_msg=f"{op} argument {i}"
        )


@over_groups_dtypes
def test_generator_action(G, dtype):
    """K(p) column i = (hat(eᵢ) p̃)[:space_dim], against the conftest generators."""
    p = jnp.asarray(np.random.default_rng(15).normal(size=(5, G.space_dim)), dtype)
    got = to_np(jacobians.generator_action(G, p))
    ph = to_np(p)
    if G.matrix_dim > G.space_dim:  # homogeneous (p, 1, 0, …)
        pad = np.zeros((5, G.matrix_dim - G.space_dim))
        pad[:, 0] = 1.0
        ph = np.concatenate([ph, pad], axis=-1)
    want = np.einsum("kij,bj->bik", GENERATORS[G], ph)[:, : G.space_dim, :]
    np.testing.assert_allclose(got, want, **_tol(dtype, 1))
