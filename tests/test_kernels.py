"""The structure of the compiled programs: what the kernels are made of, at what precision
they multiply, and which kernel a batch takes.

References: the jaxprs themselves (walked equation by equation, sub-jaxprs included), and
for the kernel choice the per-element path (``vmap``) and the other kernel on the same
inputs.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from conftest import (
    key_of,
    over_dtypes,
    over_groups,
    over_quaternion_groups,
    random_element,
    random_points,
    random_tangent,
    to_np,
)

from jaxlie_geo import jacobians, uncertainty


def _all_eqns(jaxpr):
    """Every equation, those of sub-jaxprs (jit, custom_jvp, cond, while, ...) included."""
    out = []
    for eqn in jaxpr.eqns:
        out.append(eqn)
        for param in eqn.params.values():
            subs = param if isinstance(param, (list, tuple)) else [param]
            for sub in subs:
                inner = getattr(sub, "jaxpr", None)
                if inner is not None:
                    out += _all_eqns(getattr(inner, "jaxpr", inner))
    return out


def _all_avals(jaxpr):
    """Every intermediate's abstract value, sub-jaxprs included."""
    return [v.aval for eqn in _all_eqns(jaxpr) for v in eqn.outvars]


@over_quaternion_groups
def test_no_matrix_intermediates_in_the_kernels(G):
    """exp, log, compose, apply, inverse and interpolate of the quaternion groups are
    quaternion algebra and cross products: no (…, 3, 3) or (…, 4, 4) array appears in their
    jaxprs."""
    T = random_element(G, 1, (5,), jnp.float32)
    x = random_tangent(G, 1, (5,), jnp.float32)
    p = random_points(G, 1, (5,), jnp.float32)
    ops = {
        "exp": lambda x: G.exp(x).parameters(),
        "log": lambda T: T.log(),
        "compose": lambda T: (T @ T).parameters(),
        "apply": lambda T: T @ p,
        "inverse": lambda T: T.inverse().parameters(),
        "interpolate": lambda T: T.interpolate(T[::-1], 0.3).parameters(),
    }
    for name, f in ops.items():
        arg = x if name == "exp" else T
        avals = _all_avals(jax.make_jaxpr(f)(arg).jaxpr)
        assert avals, name
        matrices = [
            a.shape
            for a in avals
            if len(getattr(a, "shape", ())) >= 2 and a.shape[-2:] in ((3, 3), (4, 4))
        ]
        assert matrices == [], (name, matrices)
    # the check can fail: as_matrix does build 3x3 blocks
    avals = _all_avals(jax.make_jaxpr(lambda T: T.as_matrix())(T).jaxpr)
    assert any(len(a.shape) >= 2 and a.shape[-2:] in ((3, 3), (4, 4)) for a in avals)


@over_groups
def test_matrix_products_at_full_precision(G):
    """Every ``dot_general`` in the library runs at ``Precision.HIGHEST`` (``_xla.matmul``):
    on GPUs a float32 dot at JAX's default precision runs in TF32, about 1e-3 relative
    error (seen on an H100: SE3 ``propagate_compose`` lost its symmetry at that level).
    Walks the jaxprs of every method and module function that builds or multiplies
    matrices, and of derivatives through them."""
    T = random_element(G, 2, (4,), jnp.float32)
    x = random_tangent(G, 2, (4,), jnp.float32)
    p = random_points(G, 2, (4,), jnp.float32)
    cov = np.eye(G.tangent_dim, dtype=np.float32) * 1e-2
    fns = {
        "adjoint": lambda T, x: T.adjoint(),
        "jlog": lambda T, x: T.jlog(),
        "jacs": lambda T, x: (
            G.jac_right(x),
            G.jac_left(x),
            G.jac_right_inv(x),
            G.jac_left_inv(x),
            G.ad(x),
        ),
        "as/from_matrix": lambda T, x: G.from_matrix(T.as_matrix()).parameters(),
        "jacobians": lambda T, x: (
            jacobians.compose(T, T),
            jacobians.inverse(T),
            jacobians.between(T, T),
            jacobians.rminus(T, T),
            jacobians.rplus(T, x),
            jacobians.exp(G, x),
            jacobians.log(T),
            jacobians.apply(T, p),
        ),
        "uncertainty": lambda T, x: (
            uncertainty.propagate_compose(T, cov, T, cov, cov),
            uncertainty.propagate_inverse(T, cov),
            uncertainty.propagate_apply(T, cov, p, np.eye(G.space_dim)),
            uncertainty.sample(key_of(0), T, cov).parameters(),
            uncertainty.mean(T).parameters(),
        ),
        "d/dx": lambda T, x: jax.jacfwd(lambda x: (T @ G.exp(x)).log())(x),
        "grad": lambda T, x: jax.grad(
            lambda x: jnp.sum(G.exp(x).inverse().apply(p) + G.jac_right(x).sum())
        )(x),
    }
    found = 0
    for name, f in fns.items():
        eqns = _all_eqns(jax.make_jaxpr(f)(T, x).jaxpr)
        assert eqns, name
        dots = [e for e in eqns if e.primitive.name == "dot_general"]
        low = [str(e) for e in dots if e.params["precision"] != (jax.lax.Precision.HIGHEST,) * 2]
        assert low == [], (name, low[:1])
        found += len(dots)
    assert found > 0  # the walk sees the products (SE3's adjoint has one at least)


