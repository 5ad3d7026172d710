"""Shared test configuration and the group-test harness.

* ``jax_enable_x64`` is switched on at import, before any test module runs, so float64 is
  available everywhere; float32 tests build float32 arrays explicitly (and so also check
  that nothing is silently promoted to float64).
* JAX's persistent compilation cache: compiling is most of the suite's time, and the same
  program is often compiled more than once (by both pytest-xdist workers, after
  ``jax.clear_caches()``, under another ``numpy_rank_promotion`` setting, by a subprocess).
  The cache lives in ``out/jax-cache`` (shared by the workers of a run and kept between
  runs; ``make clean`` removes it); ``JAXLIE_GEO_TEST_JAX_CACHE`` names another directory,
  or switches the cache off when empty. It is set through the environment, so notebook
  kernels and other subprocesses share it. A cache entry that cannot be read (a run killed
  while writing one) is compiled again, with the warning silenced.
* ``SEEDS``: the fixed seeds of the checks on random inputs (``over_seeds``); the inputs
  keep their shape from one seed to the next, so a new seed compiles nothing.
* The harness: ``GROUPS`` lists every group once; ``over_groups_dtypes`` parametrises a
  test over group × dtype and ``over_groups`` over the groups alone (the numeric tier's
  shared batch is in ``_programs.py``). A group added to ``GROUPS`` (with its generators in
  ``GENERATORS`` and its tangent layout in ``LAYOUT``) gets every property test. Subsets
  (``SE_GROUPS``, ``QUATERNION_GROUPS``, ``NON_ABELIAN_GROUPS``) are derived from ``GROUPS``
  by a property of each group, never listed by hand.
* Tolerances live in ``TOL`` (one entry per dtype); tests scale them by an explicit factor
  where an operation is known to amplify rounding.
* Independent references: the Lie-algebra generators of each group are written out here
  from the documented tangent orderings, not taken from the library, so ``hat``, ``vee``
  and ``exp`` are checked against ``Σ xᵢ Eᵢ`` and ``scipy.linalg.expm``.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Callable, Dict, Tuple

_JAX_CACHE = os.environ.setdefault(
    "JAXLIE_GEO_TEST_JAX_CACHE", str(Path(__file__).resolve().parents[1] / "out" / "jax-cache")
)
_JAX_CACHE_SETTINGS = {  # every compiled program, however small or fast to compile
    "jax_compilation_cache_dir": _JAX_CACHE,
    "jax_persistent_cache_min_compile_time_secs": "0",
    "jax_persistent_cache_min_entry_size_bytes": "-1",
}
if _JAX_CACHE:  # before jax is imported (its options read the environment then)
    for _name, _value in _JAX_CACHE_SETTINGS.items():
        os.environ.setdefault(_name.upper(), _value)

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)
if _JAX_CACHE:  # in case a plugin imported jax first
    jax.config.update("jax_compilation_cache_dir", os.environ["JAX_COMPILATION_CACHE_DIR"])
    jax.config.update(
        "jax_persistent_cache_min_compile_time_secs",
        float(os.environ["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"]),
    )
    jax.config.update(
        "jax_persistent_cache_min_entry_size_bytes",
        int(os.environ["JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES"]),
    )

import _suites  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

import jaxlie_geo  # noqa: E402
from jaxlie_geo import SE2, SE3, SE23, SO2, SO3, Sim3  # noqa: E402

pytest_plugins = ["_compile_budget"]

_JAX_CACHE_MAX_BYTES = 2**31
"""Above this size the oldest cache entries are removed (down to half), as a run starts."""


def pytest_collection_modifyitems(config: pytest.Config, items: list) -> None:
    """The slow checks of ``_suites.SLOW`` get ``@pytest.mark.slow`` (``make test`` runs the
    others); a whole-suite collection also checks the list against the tests."""
    _suites.mark(items, whole=_suites.suite(config) is not None)


def pytest_configure(config: pytest.Config) -> None:
    """Unreadable or unwritable cache entries are compiled again: not a test failure. The
    controller (not the pytest-xdist workers) keeps the cache's size bounded."""
    for what in ("reading", "writing"):
        config.addinivalue_line(
            "filterwarnings", f"ignore:Error {what} persistent compilation cache entry"
        )
    if _JAX_CACHE and not hasattr(config, "workerinput") and os.path.isdir(_JAX_CACHE):
        entries = sorted(Path(_JAX_CACHE).iterdir(), key=lambda p: p.stat().st_mtime)
        size = sum(p.stat().st_size for p in entries)
        if size > _JAX_CACHE_MAX_BYTES:
            for path in entries:  # the oldest first
                if size <= _JAX_CACHE_MAX_BYTES // 2:
                    break
                size -= path.stat().st_size
                path.unlink()


