"""Inputs at the edges of each operation's domain: rotation angles far beyond π, quaternions
of any norm or either sign, and rotations by exactly π.

References: mpmath at 60 digits for the enormous angles, the same rotation built otherwise
(unit quaternion, opposite sign) for the rest, and the documented conventions at π.
"""

from __future__ import annotations

import jax.numpy as jnp
import jaxlie as jaxlie_ref  # the peer: its log at exactly π
import mpmath
import numpy as np
from conftest import (
    DTYPES,
    GROUPS,
    HALF_DTYPES,
    LAYOUT,
    all_close_as_matrices,
    assert_close,
    over_dtypes,
    over_quaternion_groups,
    over_seeds,
    random_element,
    rotation_params,
    to_np,
)

import jaxlie_geo
from jaxlie_geo import SE2, SE3, SO2, SO3


@over_dtypes
def test_exp_at_enormous_angles(dtype):
    """Rotation angles up to where θ² overflows keep the rotation parameters within 2 eps of
    mpmath's cos and sin (of θ for a unit complex number, of θ/2 for a quaternion; the angle is
    the exact float given), with a translation where the group has one. Beyond, the
    quaternion groups' exp gives NaN, as documented (the unit-complex groups take the angle
    directly and stay accurate)."""
    mpmath.mp.dps = 60
    eps = float(jnp.finfo(dtype).eps)
    below, above = (1e19, 1e20) if dtype == jnp.float32 else (1e150, 1e160)
    for th in (1e5, 1e10, below, above):
        t = float(np.dtype(dtype).type(th))
        for G in GROUPS:
            rot, trans = LAYOUT[G]
            axis = min(1, rot.stop - rot.start - 1)  # about y in 3-D
            x = np.zeros(G.tangent_dim)
            x[rot.start + axis] = t
            if trans is not None:
                x[trans] = np.arange(1.0, 1.0 + len(trans))
            params = to_np(G.exp(x.astype(dtype)).parameters())
            quaternion = rotation_params(G) == 4
            got = params[[0, 1 + axis]] if quaternion else params[:2]
            if quaternion and th == above:
                assert np.isnan(got).all(), (G.__name__, got)
                continue
            angle = mpmath.mpf(t) / (2 if quaternion else 1)
            want = np.array([float(mpmath.cos(angle)), float(mpmath.sin(angle))])
            np.testing.assert_allclose(
                got, want, rtol=0, atol=2 * eps, err_msg=f"{G.__name__}, θ = {t:g}"
            )


@over_dtypes
def test_log_is_scale_invariant_over_the_documented_norms(dtype):
    """The log of SO3 and SE3 (the quaternion layouts, written out) depends on q's direction
    only, over the norms that ``_scalar.atan2_over`` documents: 1e-15 < ‖q‖ < 4e18 in float32,
    1e-145 < ‖q‖ < 1e153 in float64 (below, the squares of small components flush to zero;
    above, (w + r)² overflows).
    The rotation, and so the log, depends on q's direction only; SE3.log's translation
    part once carried a stray 1/‖q‖ (exp(log T) off by 0.5 at ‖q‖ = 2). The 5th and 6th
    rows have a small component (0.05, 0.0005): at 1e-18 the first read 8e3 ulp wrong."""
    small, big = (1e-15, 4e18) if dtype == jnp.float32 else (1e-145, 1e153)
    q = np.array([[0.6, 0.8, 0.0, 0.0], [0.0, 0.0, 0.6, -0.8], [1.0, 0.0, 0.0, 0.0]], dtype)
    x = np.array([[0.3, -0.5, 0.9], [0.3, 0.2, -0.1], [3.1, 0.001, 0.2]], dtype)
    q = np.concatenate([q, to_np(SO3.exp(x).wxyz)]).astype(dtype)
    t = np.array([[1.0, -2.0, 0.5]] * len(q), dtype)
    so3, se3 = to_np(SO3(q).log()), to_np(SE3(np.concatenate([q, t], -1)).log())
    eps = float(jnp.finfo(dtype).eps)
    for scale in (small, 1e-3, 0.5, 1.001, 2.0, 1e3, big):
        np.testing.assert_allclose(
            to_np(SO3(q * scale).log()), so3, rtol=0, atol=8 * eps, err_msg=f"‖q‖ = {scale:g}"
        )
        if 1e-3 <= scale <= 1e3:
            np.testing.assert_allclose(
                to_np(SE3(np.concatenate([q * scale, t], -1)).log()),
                se3,
                rtol=0,
                atol=16 * eps,
                err_msg=f"‖q‖ = {scale:g}",
            )


