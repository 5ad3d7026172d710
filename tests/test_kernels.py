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
    LAYOUT,
    has_scale,
    key_of,
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


_BRANCHES = ("cond", "while", "platform_index", "all_reduce", "psum")


@over_groups
def test_exp_and_log_are_one_elementwise_kernel(G):
    """exp and log, and their gradients, are one elementwise kernel: no batch-level branch,
    loop or platform switch in the jaxpr (an element's result depends on that
    element alone), and an element gives the same bits alone, in a batch of small angles
    and in a batch that also holds angles far beyond π."""
    x = random_tangent(G, 3, (512,), np.float32)
    p = G.exp(x).parameters()

    def loss(x):
        return jnp.sum(G.exp(x).log() ** 2)

    for name, f, arg in (
        ("exp", lambda x: G.exp(x).parameters(), x),
        ("log", lambda p: G(p).log(), p),
        ("grad", jax.grad(loss), x),
    ):
        found = {e.primitive.name for e in _all_eqns(jax.make_jaxpr(f)(arg).jaxpr)}
        assert not found & set(_BRANCHES), (name, found & set(_BRANCHES))
    big = random_tangent(G, 4, (4,), np.float32)
    rot = LAYOUT[G][0]
    big[..., rot] *= 1e3 / np.linalg.norm(big[..., rot], axis=-1, keepdims=True)
    alone = to_np(G.exp(x).parameters())
    mixed = to_np(G.exp(np.concatenate([x, big])).parameters())
    if has_scale(G):
        # Sim(3): 3 of 4096 float32 entries of t differ by one ulp between the two batch
        # sizes (the cause, inside XLA:CPU's compilation of the longer kernel, not traced).
        np.testing.assert_allclose(mixed[:-4], alone, rtol=2 * np.finfo(np.float32).eps, atol=0)
    else:
        np.testing.assert_array_equal(mixed[:-4], alone)
    np.testing.assert_array_equal(to_np(G.exp(x[:3]).parameters()), alone[:3])
