"""jaxlie_geo.manifold: right ⊕ and ⊖ on pytrees that mix group elements and arrays,
tangent-space gradients, and the Jacobian of ⊕ with respect to the parameters.

References: the group operations themselves (T ⊕ δ = T exp(δ), a ⊖ b = log(a⁻¹ b)),
``jax.jacfwd`` of ⊕ for its Jacobian, and jaxlie 1.5's ``manifold`` module run side by side
on the same pytrees, array leaves included.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import jaxlie as jaxlie_ref  # the test extra installs it; never skipped
import numpy as np
from conftest import (
    assert_close,
    assert_close_compat,
    over_dtypes,
    over_groups,
    random_element,
    random_tangent,
    to_np,
)

import jaxlie_geo
from jaxlie_geo import manifold

# ---------------------------------------------------------------------------------
# Against the group operations.


@over_groups
def test_rplus_and_rminus_are_the_group_operations(G):
    """On group leaves, ``rplus(T, δ)`` is ``T @ exp(δ)`` and ``rminus(a, b)`` is
    ``log(a⁻¹ b)``, so ``rplus(a, rminus(a, b)) == b``; ``zero_tangents`` gives zeros of the
    tangent shape; ``rplus_jacobian_parameters_wrt_delta(T)`` is ``jax.jacfwd`` of
    δ ↦ (T ⊕ δ).parameters() at 0. Batch (3,), float64."""
    dtype = np.float64
    a, b = random_element(G, 1, (3,), dtype), random_element(G, 2, (3,), dtype)
    delta = random_tangent(G, 3, (3,), dtype, max_angle=2.0)
    assert_close(manifold.rplus(a, delta).parameters(), (a @ G.exp(delta)).parameters(), dtype)
    d = manifold.rminus(a, b)
    assert_close(d, (a.inverse() @ b).log(), dtype)
    assert_close(manifold.rplus(a, d).as_matrix(), b.as_matrix(), dtype, 8)
    np.testing.assert_array_equal(to_np(manifold.zero_tangents(a)), np.zeros((3, G.tangent_dim)))
    T = a[0]
    J = manifold.rplus_jacobian_parameters_wrt_delta(T)
    want = jax.jacfwd(lambda x: manifold.rplus(T, x).parameters())(jnp.zeros(G.tangent_dim))
    assert J.shape == (G.parameters_dim, G.tangent_dim)
    assert_close(J, want, dtype, 4)


# ---------------------------------------------------------------------------------
# Side by side with jaxlie.


def _tree(lib, params):
    """The same pytree (dict/list/tuple mixing groups and arrays) in either library."""
    return {
        "pose": lib.SE3(params["se3"]),
        "planar": [lib.SE2(params["se2"]), lib.SO2(params["so2"])],
        "rot": (lib.SO3(params["so3"]),),
        "bias": params["bias"],
    }


def _params(dtype):
    L = jaxlie_geo
    return {
        "se3": np.asarray(random_element(L.SE3, 1, (2,), dtype).parameters()),
        "se2": np.asarray(random_element(L.SE2, 2, (), dtype).parameters()),
        "so2": np.asarray(random_element(L.SO2, 3, (3,), dtype).parameters()),
        "so3": np.asarray(random_element(L.SO3, 4, (), dtype).parameters()),
        "bias": np.linspace(-1, 1, 5).astype(dtype),
    }


_ELEMENT = (jaxlie_geo.MatrixLieGroup, jaxlie_ref.MatrixLieGroup)


def _flat(tree):
    """The leaves of ``tree`` as numpy arrays (an element's leaf: its parameters)."""
    leaves = jax.tree.leaves(tree, is_leaf=lambda x: isinstance(x, _ELEMENT))
    return [to_np(x.parameters() if isinstance(x, _ELEMENT) else x) for x in leaves]


def _cost(lib):
    def cost(tree, target):
        pose = tree["pose"]
        r1 = (pose.inverse() @ target["pose"]).log()
        r2 = tree["planar"][0].log() * jnp.sum(tree["bias"])
        r3 = (tree["planar"][1] @ target["planar"][1].inverse()).log()
        r4 = tree["rot"][0].apply(jnp.array([1.0, 2.0, 3.0], tree["bias"].dtype))
        return jnp.sum(r1**2) + jnp.sum(r2**2) + jnp.sum(r3**2) + jnp.sum(jnp.sin(r4))

    return cost


@over_dtypes
def test_manifold_side_by_side(dtype):
    """The same pytree (SE3, SE2, SO2, SO3 leaves and an array) through both libraries'
    ``zero_tangents``, ``rminus``, ``rplus``, ``normalize_all``, the parameter Jacobian of ⊕,
    ``grad`` and ``value_and_grad`` (argnums tuples and ``has_aux`` too) gives the same
    values at the jaxlie tolerance, array leaves of ⊖ included (a − b, as in jaxlie)."""
    P, Q = _params(dtype), {k: v for k, v in _params(dtype).items()}
    Q["se3"] = np.asarray(random_element(jaxlie_geo.SE3, 9, (2,), dtype).parameters())
    Q["so2"] = np.asarray(random_element(jaxlie_geo.SO2, 8, (3,), dtype).parameters())
    ours, ref = _tree(jaxlie_geo, P), _tree(jaxlie_ref, P)
    ours_b, ref_b = _tree(jaxlie_geo, Q), _tree(jaxlie_ref, Q)

    def same(a, b, what):
        fa, fb = _flat(a), _flat(b)
        assert len(fa) == len(fb), what
        for x, y in zip(fa, fb):
            assert_close_compat(x, y, dtype, msg=what)

    same(
        jaxlie_geo.manifold.zero_tangents(ours),
        jaxlie_ref.manifold.zero_tangents(ref),
        "zero_tangents",
    )
    delta = jaxlie_ref.manifold.rminus(ref, ref_b)
    same(jaxlie_geo.manifold.rminus(ours, ours_b), delta, "rminus")
    delta_np = jax.tree.map(np.asarray, delta)
    same(jaxlie_geo.manifold.rplus(ours, delta_np), jaxlie_ref.manifold.rplus(ref, delta), "rplus")
    same(
        jaxlie_geo.manifold.normalize_all(ours),
        jaxlie_ref.manifold.normalize_all(ref),
        "normalize_all",
    )
    # Array leaves: a − b, jaxlie's convention, beside the group leaves' log(a⁻¹ b).
    a = {"x": np.array([1.0, 3.0], dtype), "T": ours["pose"]}
    b = {"x": np.array([0.5, -1.0], dtype), "T": ours_b["pose"]}
    d = jaxlie_geo.manifold.rminus(a, b)
    jaxlie_d = jaxlie_ref.manifold.rminus(
        {"x": a["x"], "T": ref["pose"]}, {"x": b["x"], "T": ref_b["pose"]}
    )
    np.testing.assert_array_equal(to_np(d["x"]), to_np(jaxlie_d["x"]))
    np.testing.assert_array_equal(to_np(d["x"]), a["x"] - b["x"])
    assert_close_compat(d["T"], jaxlie_d["T"], dtype, msg="rminus on the group leaf")
    back = jaxlie_geo.manifold.rplus(a, d)
    np.testing.assert_array_equal(to_np(back["x"]), 2 * a["x"] - b["x"])  # as documented
    assert_close_compat(back["T"].as_matrix(), b["T"].as_matrix(), dtype, msg="rplus(rminus)")
    for T, TR in (
        (ours["pose"], ref["pose"]),
        (ours["rot"][0], ref["rot"][0]),
        (ours["planar"][1], ref["planar"][1]),
    ):
        assert_close_compat(
            jaxlie_geo.manifold.rplus_jacobian_parameters_wrt_delta(T),
            jaxlie_ref.manifold.rplus_jacobian_parameters_wrt_delta(TR),
            dtype,
        )
    g_ours = jaxlie_geo.manifold.grad(_cost(jaxlie_geo))(ours, ours_b)
    g_ref = jaxlie_ref.manifold.grad(_cost(jaxlie_ref))(ref, ref_b)
    same(g_ours, g_ref, "grad")
    (v_ours, g2), (v_ref, _) = (
        jaxlie_geo.manifold.value_and_grad(_cost(jaxlie_geo))(ours, ours_b),
        jaxlie_ref.manifold.value_and_grad(_cost(jaxlie_ref))(ref, ref_b),
    )
    assert_close_compat(v_ours, v_ref, dtype)
    same(g2, g_ours, "value_and_grad")
    # argnums as a tuple, as in jaxlie
    ga = jaxlie_geo.manifold.grad(_cost(jaxlie_geo), argnums=(0, 1))(ours, ours_b)
    gr = jaxlie_ref.manifold.grad(_cost(jaxlie_ref), argnums=(0, 1))(ref, ref_b)
    same(ga, gr, "grad argnums")

    # has_aux: (gradient, aux) from grad, ((value, aux), gradient) from value_and_grad
    def with_aux(lib):
        return lambda a, b: (_cost(lib)(a, b), {"tag": _cost(lib)(a, a)})

    (g_aux, aux), (g_aux_ref, aux_ref) = (
        jaxlie_geo.manifold.grad(with_aux(jaxlie_geo), has_aux=True)(ours, ours_b),
        jaxlie_ref.manifold.grad(with_aux(jaxlie_ref), has_aux=True)(ref, ref_b),
    )
    same(g_aux, g_aux_ref, "grad has_aux")
    assert_close_compat(aux["tag"], aux_ref["tag"], dtype)
    (v3, aux3), g3 = jaxlie_geo.manifold.value_and_grad(with_aux(jaxlie_geo), has_aux=True)(
        ours, ours_b
    )
    assert_close_compat(v3, v_ref, dtype)
    assert_close_compat(aux3["tag"], aux_ref["tag"], dtype)
    same(g3, g_ref, "value_and_grad has_aux")