@over_quaternion_groups
@over_dtypes
def test_exp_path_choice_is_invisible(G, dtype):
    """The quaternion groups' exp picks its kernel per batch (``_so3.by_angle``): one element
    far beyond π sends the whole batch through the compensated θ² kernel. Both kernels, and
    vmap (where the choice becomes a select, always compensated), agree within 4 eps on the
    angles below π, and within 0.5 eps just past the threshold."""
    small = random_tangent(G, 3, (512,), dtype)  # angles below π: the plain kernel
    big = random_tangent(G, 4, (1,), dtype, max_angle=30.0)
    big[..., -3:] *= 30.0 / np.linalg.norm(big[..., -3:], axis=-1, keepdims=True)
    alone = to_np(G.exp(small).parameters())
    mixed = to_np(G.exp(np.concatenate([small, big])).parameters())
    # vmap and a batch under _BY_ANGLE_MIN_BATCH: the compensated kernel.
    mapped = to_np(jax.vmap(lambda x: G.exp(x).parameters())(small))
    few = to_np(G.exp(small[:8]).parameters())
    eps = float(jnp.finfo(dtype).eps)
    scale = np.maximum(1.0, np.max(np.abs(alone), axis=-1, keepdims=True))
    # Both kernels are exact to a few ulp (test_accuracy); they may round differently.
    assert np.max(np.abs(mixed[:-1] - alone) / scale) <= 4 * eps
    assert np.max(np.abs(mapped - alone) / scale) <= 4 * eps
    assert np.max(np.abs(few - alone[:8]) / scale[:8]) <= 4 * eps
    # The big element takes the compensated path either way (its accuracy beyond π is
    # tests/test_accuracy.py's "beyond_pi" regime, whose batches hold only such angles).
    np.testing.assert_array_equal(mixed[-1:], to_np(G.exp(big).parameters()))
    # Just past the threshold (θ² in (10, 40)) a whole batch takes the compensated kernel:
    # its quaternions agree with the per-element path (vmap: always compensated) to 0.5 eps;
    # the plain kernel there (the threshold 4x too high) differs by 1.5 eps.
    edge = random_tangent(G, 7, (512,), dtype)
    rot = edge[..., -3:]
    theta = np.sqrt(np.random.default_rng(7).uniform(10.0, 40.0, (512, 1)))
    edge[..., -3:] = (rot / np.linalg.norm(rot, axis=-1, keepdims=True) * theta).astype(dtype)
    batch = to_np(G.exp(edge).parameters()[..., :4])
    each = to_np(jax.vmap(lambda x: G.exp(x).parameters()[..., :4])(edge))
    assert np.max(np.abs(batch - each)) <= 0.5 * eps


@over_quaternion_groups
@over_dtypes
def test_exp_derivative_takes_one_kernel(G, dtype):
    """by_angle's custom JVP: a gradient through a large batch differentiates the
    compensated kernel alone (no cond to compile and transpose twice), and equals the
    per-element gradient (vmap, which never takes the batch-level choice)."""
    xi = random_tangent(G, 5, (512,), dtype)
    w = random_tangent(G, 6, (512,), dtype)  # weights for all but qw (tangent_dim of them)

    def loss(x, w):
        return jnp.sum(w * G.exp(x).parameters()[..., 1:])

    forward = str(jax.make_jaxpr(loss)(xi, w))
    backward = str(jax.make_jaxpr(jax.grad(loss))(xi, w))
    assert "cond[" in forward  # the choice is there on the forward pass (CPU) ...
    assert "cond[" not in backward  # ... and not under differentiation
    eps = float(jnp.finfo(dtype).eps)
    np.testing.assert_allclose(
        to_np(jax.grad(loss)(xi, w)), to_np(jax.vmap(jax.grad(loss))(xi, w)), rtol=0, atol=16 * eps
    )
