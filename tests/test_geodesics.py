"""Interpolation, geodesics and ``between`` on every group × dtype, on the regime batch of
``tests/_programs.py`` (the operations shared with the other numeric modules).

References: the geodesic written with scipy's ``expm`` in its body and left forms,
T expm(t log(T⁻¹U)) and expm(t log(U T⁻¹)) T (built from U = T exp(x), whose relative log
is x, so no library log enters the reference), and the group product a⁻¹ b.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg
from _programs import BATCH, Checks, regime_batch, results, run
from conftest import (
    GROUPS,
    assert_close,
    hat_ref,
    over_groups,
    over_groups_dtypes,
    over_seeds,
    random_element,
    to_np,
)

import jaxlie_geo

_TIMES = np.array([0.5, 0.25, 0.9, -0.3, 1.7])
"""Times of the geodesic test (0.5 is the midpoint, −0.3 and 1.7 extrapolate)."""
_TS = np.array([0.0, 0.2, 0.5, 1.0, 2.0])
"""Times of the broadcasting test."""


@jax.jit
def _call_path(path, t):
    """A geodesic called under jit (it is a pytree argument)."""
    return path(t)


def _prepare(G, dtype, seed):
    d = regime_batch(G, dtype, seed)
    rng = np.random.default_rng(seed)
    d["t"] = rng.choice(_TIMES, size=BATCH).astype(dtype)
    d["t_any"] = rng.uniform(-1.0, 2.0, size=BATCH).astype(dtype)
    d["ts"] = _TS.astype(dtype)
    return d


def _program(G, d):
    T, U, y, t = d["T"], d["U"], d["y"], d["t"]
    Uy = T @ G.exp(y)  # relative log y, angle ≤ 3: away from π, where the geodesic is unique
    path = jaxlie_geo.geodesic(T, U)
    ts = d["ts"]
    T0, Uy0 = T[0, 0], Uy[0, 0]
    Tb, Ub = T[0, :3], Uy[0, :3]
    grid = Tb.interpolate(Ub, ts[:, None])
    return {
        "T": T.as_matrix(),
        "U": U.as_matrix(),
        "interp_0": T.interpolate(U, 0.0).as_matrix(),
        "interp_1": T.interpolate(U, 1.0).as_matrix(),
        "interp_0_params": T.interpolate(U, 0.0).parameters(),
        "geodesic_t": T.interpolate(Uy, t).as_matrix(),
        "midpoint": T.interpolate(Uy, 0.5).as_matrix(),
        "path_t": path(d["t_any"]).parameters(),
        "interp_t": T.interpolate(U, d["t_any"]).parameters(),
        "path_jit": _call_path(path, d["t_any"]).parameters(),
        # broadcasting of times against endpoints
        "ts_path": T0.interpolate(Uy0, ts).as_matrix(),
        "ts_list": T0.interpolate(Uy0, [float(s) for s in _TS]).as_matrix(),
        "ts_each": jnp.stack([T0.interpolate(Uy0, float(s)).as_matrix() for s in _TS]),
        "ts_exp2": (T0 @ G.exp(2 * y[0, 0])).as_matrix(),
        "grid": grid.as_matrix(),
        "grid_geodesic": jaxlie_geo.geodesic(Tb, Ub)(ts[:, None]).parameters(),
        "grid_params": grid.parameters(),
    }


def _geodesic_ref(MT, x, G, t):
    """Body and left forms of the geodesic through MT with body velocity x, with scipy:
    MT expm(t hat(x)) and expm(t MT hat(x) MT⁻¹) MT (hat from the generators), float64.
    For U = T exp(x) with |angle(x)| < π, x is log(T⁻¹U)."""
    MT = to_np(MT)
    X = np.broadcast_to(hat_ref(G, x), MT.shape)
    t = np.broadcast_to(np.asarray(t, np.float64), MT.shape[:-2])
    body = np.empty_like(MT)
    left = np.empty_like(MT)
    for idx in np.ndindex(MT.shape[:-2]):
        A = MT[idx]
        body[idx] = A @ scipy.linalg.expm(t[idx] * X[idx])
        left[idx] = scipy.linalg.expm(t[idx] * (A @ X[idx] @ np.linalg.inv(A))) @ A
    return body, left


checks = Checks()


@checks.add
def interpolate_endpoints(G, dtype, d, o):
    """interpolate(U, 0) == T and interpolate(U, 1) == U, as matrices, with the dtype."""
    assert o["interp_0_params"].dtype == dtype
    assert_close(o["interp_0"], o["T"], dtype, 2)
    assert_close(o["interp_1"], o["U"], dtype, 16)


@checks.add
def interpolate_is_geodesic(G, dtype, d, o):
    """T.interpolate(U, t) == T expm(t log(T⁻¹U)) == expm(t log(U T⁻¹)) T, away from a
    relative rotation of π, for t in {0.5, 0.25, 0.9, −0.3, 1.7}; t = 0.5 is the geodesic
    midpoint. (Reference: U = T exp(x), whose relative log is x, and scipy's expm.)"""
    body, left = _geodesic_ref(o["T"], d["y"], G, d["t"])
    assert o["geodesic_t"].dtype == dtype
    assert_close(o["geodesic_t"], body, dtype, 32)
    assert_close(o["geodesic_t"], left, dtype, 32)
    body, _ = _geodesic_ref(o["T"], d["y"], G, 0.5)
    assert_close(o["midpoint"], body, dtype, 32)


@checks.add
def geodesic_path_equals_interpolate(G, dtype, d, o):
    """geodesic(T, U)(t) == T.interpolate(U, t) for t in [−1, 2], and the path goes through
    jit as a pytree."""
    assert o["path_t"].dtype == dtype
    assert_close(o["path_t"], o["interp_t"], dtype)
    assert_close(o["path_jit"], o["path_t"], dtype, 2)


@checks.add
def interpolate_time_broadcasting(G, dtype, d, o):
    """Times of shape (K,) give K poses, times of shape (K, 1) against endpoints of batch
    (3,) give (K, 3), lists work as arrays, and extrapolation (t = 2) follows the same
    geodesic (scipy reference)."""
    path = o["ts_path"]
    assert path.shape == (5, G.matrix_dim, G.matrix_dim) and path.dtype == dtype
    assert_close(o["ts_list"], path, dtype, 2)
    assert_close(o["ts_each"], path, dtype, 2)
    y0 = d["y"][0, 0]
    assert_close(path[4], o["ts_exp2"], dtype, 32)
    body, _ = _geodesic_ref(o["T"][0, 0], y0, G, 2.0)
    assert_close(path[4], body, dtype, 64)
    grid = o["grid"]
    assert grid.shape == (5, 3, G.matrix_dim, G.matrix_dim) and grid.dtype == dtype
    MT = np.broadcast_to(to_np(o["T"][0, :3]), grid.shape)
    ts = np.broadcast_to(_TS[:, None], (5, 3))
    body, _ = _geodesic_ref(MT, np.broadcast_to(d["y"][0, :3], (5, 3, G.tangent_dim)), G, ts)
    assert_close(grid, body, dtype, 64)
    assert_close(o["grid_geodesic"], o["grid_params"], dtype)


@over_groups_dtypes
@pytest.mark.parametrize("prop", list(checks))
def test_property(G, dtype, prop):
    """Each property on the regime batch."""
    d, o = results(_prepare, _program, G, dtype)
    checks[prop](G, dtype, d, o)


@over_groups_dtypes
@over_seeds
def test_properties_on_random_batches(G, dtype, seed):
    """Every property on random batches of the same shape (the same compiled operations)."""
    d = _prepare(G, dtype, seed)
    checks.run_all(G, dtype, d, run(_program, G, d))


@over_groups
def test_between_is_the_relative_element(G):
    """``between(a, b)`` is ``a⁻¹ @ b`` (the same rotation, translations to rounding near the
    origin; accuracy far from it: test_accuracy), broadcasts batch axes, and refuses another
    group or a bare array."""
    a = random_element(G, 1, (3, 1), np.float64)
    b = random_element(G, 2, (4,), np.float64)
    E = jaxlie_geo.between(a, b)
    assert E.get_batch_axes() == (3, 4)
    assert_close(E.as_matrix(), (a.inverse() @ b).as_matrix(), np.float64, 8)
    want = jnp.broadcast_to(b.as_matrix(), (3, 4, G.matrix_dim, G.matrix_dim))
    assert_close((a @ E).as_matrix(), want, np.float64, 8)
    other = GROUPS[(GROUPS.index(G) + 1) % len(GROUPS)]
    with pytest.raises(TypeError, match=f"expected {G.__name__}, got {other.__name__}"):
        jaxlie_geo.between(a, other.identity())
    with pytest.raises(TypeError, match="expected a group element"):
        jaxlie_geo.between(a.parameters(), b)
