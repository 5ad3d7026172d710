"""JAX transformations on every group: jit, vmap, grad, jacfwd, jacrev, hessian, scan,
eval_shape and pytree manipulation.

Derivatives are checked against central finite differences in float64; jit against eager
calls; vmap against the batched call; the constructor must accept any leaf (tracers,
ShapeDtypeStructs, shapes, axis specs).
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import (
    GROUPS,
    LAYOUT,
    assert_close,
    is_se,
    over_groups,
    over_groups_dtypes,
    over_groups_float64,
    over_seeds,
    random_element,
    random_points,
    random_tangent,
    to_np,
)

import jaxlie_geo
from jaxlie_geo import SE2, SO3


def _central_diff(f, x, h):
    """Jacobian of f at x (float64 numpy) by central differences: (*out, *x.shape)."""
    x = np.asarray(x, np.float64)
    f0 = np.asarray(f(x))
    J = np.zeros((*f0.shape, x.size))
    for i in range(x.size):
        e = np.zeros(x.size)
        e[i] = h
        e = e.reshape(x.shape)
        J[..., i] = (np.asarray(f(x + e)) - np.asarray(f(x - e))) / (2 * h)
    return J.reshape(*f0.shape, *x.shape)


_CACHE = {}


def cached_jit(key, build):
    """``jax.jit(build())``, built once per key. Eager autodiff through the library's
    jitted methods recompiles its derived computations on every call, so every derivative
    below is jitted once per group (and reused by every seed)."""
    if key not in _CACHE:
        _CACHE[key] = jax.jit(build())
    return _CACHE[key]


def _pipeline(G):
    """A scalar loss through exp, compose, inverse, apply and log."""

    def loss(x, T, U, p):
        V = T @ G.exp(x) @ U.inverse()
        w = jnp.arange(1, G.tangent_dim + 1, dtype=x.dtype)
        return jnp.sum(w * V.log()) + jnp.sum(jnp.sin(V @ p)) + jnp.sum(V.log() ** 2)

    return loss


# ---------------------------------------------------------------------------------
# jit


@over_groups_dtypes
@over_seeds
def test_jit_equals_eager(G, dtype, seed):
    """log, compose with an inverse, apply, jlog and interpolate under jit equal the eager
    calls, with the input dtype."""
    T = random_element(G, seed, (3,), dtype)
    U = random_element(G, seed + 1, (3,), dtype)
    x = random_tangent(G, seed, (3,), dtype)
    p = random_points(G, seed, (3,), dtype)

    def f(T, U, x, p):
        V = T @ G.exp(x)
        return (
            V.log(),
            (V @ U.inverse()).parameters(),
            V @ p,
            V.jlog(),
            T.interpolate(U, 0.3).parameters(),
        )

    eager = f(T, U, x, p)
    jitted = cached_jit(("jit_equals_eager", G), lambda: f)(T, U, x, p)
    for a, b in zip(eager, jitted):
        assert a.dtype == b.dtype == dtype
        assert_close(b, a, dtype, 4)


# ---------------------------------------------------------------------------------
# vmap


@over_groups_dtypes
@over_seeds
def test_vmap_equals_batched_call(G, dtype, seed):
    """vmap over the batch equals the batched call, and an unbatched element mapped against
    batched tangents and points equals the broadcast call."""
    T = random_element(G, seed, (3,), dtype)
    x = random_tangent(G, seed, (3,), dtype)
    p = random_points(G, seed, (3,), dtype)

    def f(T, x, p):
        V = T @ G.exp(x)
        return V.log(), V @ p, V.inverse().parameters()

    batched = f(T, x, p)
    mapped = cached_jit(("vmap", G), lambda: jax.vmap(f))(T, x, p)
    for a, b in zip(batched, mapped):
        assert b.dtype == dtype
        assert_close(b, a, dtype, 4)
    # an unbatched element mapped against batched tangents
    T0 = T[0]
    mapped0 = cached_jit(("vmap0", G), lambda: jax.vmap(f, in_axes=(None, 0, 0)))(T0, x, p)
    for a, b in zip(f(T0, x, p), mapped0):
        assert_close(b, a, dtype, 4)


@over_groups_dtypes
def test_vmap_with_group_instance_as_axis_spec(G, dtype):
    """in_axes/out_axes given as a group instance with integer leaves (the constructor must
    not validate)."""
    T = random_element(G, 1, (2, 4), dtype)
    p = random_points(G, 1, (4, 2), dtype)
    # map over the second batch axis of T (parameters axis 1) and the first of p
    out = jax.vmap(lambda T, p: T @ p, in_axes=(G(1), 0))(T, p)
    assert out.shape == (4, 2, G.space_dim)
    want = np.swapaxes(to_np(T @ np.swapaxes(p, 0, 1)), 0, 1)
    assert_close(out, want, dtype, 2)
    # out_axes as a group spec: put the mapped axis second
    x = random_tangent(G, 1, (4, 2), dtype)
    E = jax.vmap(G.exp, out_axes=G(1))(x)
    assert E.get_batch_axes() == (2, 4)
    assert_close(E.parameters(), np.swapaxes(to_np(G.exp(x).parameters()), 0, 1), dtype)


# ---------------------------------------------------------------------------------
# Derivatives against finite differences (float64).


@over_groups
@over_seeds
def test_grad_matches_finite_differences(G, seed):
    """The gradient of a loss through exp, compose, inverse, apply and log, with respect to the
    tangent, both elements' raw parameters and the points, equals central differences
    (float64)."""
    dtype = jnp.float64
    T = random_element(G, seed, (), dtype)
    U = random_element(G, seed + 1, (), dtype)
    x = random_tangent(G, seed, (), dtype, max_angle=2.5)
    p = random_points(G, seed, (), dtype)
    loss = cached_jit(("loss", G), lambda: _pipeline(G))
    grads = cached_jit(("grad_all", G), lambda: jax.grad(_pipeline(G), argnums=(0, 1, 2, 3)))
    g, gT, gU, gp = grads(x, T, U, p)
    fd = _central_diff(lambda y: loss(y, T, U, p), x, 1e-6)
    np.testing.assert_allclose(to_np(g), fd, rtol=1e-6, atol=1e-7)
    # gradient with respect to the raw parameters of T and U, and to the points
    assert isinstance(gT, G) and isinstance(gU, G)
    for P, gP, rebuild in (
        (T.parameters(), gT.parameters(), lambda q: loss(x, G(q), U, p)),
        (U.parameters(), gU.parameters(), lambda q: loss(x, T, G(q), p)),
        (p, gp, lambda q: loss(x, T, U, q)),
    ):
        fd = _central_diff(rebuild, to_np(P), 1e-6)
        np.testing.assert_allclose(to_np(gP), fd, rtol=1e-6, atol=1e-7)


@over_groups
@over_seeds
def test_jacfwd_jacrev_agree_with_finite_differences(G, seed):
    """Forward and reverse mode Jacobians of exp, compose, log and apply agree to rounding and
    equal central differences (float64)."""
    dtype = jnp.float64
    T = random_element(G, seed, (), dtype)
    x = random_tangent(G, seed, (), dtype, max_angle=2.5)
    p = random_points(G, seed, (), dtype)

    def f(x, T, p):
        V = T @ G.exp(x)
        return jnp.concatenate([V.log(), V @ p, V.parameters()])

    Jf = cached_jit(("jacfwd", G), lambda: jax.jacfwd(f))(x, T, p)
    Jr = cached_jit(("jacrev", G), lambda: jax.jacrev(f))(x, T, p)
    fd = _central_diff(lambda y: f(y, T, p), x, 1e-6)
    np.testing.assert_allclose(to_np(Jf), to_np(Jr), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(to_np(Jf), fd, rtol=1e-6, atol=1e-7)


def _weighted_log(G):
    """x, T ↦ Σ wᵢ log(T exp(x))ᵢ: with T = I it is linear in x (log∘exp = id for
    |angle| < π), so its Hessian must vanish there."""

    def g(x, T):
        w = jnp.arange(1, G.tangent_dim + 1, dtype=x.dtype)
        return jnp.sum(w * (T @ G.exp(x)).log())

    return g


def _grad_and_hessian(G):
    # Second derivatives of the SE(3) kernels take seconds to compile: one function per
    # group, shared by the tests below (float64 only).
    g = _weighted_log(G)
    return cached_jit(
        ("grad_hessian", G), lambda: lambda x, T: (g(x, T), jax.grad(g)(x, T), jax.hessian(g)(x, T))
    )


@over_groups
@over_seeds
def test_hessian_consistency(G, seed):
    """jax.hessian is symmetric and equals central differences of jax.grad, which equals
    central differences of the value."""
    dtype = jnp.float64
    T = random_element(G, seed, (), dtype)
    x = random_tangent(G, seed, (), dtype, max_angle=2.5)
    f = _grad_and_hessian(G)
    _, g, H = f(x, T)
    np.testing.assert_allclose(to_np(H), to_np(H).T, rtol=1e-9, atol=1e-9)
    fd_g = _central_diff(lambda y: f(y, T)[0], x, 1e-6)
    np.testing.assert_allclose(to_np(g), fd_g, rtol=1e-6, atol=1e-7)
    fd_H = _central_diff(lambda y: f(y, T)[1], x, 1e-5)
    np.testing.assert_allclose(to_np(H), fd_H, rtol=1e-5, atol=1e-6)


@over_groups
def test_grad_through_interpolation_time(G):
    """d/dt of interpolate equals central differences at t = 0, 0.4, 1 and 1.6, and the same
    derivative through a ``geodesic`` passed to jit as a pytree."""
    dtype = jnp.float64
    T = random_element(G, 3, (), dtype)
    U = T @ G.exp(random_tangent(G, 3, (), dtype, max_angle=2.0))

    def f(t, T, U):
        return jnp.sum(jnp.cos(T.interpolate(U, t).parameters()))

    df = cached_jit(("dinterp", G), lambda: jax.grad(f))
    for t in (0.0, 0.4, 1.0, 1.6):
        g = df(np.asarray(t, dtype), T, U)
        fd = (f(t + 1e-6, T, U) - f(t - 1e-6, T, U)) / 2e-6
        np.testing.assert_allclose(float(g), float(fd), rtol=1e-6, atol=1e-8)
    path = jaxlie_geo.geodesic(T, U)
    g = jax.jit(jax.grad(lambda t, path: jnp.sum(jnp.cos(path(t).parameters()))))(
        np.asarray(0.4, dtype), path
    )
    np.testing.assert_allclose(float(g), float(df(np.asarray(0.4, dtype), T, U)), rtol=1e-12)


# ---------------------------------------------------------------------------------
# Derivatives at the delicate points: exactly zero, pure translations, tiny angles.


def _delicate_tangents(G, dtype):
    rot, trans = LAYOUT[G]
    out = [np.zeros(G.tangent_dim)]
    tiny = np.zeros(G.tangent_dim)
    tiny[rot] = 1e-9
    out.append(tiny)
    if is_se(G):
        pure = np.zeros(G.tangent_dim)
        pure[trans] = np.linspace(1.0, 2.0, len(trans))
        out.append(pure)
        big = pure * 100.0
        out.append(big)
    return np.stack(out).astype(dtype)


@over_groups_dtypes
def test_derivatives_of_log_exp_at_zero_and_pure_translation(G, dtype):
    """d log(exp(x))/dx = I (forward and reverse mode), with no NaN, at x = 0, at a 1e-9
    rotation and at pure translations."""
    k = G.tangent_dim
    eps = float(jnp.finfo(dtype).eps)

    def f(x):
        return G.exp(x).log()

    jacs = cached_jit(("log_exp_jacs", G), lambda: lambda x: (jax.jacfwd(f)(x), jax.jacrev(f)(x)))
    for x in _delicate_tangents(G, dtype):
        scale = max(1.0, float(np.max(np.abs(x))))
        for J in jacs(x):
            J = to_np(J)
            assert np.all(np.isfinite(J)), (x, J)
            np.testing.assert_allclose(J, np.eye(k), rtol=0, atol=16 * eps * scale)


@over_groups_float64
def test_hessian_of_log_exp_vanishes_at_zero_and_pure_translation(G, dtype):
    """d²/dx² Σ wᵢ log(exp(x))ᵢ = 0, finite, at the points of the test above (log∘exp is
    the identity below π)."""
    eps = float(jnp.finfo(dtype).eps)
    second = _grad_and_hessian(G)
    I = G.identity(dtype=dtype)
    for x in _delicate_tangents(G, dtype):
        scale = max(1.0, float(np.max(np.abs(x))))
        _, g, H = second(x, I)
        assert np.all(np.isfinite(to_np(g))) and np.all(np.isfinite(to_np(H))), (x, H)
        np.testing.assert_allclose(to_np(H), 0.0, atol=64 * eps * scale, rtol=0)


@over_groups_dtypes
def test_no_nan_gradients_at_identity_and_pure_translation(G, dtype):
    """Gradients of losses through log, jlog, exp and compose at the identity and at
    pure translations (where 0/0 forms lurk) are finite and match finite differences."""
    I = G.identity(dtype=dtype)
    elements = [I]
    if is_se(G):
        elements.append(G.from_translation(np.linspace(0.5, -1.5, G.space_dim).astype(dtype)))

    def loss(q, d):
        return jnp.sum((G(q) @ G.exp(d)).log())

    grads = cached_jit(("nan_grads", G), lambda: jax.grad(loss, argnums=(0, 1)))
    grad_jlog = cached_jit(("nan_grad_jlog", G), lambda: jax.grad(lambda q: jnp.sum(G(q).jlog())))
    zero = np.zeros(G.tangent_dim, dtype)
    for T in elements:
        g_params, g = grads(T.parameters(), zero)
        for gi in (g_params, g):
            assert np.all(np.isfinite(to_np(gi))), gi
        if dtype == jnp.float64:
            assert np.all(np.isfinite(to_np(grad_jlog(T.parameters()))))
        # log(T exp(d)) = log(T) + J d: its gradient in d at 0 is J^T 1 (jlog at T)
        want = to_np(T.jlog()).sum(axis=0)
        assert_close(g, want, dtype, 4)
        if dtype == jnp.float64:
            fd = _central_diff(
                lambda d, T=T: (T @ G.exp(jnp.asarray(d))).log(), np.zeros(G.tangent_dim), 1e-6
            )
            np.testing.assert_allclose(to_np(T.jlog()), fd, rtol=1e-7, atol=1e-8)


# ---------------------------------------------------------------------------------
# Pytree behaviour.


@over_groups_dtypes
def test_tree_map_eval_shape_and_leaves(G, dtype):
    """An element is a pytree of one leaf: tree_map, flatten and unflatten keep the class, and
    ``eval_shape`` of factories and methods gives the documented shapes and dtype."""
    T = random_element(G, 5, (2, 4), dtype)
    shapes = jax.tree.map(lambda a: a.shape, T)
    assert isinstance(shapes, G)
    assert shapes.parameters() == (2, 4, G.parameters_dim)
    leaves, treedef = jax.tree.flatten(T)
    assert len(leaves) == 1 and leaves[0].shape == (2, 4, G.parameters_dim)
    assert isinstance(jax.tree.unflatten(treedef, leaves), G)
    # eval_shape of a factory and of a method
    spec = jax.ShapeDtypeStruct((5, G.tangent_dim), dtype)
    out = jax.eval_shape(G.exp, spec)
    assert isinstance(out, G)
    assert out.parameters().shape == (5, G.parameters_dim)
    assert out.parameters().dtype == dtype
    abstract = G(jax.ShapeDtypeStruct((3, G.parameters_dim), dtype))
    logs = jax.eval_shape(lambda T: T.log(), abstract)
    assert logs.shape == (3, G.tangent_dim) and logs.dtype == dtype
    mats = jax.eval_shape(lambda T, U: (T @ U).as_matrix(), abstract, abstract)
    assert mats.shape == (3, G.matrix_dim, G.matrix_dim) and mats.dtype == dtype


@over_groups_dtypes
def test_pickle_and_copy_round_trip(G, dtype):
    """multiprocessing, checkpoints written with pickle, and ``copy.deepcopy`` of a config
    holding poses: the class, dtype and every parameter bit survive, and the copy is a
    new, still frozen element."""
    import copy
    import pickle

    T = random_element(G, 6, (3,), dtype)
    for U in (pickle.loads(pickle.dumps(T)), copy.deepcopy(T), copy.copy(T)):
        assert type(U) is G and U is not T
        assert U.parameters().dtype == dtype
        np.testing.assert_array_equal(to_np(U.parameters()), to_np(T.parameters()))
        with pytest.raises(dataclasses.FrozenInstanceError):
            setattr(U, dataclasses.fields(G)[0].name, T.parameters())
        assert_close((U @ T.inverse()).log(), np.zeros((3, G.tangent_dim)), dtype)


def test_pytree_structures_name_the_class():
    """Elements of different groups never share a tree structure, so ``jax.jit`` cannot
    serve one group the computation compiled for another. (Classes registered with
    ``jax.tree_util.register_dataclass`` compare equal here when their fields have the same
    layout — jax 0.10.2 — and jit then returned SE2's jlog for an SO3 input.)"""
    x = jnp.zeros(4)
    path = jaxlie_geo.geodesic(SE2.identity(), SE2.identity())
    structures = {G.__name__: jax.tree.structure(G(x)) for G in GROUPS}
    structures.update(
        {
            "Geodesic": jax.tree.structure(path),
            "Geodesic-as-tuple": jax.tree.structure((path.start, path.tangent)),
        }
    )

    @jax.tree_util.register_dataclass
    @dataclasses.dataclass(frozen=True)
    class UserPose:  # a user's own one-field pytree, the same layout as ours
        wxyz: jax.Array

    structures["user"] = jax.tree.structure(UserPose(x))
    names = list(structures)
    for i, a in enumerate(names):
        for b in names[i + 1 :]:
            assert structures[a] != structures[b], (a, b)
    # keyed paths name the field, as for dataclasses
    ((path_, _),) = jax.tree_util.tree_flatten_with_path(SO3(x))[0]
    assert jax.tree_util.keystr(path_) == ".wxyz"

    # jit with one function and the same leaf shapes: each group gets its own result
    @jax.jit
    def tangent_dim_of(T):
        return jnp.zeros(type(T).tangent_dim).sum() + type(T).tangent_dim

    for _ in range(3):
        for G in GROUPS:
            assert int(tangent_dim_of(G(x))) == G.tangent_dim


@over_groups_dtypes
def test_scan_and_cond_carry_group_elements(G, dtype):
    """A trajectory integrated with lax.scan equals the Python loop; lax.cond selects
    between two elements."""
    xs = random_tangent(G, 11, (6,), dtype, max_angle=0.5)
    T0 = random_element(G, 11, (), dtype)

    def step(T, x):
        T = T @ G.exp(x)
        return T, T.parameters()

    T_end, traj = cached_jit(("scan", G), lambda: lambda T0, xs: jax.lax.scan(step, T0, xs))(T0, xs)
    T = T0
    for i in range(6):
        T = T @ G.exp(xs[i])
        assert_close(traj[i], T.parameters(), dtype, 8)
    assert_close(T_end.parameters(), T.parameters(), dtype, 8)
    assert T_end.parameters().dtype == dtype
    chosen = jax.jit(lambda c, a, b: jax.lax.cond(c, lambda: a, lambda: b))(True, T0, T_end)
    assert isinstance(chosen, G)
    np.testing.assert_array_equal(to_np(chosen.parameters()), to_np(T0.parameters()))


@pytest.mark.parametrize("batch_axes", [[2], (2, 3)], ids=["list", "tuple"])
def test_static_batch_axes_accept_lists(batch_axes):
    """``identity`` and ``sample_uniform`` accept batch axes as a list or a tuple, positionally
    and by keyword (a list is not hashable as a static argument as it stands)."""
    for G in (jaxlie_geo.SO3, jaxlie_geo.SE2):
        assert G.identity(batch_axes).get_batch_axes() == tuple(batch_axes)
        assert G.sample_uniform(jax.random.PRNGKey(0), batch_axes).get_batch_axes() == tuple(
            batch_axes
        )
        # by keyword too (a list is not hashable as a static argument as it stands)
        assert G.identity(batch_axes=batch_axes).get_batch_axes() == tuple(batch_axes)
        key = jax.random.PRNGKey(0)
        assert G.sample_uniform(key, batch_axes=batch_axes).get_batch_axes() == tuple(batch_axes)


@over_groups
def test_export_with_a_symbolic_batch(G):
    """``jax.export`` with a symbolic batch size (shape polymorphism, as jaxlie allows):
    every size-dependent choice (the angle-dependent kernel, chunking, broadcast checks)
    takes its default, and the exported function computes what ``jit`` does. In float32,
    the dtype of programs exported without x64 (the shape logic is the same in float64;
    each of these programs compiles twice, in seconds). (jax < 0.6's
    ``jax.export`` imports absl-py, which jax does not declare: skipped where it is absent.)"""
    dtype = jnp.float32
    export = pytest.importorskip("jax.export", reason="jax.export needs absl-py on this jax")

    def f(pt, pu, x, p):
        T, U = G(pt), G(pu)
        V = T @ G.exp(x)
        J = jaxlie_geo.jacobians.compose(T, U)
        return (
            V.log(),
            (V @ U.inverse()).parameters(),
            V @ p,
            V.jlog(),
            G.jac_right(x),
            T.interpolate(U, 0.3).parameters(),
            V.normalize().parameters(),
            V.adjoint(),
            G.from_matrix(V.as_matrix()).parameters(),
            J[0],
            J[1],
            jaxlie_geo.manifold.rminus(T, U),
            jaxlie_geo.motion.velocity_between(T, U, 2.0),
            T[[0, 1]].parameters(),
            T[np.array([2, 0]), ...].parameters(),  # static indices
        )

    (b,) = export.symbolic_shape("b")
    spec = lambda k: jax.ShapeDtypeStruct((b, k), dtype)  # noqa: E731
    k, d, m = G.tangent_dim, G.space_dim, G.parameters_dim
    exported = export.export(jax.jit(f))(spec(m), spec(m), spec(k), spec(d))
    n = 300
    args = (
        random_element(G, 0, (n,), dtype).parameters(),
        random_element(G, 1, (n,), dtype).parameters(),
        random_tangent(G, 0, (n,), dtype),
        random_points(G, 0, (n,), dtype),
    )
    for got, want in zip(exported.call(*args), jax.jit(f)(*args)):
        assert got.dtype == want.dtype == dtype
        assert_close(got, want, dtype, 4)