# ---------------------------------------------------------------------------------
# The harness: every group, batch shape and dtype.

GROUPS = [SO2, SE2, SO3, SE3, Sim3, SE23]
DTYPES = [jnp.float32, jnp.float64]


HALF_DTYPES = [jnp.float16, jnp.bfloat16]


def dtype_name(dtype: Any) -> str:
    """The test-id spelling of a dtype: ``float32``."""
    return jnp.dtype(dtype).name


def group_name(G: type) -> str:
    """The test-id spelling of a group: ``SE3``."""
    return G.__name__


GROUP_DTYPES = [
    pytest.param(G, d, id=f"{G.__name__}-{dtype_name(d)}") for G in GROUPS for d in DTYPES
]

over_groups_dtypes = pytest.mark.parametrize(("G", "dtype"), GROUP_DTYPES)
"""Parametrise over group × dtype (arguments ``G, dtype``)."""
over_groups_float64 = pytest.mark.parametrize(
    ("G", "dtype"),
    [pytest.param(G, jnp.float64, id=f"{G.__name__}-float64") for G in GROUPS],
)
"""Parametrise over the groups in float64 alone (arguments ``G, dtype``): for the checks that
differentiate twice or more (derivatives of Jacobians, Hessians, third derivatives), which
run in float64 only, as jaxlie's whole suite does; float32 keeps values and first
derivatives on every group."""
over_groups = pytest.mark.parametrize("G", GROUPS, ids=group_name)
"""Parametrise over the groups (argument ``G``)."""
over_dtypes = pytest.mark.parametrize("dtype", DTYPES, ids=dtype_name)
"""Parametrise over the dtypes (argument ``dtype``)."""

# ---------------------------------------------------------------------------------
# Tolerances: one place, per dtype. rtol and atol are applied together
# (|got − want| ≤ atol + rtol·|want|, numpy's rule) after scaling by a test's factor.

TOL: Dict[Any, Dict[str, float]] = {
    jnp.dtype(jnp.float32): {"rtol": 1e-5, "atol": 1e-5},
    jnp.dtype(jnp.float64): {"rtol": 1e-12, "atol": 1e-12},
}
EPS: Dict[Any, float] = {
    jnp.dtype(jnp.float32): float(jnp.finfo(jnp.float32).eps),
    jnp.dtype(jnp.float64): float(jnp.finfo(jnp.float64).eps),
}
# Comparisons with jaxlie: jaxlie's own kernels are less accurate (Taylor switches at
# 1e-5 / 1e-10 on θ², arccos-based logs), so the side-by-side checks allow more.
COMPAT_TOL: Dict[Any, Dict[str, float]] = {
    jnp.dtype(jnp.float32): {"rtol": 1e-4, "atol": 1e-4},
    jnp.dtype(jnp.float64): {"rtol": 1e-9, "atol": 1e-9},
}


def tol(dtype: Any, factor: float = 1.0) -> Dict[str, float]:
    """``rtol``/``atol`` for ``dtype``, scaled by ``factor``."""
    t = TOL[jnp.dtype(dtype)]
    return {"rtol": t["rtol"] * factor, "atol": t["atol"] * factor}


def to_np(x: Any) -> np.ndarray:
    """A float64 numpy copy (references are computed in float64 numpy)."""
    return np.asarray(x, dtype=np.float64)


def assert_close(got: Any, want: Any, dtype: Any, factor: float = 1.0, msg: str = "") -> None:
    """Elementwise closeness at ``dtype``'s tolerance (scaled by ``factor``)."""
    got, want = to_np(got), to_np(want)
    assert got.shape == want.shape, f"shape {got.shape} != {want.shape} {msg}"
    np.testing.assert_allclose(got, want, err_msg=msg, **tol(dtype, factor))


