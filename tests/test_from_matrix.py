"""SO3/SE3.from_matrix near and at π (Shepperd pivoting) against mpmath.

The reference quaternion is that of the exact rotation (50 digits) whose rounded matrix the
function receives; rounding the matrix moves the quaternion by O(eps), so a well-conditioned
conversion is within a few ulp. Compared up to the quaternion's sign.
"""

import jax
import mpmath as mp
import numpy as np
import pytest

import jaxlie_geo as jl

jax.config.update("jax_enable_x64", True)

mp.mp.dps = 50


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


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_from_matrix_quaternion_near_pi(dtype):
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
            got = np.asarray(jl.SO3.from_matrix(M).wxyz, dtype=np.float64)
            ref = np.array([float(c) for c in q])
            err = min(np.abs(got - ref).max(), np.abs(got + ref).max()) / eps
            worst = max(worst, err)
            # SE3 shares the rotation code path; check it is wired the same way.
            H = np.eye(4, dtype=dtype)
            H[:3, :3] = M
            H[:3, 3] = [1.0, -2.0, 3.0]
            T = jl.SE3.from_matrix(H)
            want = np.asarray(jl.SO3.from_matrix(M).wxyz)
            assert np.array_equal(np.asarray(T.rotation().wxyz), want)
    assert worst <= 4.0, f"{worst:.1f} ulp"


def test_from_matrix_batched_and_jitted():
    """``from_matrix`` under jit on a (4, 5) batch gives back the matrices."""
    rng = np.random.default_rng(0)
    T = jl.SO3.exp(rng.normal(size=(4, 5, 3)))
    M = T.as_matrix()
    back = jax.jit(jl.SO3.from_matrix)(M)
    assert back.get_batch_axes() == (4, 5)
    np.testing.assert_allclose(back.as_matrix(), M, atol=1e-12)
