"""jaxlie 1.5 code run with `import jaxlie_geo as jaxlie` gives jaxlie's results.

Each test runs the same user code against both libraries (passed as a module) and compares
as matrices (per-dtype tolerance), draws, signs and shapes. Where jaxlie is known to be
inaccurate (small-angle SE3 Jacobians), the comparison is left to tests/test_accuracy.py.
"""

import jax
import jax.numpy as jnp
import jaxlie as jaxlie_ref
import numpy as np
import pytest

import jaxlie_geo

jax.config.update("jax_enable_x64", True)

NAMES = ["SO2", "SE2", "SO3", "SE3"]


def user_code(jaxlie, dtype):
    """A realistic sample of jaxlie 1.5 usage (README-style)."""
    out = {}
    T_w_b = jaxlie.SE3.from_rotation_and_translation(
        jaxlie.SO3.from_rpy_radians(0.3, -0.2, 1.1), jnp.array([1.0, 2.0, 3.0], dtype)
    )
    p_b = jnp.array([[0.5, -1.0, 2.0], [1.0, 0.0, 0.0]], dtype)
    out["apply"] = T_w_b @ p_b
    out["inverse"] = T_w_b.inverse().as_matrix()
    out["log"] = T_w_b.log()
    out["exp_log"] = jaxlie.SE3.exp(T_w_b.log()).as_matrix()
    out["adjoint"] = T_w_b.adjoint()
    out["jlog"] = T_w_b.jlog()
    out["rpy"] = jnp.stack(T_w_b.rotation().as_rpy_radians())
    out["xyzw"] = T_w_b.rotation().as_quaternion_xyzw()
    out["from_xyzw"] = jaxlie.SO3.from_quaternion_xyzw(jnp.array([0.1, 0.2, 0.3, 0.9], dtype)).as_matrix()
    out["so2"] = jaxlie.SO2.from_radians(jnp.array(0.7, dtype)).as_matrix()
    out["so2_rad"] = jaxlie.SO2.from_radians(jnp.array(2.5, dtype)).as_radians()
    out["se2"] = jaxlie.SE2.from_xy_theta(1.0, -2.0, 0.4).as_matrix()
    out["se2_log"] = jaxlie.SE2.from_xy_theta(1.0, -2.0, 0.4).log()
    out["from_matrix"] = jaxlie.SE3.from_matrix(T_w_b.as_matrix()).as_matrix()
    out["identity"] = jaxlie.SE3.identity((2, 3)).parameters()
    out["from_translation"] = jaxlie.SE2.from_translation(jnp.array([1.0, 2.0], dtype)).as_matrix()
    out["from_rotation"] = jaxlie.SE3.from_rotation(jaxlie.SO3.from_z_radians(0.3)).as_matrix()
    out["normalize"] = jaxlie.SO3(jnp.array([2.0, 0.0, 0.0, 0.0], dtype)).normalize().wxyz
    # Optimisation on the manifold, as in jaxlie's docs.
    target = jaxlie.SE3.exp(jnp.array([0.1, 0.2, 0.3, 0.3, -0.1, 0.2], dtype))

    def loss(T):
        return jnp.sum(jaxlie.manifold.rminus(T, target) ** 2)

    T0 = jaxlie.SE3.exp(jnp.array([0.0, 0.1, 0.0, 0.2, 0.1, 0.0], dtype))
    out["grad"] = jaxlie.manifold.grad(loss)(T0)
    value, g = jaxlie.manifold.value_and_grad(loss)(T0)
    out["value"] = value
    out["rplus"] = jaxlie.manifold.rplus(T0, g).parameters()
    tree = {"pose": T0, "x": jnp.ones(2, dtype)}
    out["zero_tangents"] = jax.tree.leaves(jaxlie.manifold.zero_tangents(tree))
    out["normalize_all"] = jaxlie.manifold.normalize_all(tree)["pose"].parameters()
    out["rplus_jac"] = jaxlie.manifold.rplus_jacobian_parameters_wrt_delta(T0)
    out["eps"] = jnp.array([jaxlie.utils.get_epsilon(jnp.dtype("float32")), jaxlie.utils.get_epsilon(jnp.dtype("float64"))])
    a, b = jaxlie.utils.broadcast_leading_axes((jaxlie.SO3.identity((3, 1)), jnp.zeros((1, 4, 3))))
    out["broadcast"] = jnp.array([*a.get_batch_axes(), *b.shape])
    return out


@pytest.mark.parametrize("dtype", [jnp.float32, jnp.float64])
def test_user_code_same_results(dtype):
    ours, theirs = user_code(jaxlie_geo, dtype), user_code(jaxlie_ref, dtype)
    tol = 2e-5 if dtype == jnp.float32 else 1e-12
    for key in theirs:
        a, b = ours[key], theirs[key]
        if isinstance(a, list):
            assert len(a) == len(b)
            for x, y in zip(a, b):
                np.testing.assert_allclose(np.asarray(x), np.asarray(y), atol=tol, err_msg=key)
            continue
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), atol=tol * 10, err_msg=key)


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("batch", [(), (5,), (2, 3)])
def test_sample_uniform_same_draws(name, batch):
    key = jax.random.key(7)
    ours = getattr(jaxlie_geo, name).sample_uniform(key, batch_axes=batch)
    theirs = getattr(jaxlie_ref, name).sample_uniform(key, batch_axes=batch)
    np.testing.assert_array_equal(np.asarray(ours.parameters()), np.asarray(theirs.parameters()))


@pytest.mark.parametrize("name", NAMES)
def test_class_attributes_and_layout(name):
    ours, theirs = getattr(jaxlie_geo, name), getattr(jaxlie_ref, name)
    for attr in ("matrix_dim", "parameters_dim", "tangent_dim", "space_dim"):
        assert getattr(ours, attr) == getattr(theirs, attr)
    x = np.random.default_rng(0).normal(size=(4, ours.tangent_dim)) * 0.5
    np.testing.assert_allclose(ours.exp(x).parameters(), theirs.exp(x).parameters(), atol=1e-12)
    np.testing.assert_allclose(ours.exp(x).as_matrix(), theirs.exp(x).as_matrix(), atol=1e-12)


def test_quaternion_sign_never_flipped():
    q = -jnp.array([0.9, 0.1, -0.3, 0.2])
    R = jaxlie_geo.SO3(q)
    np.testing.assert_array_equal(np.asarray((R @ jaxlie_geo.SO3.identity()).wxyz), np.asarray(q))
    np.testing.assert_array_equal(np.asarray(jaxlie_geo.SO3.from_quaternion_xyzw(jnp.roll(q, -1)).wxyz), np.asarray(q))
    T = jaxlie_geo.SE3.from_rotation_and_translation(R, jnp.zeros(3))
    np.testing.assert_array_equal(np.asarray(T.rotation().wxyz), np.asarray(q))
    theirs = jaxlie_ref.SO3(q) @ jaxlie_ref.SO3.identity()
    np.testing.assert_allclose(np.asarray((R @ jaxlie_geo.SO3.identity()).wxyz), np.asarray(theirs.wxyz))