def assert_close_compat(got: Any, want: Any, dtype: Any, msg: str = "") -> None:
    """Closeness at the jaxlie side-by-side tolerance."""
    got, want = to_np(got), to_np(want)
    assert got.shape == want.shape, f"shape {got.shape} != {want.shape} {msg}"
    np.testing.assert_allclose(got, want, err_msg=msg, **COMPAT_TOL[jnp.dtype(dtype)])


def assert_rel_norm(got: Any, want: Any, dtype: Any, ulps: float, axes: int = 1) -> None:
    """Norm-wise relative error over the last ``axes`` axes:
    ``‖got − want‖ ≤ ulps · eps · ‖want‖`` with no absolute floor, so errors in tiny
    values (small angles) are not hidden."""
    got, want = to_np(got), to_np(want)
    assert got.shape == want.shape, f"shape {got.shape} != {want.shape}"
    ax = tuple(range(-axes, 0))
    err = np.sqrt(np.sum((got - want) ** 2, axis=ax))
    scale = np.sqrt(np.sum(want**2, axis=ax))
    bound = ulps * EPS[jnp.dtype(dtype)] * scale
    bad = ~(err <= bound)
    shown = (got[bad], want[bad]) if got.ndim > axes else (got, want)
    assert not np.any(bad), (
        f"relative error too large: err={err[bad]}, bound={bound[bad]},\n"
        f"got={shown[0]}\nwant={shown[1]}"
    )


def param_dtypes(tree: Any) -> set:
    """The set of dtypes of every array leaf of ``tree`` (groups included)."""
    return {jnp.asarray(x).dtype for x in jax.tree.leaves(tree)}


# ---------------------------------------------------------------------------------
# Independent references: generators and tangent layouts, from the documented orderings
# (SO2 (θ,), SE2 (vx, vy, θ), SO3 (ωx, ωy, ωz), SE3 (vx, vy, vz, ωx, ωy, ωz)).


def _unit(n: int, i: int, j: int) -> np.ndarray:
    m = np.zeros((n, n))
    m[i, j] = 1.0
    return m


def _so3_generators() -> np.ndarray:
    ex = _unit(3, 2, 1) - _unit(3, 1, 2)
    ey = _unit(3, 0, 2) - _unit(3, 2, 0)
    ez = _unit(3, 1, 0) - _unit(3, 0, 1)
    return np.stack([ex, ey, ez])


def _embed(block: np.ndarray, n: int) -> np.ndarray:
    out = np.zeros((n, n))
    out[: block.shape[0], : block.shape[1]] = block
    return out


GENERATORS: Dict[type, np.ndarray] = {
    SO2: np.stack([_unit(2, 1, 0) - _unit(2, 0, 1)]),
    SE2: np.stack([_unit(3, 0, 2), _unit(3, 1, 2), _embed(_unit(2, 1, 0) - _unit(2, 0, 1), 3)]),
    SO3: _so3_generators(),
    SE3: np.stack(
        [_unit(4, 0, 3), _unit(4, 1, 3), _unit(4, 2, 3)] + [_embed(e, 4) for e in _so3_generators()]
    ),
    # Sim(3): (v, ω, σ), [[ω̂ + σI, v], [0, 0]]
    Sim3: np.stack(
        [_unit(4, 0, 3), _unit(4, 1, 3), _unit(4, 2, 3)]
        + [_embed(e, 4) for e in _so3_generators()]
        + [_embed(np.eye(3), 4)]
    ),
    # SE_2(3): (ρ, ω, ν), [[ω̂, ρ, ν], [0, 0, 0], [0, 0, 0]]
    SE23: np.stack(
        [_unit(5, i, 3) for i in range(3)]
        + [_embed(e, 5) for e in _so3_generators()]
        + [_unit(5, i, 4) for i in range(3)]
    ),
}
"""``GENERATORS[G][k]`` is the Lie-algebra matrix of the k-th tangent coordinate."""