@over_quaternion_groups
@over_dtypes
@over_seeds
def test_log_is_independent_of_quaternion_sign(G, dtype, seed):
    """q and −q are the same rotation: the principal log must not depend on the sign."""
    T = random_element(G, seed, (3,), dtype)
    p = np.array(T.parameters())
    p[..., :4] *= -1
    flipped = G(jnp.asarray(p))
    assert_close(flipped.log(), T.log(), dtype, 2)
    all_close_as_matrices(flipped, T, dtype)


def test_angle_of_a_half_turn():
    """SO2 and SE2 (the unit-complex layouts, written out): a rotation by π reads ±π, a valid
    log (exp of it gives the rotation back), in every float dtype; −π exactly where the stored
    sine is −0.0, as atan2 gives (``from_matrix(−I)`` stores the −0.0 that numpy's ``-np.eye(2)``
    has below the diagonal, as jaxlie does: −π)."""
    for dtype in HALF_DTYPES + DTYPES:
        R = SO2.from_matrix(-np.eye(2, dtype=dtype))
        assert np.signbit(np.float32(R.unit_complex[1])), R  # −0.0 below the diagonal, kept
        want = jnp.asarray(-np.pi, dtype)
        for got in (R.as_radians(), R.log()[0], SE2.from_rotation(R).log()[2]):
            assert got.dtype == dtype and got == want, (dtype, got)
        np.testing.assert_allclose(
            np.float32(SO2.exp(R.log()).as_matrix()),
            -np.eye(2),
            atol=2 * float(jnp.finfo(dtype).eps),
        )


@over_dtypes
def test_log_at_exactly_pi_is_jaxlies(dtype):
    """At w = 0 exactly (a turn of π) the principal log is −π times the stored vector
    part's direction (+π·axis is the other valid log), as jaxlie returns, in SO3 and SE3;
    interpolate and velocity_between follow it."""
    rng = np.random.default_rng(14)
    axes = np.concatenate([np.eye(3), -np.eye(3), rng.normal(size=(4, 3))])
    axes /= np.linalg.norm(axes, axis=-1, keepdims=True)
    q = jnp.asarray(np.concatenate([np.zeros((10, 1)), axes], axis=-1), dtype)
    eps = float(jnp.finfo(dtype).eps)
    want = -np.pi * axes
    np.testing.assert_allclose(to_np(SO3(q).log()), want, atol=8 * eps)
    np.testing.assert_allclose(
        to_np(SO3(q).log()), np.asarray(jaxlie_ref.SO3(jnp.asarray(q)).log()), atol=8 * eps
    )
    t = jnp.asarray(rng.normal(size=(10, 3)), dtype)
    T = SE3.from_rotation_and_translation(SO3(q), t)
    np.testing.assert_allclose(to_np(T.log()[..., 3:]), want, atol=8 * eps)
    half = SO3.identity((10,), dtype).interpolate(SO3(q), 0.5)
    np.testing.assert_allclose(
        to_np(half.as_matrix()), to_np(SO3.exp(want / 2).as_matrix()), atol=8 * eps
    )
    w = jaxlie_geo.motion.velocity_between(SO3.identity((10,), dtype), SO3(q), 2.0)
    np.testing.assert_allclose(to_np(w), want / 2, atol=8 * eps)
