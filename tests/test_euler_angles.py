"""SO3's roll, pitch and yaw (``from_rpy_radians``, ``as_rpy_radians``,
``compute_roll/pitch/yaw_radians``): an API of SO3 alone, so these tests name it.

References: scipy's intrinsic ZYX Euler angles of the same rotation, and mpmath's asin of the
stored quaternion near gimbal lock; central differences for the derivatives.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from conftest import over_dtypes, to_np

from jaxlie_geo import SO3


@over_dtypes
def test_rpy_depends_on_the_quaternion_direction_only(dtype):
    """compute_roll/pitch/yaw_radians of a scaled quaternion equal those of the unit one, and
    scipy's intrinsic ZYX angles of the same rotation (as ``as_matrix`` reads it). The unit
    formulas read π/2 for a pitch of 1.3 from a quaternion 5% long (the clipped sine)."""
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(5)
    rpy = rng.uniform([-3.0, -1.5, -3.0], [3.0, 1.5, 3.0], size=(64, 3))
    q = np.asarray(SO3.from_rpy_radians(*jnp.asarray(rpy.T, dtype)).wxyz, np.float64)
    ref = Rotation.from_quat(np.roll(q, -1, axis=-1)).as_euler("ZYX")[:, ::-1]
    eps = float(np.finfo(dtype).eps)
    for scale in (1.0, 0.5, 1.05, 2.0, 1e3):
        R = SO3(jnp.asarray(q * scale, dtype))
        got = np.stack(
            [
                np.asarray(R.compute_roll_radians()),
                np.asarray(R.compute_pitch_radians()),
                np.asarray(R.compute_yaw_radians()),
            ],
            -1,
        ).astype(np.float64)
        # pitch is ill-conditioned near ±π/2 (asin): compare its sine there
        err = np.abs(got - ref)
        err[:, 1] = np.abs(np.sin(got[:, 1]) - np.sin(ref[:, 1])) / np.maximum(
            np.cos(ref[:, 1]), 1e-3
        )
        assert err.max() <= 16 * eps, (scale, err.max() / eps)


@over_dtypes
def test_rpy_at_and_near_gimbal_lock(dtype):
    """At and near pitch ±π/2 (0 to 0.3 away): the pitch is within 2 eps of mpmath's
    asin(2(wy − zx)/‖q‖²) of the stored quaternion (jaxlie's asin: 5.8e3 eps in float32,
    1.3e8 in float64, and NaN past ±1), and ``from_rpy_radians`` of the three angles, each
    read by its own (jitted) method, gives the rotation back within 8 eps (roll and yaw
    alone are ill-conditioned there; read independently they gave O(1) errors at lock).
    Scaled quaternions too (direction only)."""
    import mpmath

    mpmath.mp.dps = 50
    rng = np.random.default_rng(8)
    eps = float(np.finfo(dtype).eps)
    n = 256
    for delta in (0.0, 1e-6, 1e-3, 0.3):
        rpy = rng.uniform(-np.pi, np.pi, size=(n, 3))
        rpy[:, 1] = np.where(np.arange(n) % 2 == 0, 1.0, -1.0) * (np.pi / 2 - delta)
        R = SO3.from_rpy_radians(*jnp.asarray(rpy.T, dtype))
        q = np.asarray(R.wxyz, np.float64)
        want = []
        for w, x, y, z in q.tolist():
            w, x, y, z = (mpmath.mpf(v) for v in (w, x, y, z))
            want.append(float(mpmath.asin(2 * (w * y - z * x) / (w * w + x * x + y * y + z * z))))
        for scale in (1.0, 1.5, 0.75):
            Q = SO3(R.wxyz * jnp.asarray(scale, dtype))
            roll, pitch = Q.compute_roll_radians(), Q.compute_pitch_radians()
            yaw = Q.compute_yaw_radians()
            np.testing.assert_allclose(to_np(pitch), want, rtol=0, atol=2 * eps, err_msg=f"{delta}")
            back = SO3.from_rpy_radians(roll, pitch, yaw)
            np.testing.assert_allclose(
                to_np(back.as_matrix()),
                to_np(R.as_matrix()),
                rtol=0,
                atol=8 * eps,
                err_msg=f"δ = {delta}, scale {scale}",
            )
    # exactly at lock, w ∓ y and z ± x exactly 0 (each read as 1), and the zero quaternion
    exact = np.array(
        [
            [0.5, 0.5, 0.5, -0.5],
            [0.5, -0.5, -0.5, -0.5],
            [1.0, 0.0, 1.0, 0.0],
            [1.0, 0.0, -1.0, 0.0],
            [0.0, 1.0, 0.0, 1.0],
            [0.6, 0.8, 0.6, -0.8],
        ],
        dtype,
    )
    R = SO3(jnp.asarray(exact))
    roll, pitch, yaw = R.as_rpy_radians()
    np.testing.assert_array_equal(np.abs(to_np(pitch)), np.float64(np.asarray(np.pi / 2, dtype)))
    np.testing.assert_allclose(
        to_np(SO3.from_rpy_radians(roll, pitch, yaw).as_matrix()),
        to_np(R.as_matrix()),
        rtol=0,
        atol=8 * eps,
    )
    assert [float(a) for a in SO3(jnp.zeros(4, dtype)).as_rpy_radians()] == [0.0, 0.0, 0.0]
    # derivatives: 0 for the pitch exactly at lock (a maximum; NaN through √0 before the
    # guard), central differences elsewhere (float64)
    pitch_of = jax.vmap(jax.grad(lambda q: SO3(q).compute_pitch_radians()))
    np.testing.assert_array_equal(to_np(pitch_of(jnp.asarray(exact))), 0.0)
    if dtype == np.float64:
        q = np.asarray(SO3.from_rpy_radians(0.3, np.pi / 2 - 0.1, -2.0).wxyz)
        for f in ("compute_roll_radians", "compute_pitch_radians", "compute_yaw_radians"):
            g = to_np(jax.grad(lambda q, f=f: getattr(SO3(q), f)())(jnp.asarray(q)))
            fd = [
                (
                    float(getattr(SO3(jnp.asarray(q + h * e)), f)())
                    - float(getattr(SO3(jnp.asarray(q - h * e)), f)())
                )
                / (2 * h)
                for e, h in zip(np.eye(4), [1e-6] * 4)
            ]
            np.testing.assert_allclose(g, fd, rtol=1e-7, atol=1e-7, err_msg=f)