# (rotation slice, the other tangent coordinates) of each group; ``None`` where absent.
LAYOUT: Dict[type, Tuple[slice, Any]] = {
    SO2: (slice(0, 1), None),
    SE2: (slice(2, 3), [0, 1]),
    SO3: (slice(0, 3), None),
    SE3: (slice(3, 6), [0, 1, 2]),
    Sim3: (slice(3, 6), [0, 1, 2]),
    SE23: (slice(3, 6), [0, 1, 2, 6, 7, 8]),
}


SCALE_INDEX: Dict[type, int] = {Sim3: 6}
"""The tangent coordinate of the log-scale σ, for the groups that have one. Random tangents
draw it from N(0, 1), whatever the translation's scale (e^σ must stay finite)."""


def is_se(G: type) -> bool:
    """Whether ``G`` is a rotation-and-translation group SE(n) (``SEBase``: the
    ``from_rotation_and_translation`` and ``translation()`` interface)."""
    return issubclass(G, jaxlie_geo.SEBase)


def has_translation(G: type) -> bool:
    """Whether ``G``'s tangent has coordinates besides the rotation (every group but SO(n))."""
    return LAYOUT[G][1] is not None


def has_scale(G: type) -> bool:
    """Whether a generator has a nonzero trace (Sim(3)'s scale): the linear block of the
    matrix is then s R rather than a rotation."""
    return any(np.trace(E) != 0 for E in GENERATORS[G])


def rotation_params(G: type) -> int:
    """How many leading parameters hold the rotation: 2 (a unit complex number) or 4 (a unit
    quaternion); the rest (translation, velocity, log-scale), if any, follows."""
    return 2 if G.space_dim == 2 else 4


def is_abelian(G: type) -> bool:
    """Whether every pair of generators commutes (then exp is a homomorphism and every
    Jacobian is the identity)."""
    E = GENERATORS[G]
    return all(np.array_equal(a @ b, b @ a) for a in E for b in E)


# ---------------------------------------------------------------------------------
# Subsets of the groups, each derived from ``GROUPS`` by a property of the group. A test
# parametrised over a subset says in its docstring why the property is specific to it.

SE_GROUPS = [G for G in GROUPS if is_se(G)]
"""The groups with a translation."""
QUATERNION_GROUPS = [G for G in GROUPS if rotation_params(G) == 4]
"""The groups whose rotation is a unit quaternion (the 3-D rotation kernels)."""
NON_ABELIAN_GROUPS = [G for G in GROUPS if not is_abelian(G)]
"""The groups whose Jacobians, adjoints and means are not trivial."""

over_se_groups = pytest.mark.parametrize("G", SE_GROUPS, ids=group_name)
"""Parametrise over ``SE_GROUPS`` (argument ``G``)."""
over_quaternion_groups = pytest.mark.parametrize("G", QUATERNION_GROUPS, ids=group_name)
"""Parametrise over ``QUATERNION_GROUPS`` (argument ``G``)."""
over_non_abelian_groups = pytest.mark.parametrize("G", NON_ABELIAN_GROUPS, ids=group_name)


def _in_jaxlie(G: type) -> bool:
    import jaxlie  # the test extra installs it

    return hasattr(jaxlie, G.__name__)


JAXLIE_GROUPS = [G for G in GROUPS if _in_jaxlie(G)]
"""The groups jaxlie 1.5 also has (the side-by-side and interop tests); the others have
no counterpart there (``interop.to_jaxlie`` raises ``TypeError`` for them)."""
over_jaxlie_groups = pytest.mark.parametrize("G", JAXLIE_GROUPS, ids=group_name)
"""Parametrise over ``JAXLIE_GROUPS`` (argument ``G``)."""
over_jaxlie_groups_dtypes = pytest.mark.parametrize(
    ("G", "dtype"),
    [pytest.param(G, d, id=f"{G.__name__}-{dtype_name(d)}") for G in JAXLIE_GROUPS for d in DTYPES],
)
"""Parametrise over ``JAXLIE_GROUPS`` × dtype (arguments ``G, dtype``)."""
"""Parametrise over ``NON_ABELIAN_GROUPS`` (argument ``G``)."""


def identity_matrices(G: type, batch: Tuple[int, ...]) -> np.ndarray:
    """The identity matrix of ``G``, broadcast to ``batch``."""
    return np.broadcast_to(np.eye(G.matrix_dim), (*batch, G.matrix_dim, G.matrix_dim))


def hat_ref(G: type, x: Any) -> np.ndarray:
    """``Σ xₖ Eₖ`` in float64 numpy."""
    return np.einsum("...k,kij->...ij", to_np(x), GENERATORS[G])


def vee_ref(G: type, m: Any) -> np.ndarray:
    """Coefficients of ``m`` on the generators (Frobenius projection; the generators are
    orthogonal, so this reads the antisymmetric rotation part and the translation column)."""
    E = GENERATORS[G]
    return np.einsum("...ij,kij->...k", to_np(m), E) / np.einsum("kij,kij->k", E, E)


def expm_ref(G: type, x: Any) -> np.ndarray:
    """``scipy.linalg.expm(Σ xₖ Eₖ)``, batched, float64."""
    import scipy.linalg

    X = hat_ref(G, x)
    flat = X.reshape(-1, *X.shape[-2:])
    return np.stack([scipy.linalg.expm(m) for m in flat]).reshape(X.shape)


def logm_ref(m: Any) -> np.ndarray:
    """Principal ``scipy.linalg.logm``, batched, real part, float64."""
    import scipy.linalg

    m = to_np(m)
    flat = m.reshape(-1, *m.shape[-2:])
    return np.stack([np.real(scipy.linalg.logm(a)) for a in flat]).reshape(m.shape)


def rotation_angle(G: type, tangent: Any) -> np.ndarray:
    """|rotation angle| of a tangent, shape ``batch``."""
    return np.linalg.norm(to_np(tangent)[..., LAYOUT[G][0]], axis=-1)


def homogeneous_apply(G: type, M: Any, p: Any) -> np.ndarray:
    """Action of a group matrix on points, in numpy: ``M p`` (SO) or ``(M [p; 1; 0…])[:n]``."""
    M, p = to_np(M), to_np(p)
    n, m = p.shape[-1], G.matrix_dim
    if m > n:  # homogeneous (p, 1, 0, …): SE_2(3)'s velocity column does not act
        pad = np.zeros((*p.shape[:-1], m - n))
        pad[..., 0] = 1.0
        ph = np.concatenate([p, pad], axis=-1)
        return np.einsum("...ij,...j->...i", M, ph)[..., :n]
    return np.einsum("...ij,...j->...i", M, p)


# ---------------------------------------------------------------------------------
# Random inputs.

SEEDS = (1, 2, 3)
"""The seeds of the checks on random inputs: tangents and points come from numpy's generator
with the seed (no JAX compilation per draw), elements from ``G.sample_uniform``."""
over_seeds = pytest.mark.parametrize("seed", SEEDS)
"""Parametrise over ``SEEDS`` (argument ``seed``)."""


def key_of(seed: int) -> jax.Array:
    return jax.random.PRNGKey(seed)


def _angles(
    rng: np.random.Generator, batch: Tuple[int, ...], kind: str, max_angle: float
) -> np.ndarray:
    u = rng.uniform(size=batch)
    if kind == "generic":
        return u * max_angle
    if kind == "zero":
        return np.zeros(batch)
    if kind == "tiny":
        return 1e-12 * (0.5 + u)
    if kind == "small":
        return 10.0 ** (-8.0 + 7.0 * u)  # 1e-8 .. 1e-1, log-uniform
    if kind == "large":
        return max_angle - 0.1 * u
    if kind == "mixed":  # a bit of everything inside one batch
        pool = np.array([0.0, 1e-12, 1e-6, 0.5, 2.0, max_angle])
        return pool[rng.integers(0, len(pool), size=batch)]
    raise ValueError(kind)


def random_tangent(
    G: type,
    seed: int,
    batch: Tuple[int, ...],
    dtype: Any,
    kind: str = "generic",
    max_angle: float = 3.0,
    trans_scale: float = 1.0,
) -> np.ndarray:
    """Random tangent of ``G`` (a numpy array of ``dtype``) with rotation angle set by
    ``kind`` (at most ``max_angle``; "generic" is uniform in [0, max_angle]) and a normal
    translation of scale ``trans_scale``; built in float64 and rounded to ``dtype``."""
    rng = np.random.default_rng(seed)
    rot, trans = LAYOUT[G]
    rot_dim = rot.stop - rot.start
    direction = rng.normal(size=(*batch, rot_dim))
    direction /= np.linalg.norm(direction, axis=-1, keepdims=True)
    angle = _angles(rng, batch, kind, max_angle)
    out = np.zeros((*batch, G.tangent_dim))
    out[..., rot] = direction * angle[..., None]
    if trans is not None:
        out[..., trans] = trans_scale * rng.normal(size=(*batch, len(trans)))
    if G in SCALE_INDEX:
        out[..., SCALE_INDEX[G]] = rng.normal(size=batch)
    return out.astype(dtype)


def random_element(G: type, seed: int, batch: Tuple[int, ...], dtype: Any) -> Any:
    """Haar-uniform rotation (translation uniform in [-1, 1]) via ``G.sample_uniform``."""
    return G.sample_uniform(key_of(seed), batch, dtype=dtype)


def random_points(G: type, seed: int, batch: Tuple[int, ...], dtype: Any) -> np.ndarray:
    """Standard normal points, a numpy array of ``dtype``."""
    rng = np.random.default_rng(seed + 7919)
    return rng.normal(size=(*batch, G.space_dim)).astype(dtype)


def special_tangents(G: type, dtype: Any) -> jax.Array:
    """A batch of delicate tangents: zero, 1e-12 rotations, pure translations, an exact
    (float) π rotation, π − 1e-6, and a long translation with a generic angle."""
    rot, trans = LAYOUT[G]
    rot_dim = rot.stop - rot.start
    axis = np.ones(rot_dim) / np.sqrt(rot_dim)
    angles = [0.0, 1e-12, 0.0, np.pi, np.pi - 1e-6, 1.0, 1e-12]
    tscales = [0.0, 0.0, 1.0, 0.0, 1.0, 10.0, 3.0]
    out = np.zeros((len(angles), G.tangent_dim))
    for i, (a, s) in enumerate(zip(angles, tscales)):
        out[i, rot] = a * axis
        if trans is not None:
            out[i, trans] = s * np.linspace(1.0, -0.5, len(trans))
    if G in SCALE_INDEX:  # σ: exactly 0, tiny, and moderate of both signs
        out[:, SCALE_INDEX[G]] = [0.0, 1e-12, 0.5, 0.0, -0.7, 2.0, -1e-9]
    return out.astype(dtype)


def make_group(G: type, params: Any) -> Any:
    """An element from raw parameters (through the pytree constructor)."""
    return G(jnp.asarray(params))


def all_close_as_matrices(a: Any, b: Any, dtype: Any, factor: float = 1.0, msg: str = "") -> None:
    assert_close(a.as_matrix(), b.as_matrix(), dtype, factor, msg)


__all__ = [
    "GROUPS",
    "SE_GROUPS",
    "QUATERNION_GROUPS",
    "NON_ABELIAN_GROUPS",
    "DTYPES",
    "HALF_DTYPES",
    "dtype_name",
    "group_name",
    "TOL",
    "COMPAT_TOL",
    "EPS",
    "over_groups_dtypes",
    "over_groups",
    "over_groups_float64",
    "over_dtypes",
    "over_se_groups",
    "over_quaternion_groups",
    "over_non_abelian_groups",
    "JAXLIE_GROUPS",
    "over_jaxlie_groups",
    "over_jaxlie_groups_dtypes",
    "tol",
    "assert_close",
    "assert_close_compat",
    "assert_rel_norm",
    "param_dtypes",
    "GENERATORS",
    "LAYOUT",
    "is_se",
    "has_translation",
    "has_scale",
    "SCALE_INDEX",
    "rotation_params",
    "is_abelian",
    "identity_matrices",
    "hat_ref",
    "vee_ref",
    "expm_ref",
    "logm_ref",
    "rotation_angle",
    "homogeneous_apply",
    "SEEDS",
    "over_seeds",
    "key_of",
    "random_tangent",
    "random_element",
    "random_points",
    "special_tangents",
    "make_group",
    "all_close_as_matrices",
    "jaxlie_geo",
    "Callable",
]
