"""Abstract bases: what every matrix Lie group, and every semidirect product, does once.

Conventions used throughout the package:

* Elements are frozen dataclasses with a single array field holding the parameters,
  shape ``(*batch, parameters_dim)``; leading batch axes broadcast numpy-style between
  operands.
* Perturbations are on the right: ``T ⊕ δ = T @ exp(δ)`` (jaxlie's and Solà et al.'s
  "right" convention); ``adjoint`` moves tangents across: ``T @ exp(δ) = exp(Ad(T) δ) @ T``.
* Tangent orderings follow jaxlie: SE(2) ``(vx, vy, θ)``, SE(3) ``(v, ω)``. Eberly
  (seed 001 §10) orders SE(3) rotation-first; the formulas here are adapted.
* Constructors never validate (JAX rebuilds pytrees with non-array leaves); factories and
  operations do, at trace time, raising ``ValueError`` that names the expected and the
  received shape.
"""

from __future__ import annotations

import abc
import dataclasses
import functools
import importlib
import inspect
import math
import re
from typing import (
    TYPE_CHECKING,
    Any,
    Callable,
    ClassVar,
    Generic,
    Iterable,
    Iterator,
    Optional,
    Sequence,
    Tuple,
    Type,
    TypeVar,
    Union,
    cast,
    overload,
)

import jax
import jax.numpy as jnp
import numpy as onp
from typing_extensions import Self, dataclass_transform, final

from . import hints

if TYPE_CHECKING:
    from ._geodesic import Geodesic


# ---------------------------------------------------------------------------------
# Input checking, shared by every factory and operation.


def _default_float() -> jnp.dtype:
    """The default float dtype: float64 when ``jax_enable_x64`` is on, else float32."""
    return jnp.zeros(()).dtype


def as_float_array(
    x: Any, name: str, trailing: Tuple[int, ...], where: str, like: Any = None
) -> jax.Array:
    """Convert ``x`` to a floating JAX array and check its trailing shape.

    Integer and boolean inputs are promoted to ``like``'s dtype when given (the element
    they are combined with: int ⊕ float32 → float32, as JAX promotes), else to the default
    float dtype; floating inputs keep their dtype. Raises ``ValueError`` naming ``where``,
    ``name``, the expected trailing shape and the received shape.
    """
    x = jnp.asarray(x)
    if not jnp.issubdtype(x.dtype, jnp.floating):
        if jnp.issubdtype(x.dtype, jnp.complexfloating):
            raise ValueError(f"{where}: `{name}` must be real, got dtype {x.dtype}.")
        x = x.astype(_default_float() if like is None else jnp.asarray(like).dtype)
    k = len(trailing)
    if x.ndim < k or tuple(x.shape[x.ndim - k :]) != tuple(trailing):
        expected = "(*batch, " + ", ".join(map(str, trailing)) + ")" if k else "(*batch,)"
        raise ValueError(
            f"{where}: `{name}` must have shape {expected}, got shape {tuple(x.shape)}."
        )
    return x


def resolve_dtype(dtype: Any) -> jnp.dtype:
    """``None`` -> default float dtype; anything else must be a floating dtype."""
    if dtype is None:
        return _default_float()
    dtype = jnp.dtype(dtype)
    if not jnp.issubdtype(dtype, jnp.floating):
        raise ValueError(f"dtype must be a floating dtype, got {dtype}.")
    return jax.dtypes.canonicalize_dtype(dtype)


def static_size(shape: Sequence[Any]) -> Optional[int]:
    """The number of elements of ``shape``, or None when a dimension is symbolic
    (``jax.export`` shape polymorphism), where size-dependent choices take their default."""
    if all(isinstance(d, (int, onp.integer)) for d in shape):
        return math.prod(shape)
    return None


def materialize(*xs: Any) -> Any:
    """Have XLA compute each input once, into memory, before a kernel that reads its
    components several times (a Hamilton product reads each of 8 components 4 times).

    Without it XLA:CPU fuses an expensive producer (exp's sincos, log's atan polynomial)
    into every consumer that reads it and recomputes it per read. Measured at 10^6 SE3
    elements (float32, 2 cores): ``a @ SE3.exp(x)`` 196 → 73 ns/element (the exp alone: 63),
    ``(a.inverse() @ b).log()`` 122 → 74, ``a.interpolate(b, t)`` 290 → 159 (186 → 96 in
    ``benchmarks/run.py``). On a whole input already in memory (a function argument) the
    barrier is free; on a *slice* of one, jax ≥ 0.11 copies the slice (hence the
    barrier-free ``SOBase`` kernels that the SE groups call). Transparent to jit, vmap
    and autodiff.

    With jax ≥ 0.11 the tangents pass through without a barrier (``_barrier``): JAX's own
    rule puts them behind a second barrier, and jax 0.11.2 fails to transpose that one
    inside a ``custom_jvp`` rule (``_batch.in_chunks``): the gradient of a 2^19-element
    ``interpolate`` raised "DynamicJaxprTracer has no attribute accum", on CPU and GPU. On
    jax 0.10 the barrier stays on the tangents: without it XLA recomputes tangent producers
    per consumer, and ``jax.jacfwd`` of an SE3 compose took 6.4x longer (13.0 against 2.0
    µs per element at 10^5, 2-core VM).
    """
    out = _barrier(xs) if _TANGENTS_PASS_THROUGH else jax.lax.optimization_barrier(xs)
    return out[0] if len(xs) == 1 else out


def _version(text: str) -> Tuple[int, ...]:
    """The leading numeric components of a version string, then −1 for a pre-release
    (a, b, rc, dev), which precedes the release: "0.12.0.1" -> (0, 12, 0, 1), "0.6.0rc1" ->
    (0, 6, 0, -1), "0.7.0.dev20250601" -> (0, 7, 0, -1), "0.5.3+cuda12" -> (0, 5, 3). Compare
    with ``_at_least``."""
    out = []
    for part in text.split("."):
        digits = re.match(r"\d*", part).group()  # type: ignore[union-attr]  # \d* always matches
        if digits:
            out.append(int(digits))
        if digits != part:
            if re.match(r"[-_]?(a|b|c|rc|alpha|beta|pre|preview|dev)\d*$", part[len(digits):], re.I):
                out.append(-1)
            break
    return tuple(out)


def _at_least(text: str, minimum: Tuple[int, ...]) -> bool:
    """Whether version ``text`` is ``minimum`` or later (missing components count as 0)."""
    have = _version(text)
    width = max(len(have), len(minimum))
    pad = lambda v: v + (0,) * (width - len(v))  # noqa: E731
    return pad(have) >= pad(minimum)


# jax 0.5.3 is the first release with JVP and transpose rules for optimization_barrier
# (0.4.38 the first with its batching rule); older ones fail on the first grad or vmap.
if not _at_least(jax.__version__, (0, 5, 3)):
    raise ImportError(
        f"jaxlie_geo needs jax >= 0.5.3 (the first release that differentiates "
        f"lax.optimization_barrier); found jax {jax.__version__}."
    )
_TANGENTS_PASS_THROUGH = _at_least(jax.__version__, (0, 11))


@jax.custom_jvp
def _barrier(xs: Any) -> Any:
    """``optimization_barrier`` on the primal values only (see ``materialize``)."""
    return jax.lax.optimization_barrier(xs)


@_barrier.defjvp
def _barrier_jvp(primals: Any, tangents: Any) -> Any:
    return _barrier(primals[0]), tangents[0]


def components(x: jax.Array) -> Tuple[jax.Array, ...]:
    """Split the last axis into a tuple of arrays of shape ``x.shape[:-1]``."""
    return tuple(x[..., i] for i in range(x.shape[-1]))


def constant(values: Any, like: jax.Array) -> jax.Array:
    """``values`` (a constant vector or matrix) in ``like``'s dtype, with leading unit axes
    up to ``like``'s rank, so that combining it with batched arrays needs no implicit rank
    promotion: users may set ``jax_numpy_rank_promotion="raise"``, under which jaxlie's
    inverse and compose fail. The same HLO as the implicit broadcast."""
    c = jnp.asarray(values, like.dtype)
    return c.reshape((1,) * (like.ndim - c.ndim) + c.shape)


def aligned(*xs: Any) -> Tuple[Any, ...]:
    """Group elements and ``(*batch, k)`` arrays with leading unit axes added so that all
    have the same number of batch axes: the binary operations broadcast their batch axes
    numpy-style, and with the rank made equal no implicit rank promotion is left (a
    reshape, free; nothing is copied). Unlike ``utils.broadcast_leading_axes`` it does not
    broadcast to the full batch: ``materialize`` would then write a whole-batch copy of a
    single element composed with a batch."""
    params = [x.parameters() if isinstance(x, MatrixLieGroup) else x for x in xs]
    ndim = max(jnp.ndim(p) for p in params)
    out = []
    for x, p in zip(xs, params):
        if jnp.ndim(p) < ndim:
            p = jnp.reshape(p, (1,) * (ndim - jnp.ndim(p)) + jnp.shape(p))
            x = type(x)(p) if isinstance(x, MatrixLieGroup) else p
        out.append(x)
    return tuple(out)


def matmul(A: jax.Array, B: jax.Array) -> jax.Array:
    """``A @ B`` at full precision. Every matrix product in the library goes through here
    (``jacobians`` writes its small products out as multiply-adds instead): on GPUs a
    float32 ``@`` at JAX's default precision runs in TF32, about 1e-3 relative error on an
    H100, where SE3 ``propagate_compose`` lost its symmetry at that level. On CPU the
    precision setting changes nothing."""
    return jnp.matmul(A, B, precision=jax.lax.Precision.HIGHEST)


# ---------------------------------------------------------------------------------
# Pytree registration.

_C = TypeVar("_C", bound=type)


@dataclass_transform(frozen_default=True, eq_default=False)
def pytree_dataclass(cls: _C) -> _C:
    """Make ``cls`` a frozen dataclass (``eq=False``) and register it as a pytree whose
    structure records the class: every field is a child, with ``GetAttrKey`` key paths.

    Not ``jax.tree_util.register_dataclass``: up to jax 0.10.2 (the newest release when
    this was written) the treedefs of two classes registered that way compare *equal*
    whenever their fields have the same layout (``tree_structure(SO3(x)) ==
    tree_structure(SE2(x))`` is True; only the hashes differ), so ``jax.jit``'s cache can
    return the computation compiled for one class when called with the other. Measured:
    400 distinct one-field classes through one jitted function gave 64 results computed
    for another class; in this project's test suite, SO3.jlog's reference came out as
    SE2's. ``tests/test_transforms.py`` checks that no two of our pytree classes (and no
    user dataclass of the same layout) share a structure.
    """
    # Group elements keep MatrixLieGroup.__repr__ (rounded values, no dtype noise).
    own_repr = not issubclass(cls, MatrixLieGroup)
    cls = dataclasses.dataclass(frozen=True, eq=False, repr=own_repr)(cls)  # type: ignore[assignment]
    cls.__setattr__ = _setattr_if_mutable  # type: ignore[assignment,method-assign]
    names = tuple(f.name for f in dataclasses.fields(cls))
    keys = tuple(jax.tree_util.GetAttrKey(n) for n in names)

    def flatten_with_keys(x: Any) -> Tuple[Tuple[Any, ...], None]:
        return tuple((k, getattr(x, n)) for k, n in zip(keys, names)), None

    def flatten(x: Any) -> Tuple[Tuple[Any, ...], None]:
        return tuple(getattr(x, n) for n in names), None

    def unflatten(_: None, children: Iterable[Any]) -> Any:
        # Bypass the frozen dataclass's __init__ (one object.__setattr__ per field either
        # way; this saves the call): unflattening runs on every jitted call's outputs.
        obj: Any = object.__new__(cls)
        for n, c in zip(names, children):
            object.__setattr__(obj, n, c)
        return obj

    jax.tree_util.register_pytree_with_keys(cls, flatten_with_keys, unflatten, flatten)
    _register_flax_state(cls, names)
    return cls


def _setattr_if_mutable(self: Any, name: str, value: Any) -> None:
    """Frozen (``dataclasses.FrozenInstanceError``), except on the copies that
    ``jax_dataclasses.copy_and_mutate`` yields, which it marks with ``__mutability__``:
    there a field may be reassigned, as on jaxlie's jax_dataclasses elements. With
    ``validate=True`` (its default) the new value must have the old one's tree structure
    and shapes, and a dtype of the same kind (jax_dataclasses' rule); else ``ValueError``."""
    mode = getattr(self.__dict__.get("__mutability__"), "name", "FROZEN")
    if mode == "FROZEN":
        raise dataclasses.FrozenInstanceError(
            f"cannot assign to field {name!r}: {type(self).__name__} is frozen (build a new "
            f"element, use dataclasses.replace, or jax_dataclasses.copy_and_mutate)."
        )
    if mode == "MUTABLE":
        old, new = getattr(self, name), value
        old_leaves, old_def = jax.tree_util.tree_flatten(old)
        new_leaves, new_def = jax.tree_util.tree_flatten(new)
        same = bool(old_def == new_def) and all(  # type: ignore[operator]
            onp.shape(a) == onp.shape(b)
            and onp.result_type(a).kind == onp.result_type(b).kind
            for a, b in zip(old_leaves, new_leaves)
        )
        if not same:
            shown = [(onp.shape(x), str(onp.result_type(x))) for x in new_leaves]
            want = [(onp.shape(x), str(onp.result_type(x))) for x in old_leaves]
            raise ValueError(
                f"{type(self).__name__}.{name}: copy_and_mutate needs the same structure, "
                f"shapes and kind of dtype: got {shown}, had {want}."
            )
    object.__setattr__(self, name, value)


try:  # flax is optional: serialization is registered only where it imports
    _flax_serialization: Any = importlib.import_module("flax.serialization")
except Exception:  # absent, or broken against this jax: then there is nothing to register
    _flax_serialization = None


def _register_flax_state(cls: type, names: Tuple[str, ...]) -> None:
    """Register ``cls`` with ``flax.serialization`` (when flax is installed), as jaxlie's
    jax_dataclasses does: the state dict is ``{field name: state of the field}``, e.g.
    ``{"wxyz_xyz": array}``, so ``to_bytes``/``from_bytes`` and ``to_state_dict`` work and
    a file written by either library loads in the other (same field names). Restoring
    raises ``ValueError`` naming a missing or unknown field."""
    if _flax_serialization is None:
        return
    ser = _flax_serialization

    def to_state(x: Any) -> dict:
        return {n: ser.to_state_dict(getattr(x, n)) for n in names}

    def from_state(x: Any, state: dict) -> Any:
        missing = [n for n in names if n not in state]
        unknown = sorted(set(state) - set(names))
        if missing or unknown:
            raise ValueError(
                f"{cls.__name__} state dict: missing field(s) {missing}, unknown field(s) "
                f"{unknown}; expected exactly {list(names)}."
            )
        return dataclasses.replace(
            x, **{n: ser.from_state_dict(getattr(x, n), state[n]) for n in names}
        )

    ser.register_serialization_state(cls, to_state, from_state)


# ---------------------------------------------------------------------------------
# jit-wrapping of public methods.

_NOT_JITTED = frozenset({"get_batch_axes", "parameters", "reshape"})
_JITTED_PRIVATE = {"_between": "relative element (a⁻¹ @ b)"}
"""Private methods that public functions call eagerly (``manifold.rminus``, ``geodesic``),
jitted too, with the name their error messages use: unjitted, an eager SE3 ``rminus`` of
100 poses took 1.7 ms (one dispatch per primitive) against 90 µs."""
_STATIC_NAMES = ("batch_axes", "dtype")


def _inherited_doc(cls: type, name: str) -> Any:
    """The docstring of ``name`` in the nearest base class that documents it."""
    for base in cls.__mro__[1:]:
        raw = base.__dict__.get(name)
        fn = getattr(raw, "__func__", raw)
        if fn is not None and getattr(fn, "__doc__", None):
            return fn.__doc__
    return None


def check_elements(where: str, *args: Any) -> None:
    """Check the group elements among ``args`` at trace time: parameters of shape
    ``(*batch, parameters_dim)``, and batch axes that broadcast together (numpy rules).
    Raises ``ValueError`` naming ``where`` and the shapes. Without the first check
    ``SO3(tangent).log()`` silently read a 3-vector as a quaternion; without the second a
    batch mismatch surfaced as jax.numpy's "mul got incompatible shapes", naming neither
    the operation nor the group."""
    batches = []
    for a in args:
        if not isinstance(a, MatrixLieGroup):
            continue
        shape = getattr(a.parameters(), "shape", None)
        if shape is None:
            continue
        dtype = getattr(a.parameters(), "dtype", None)
        if dtype is not None and jnp.issubdtype(dtype, jnp.complexfloating):
            raise ValueError(f"{where}: {type(a).__name__} parameters must be real, got dtype {dtype}.")
        if tuple(shape[-1:]) != (a.parameters_dim,):
            raise ValueError(
                f"{where}: {type(a).__name__} parameters must have shape "
                f"(*batch, {a.parameters_dim}), got shape {tuple(shape)}."
            )
        batches.append(tuple(shape[:-1]))
    check_batches(where, "batch axes", *batches)


def check_batches(where: str, what: str, *batches: Tuple[int, ...]) -> Tuple[int, ...]:
    """The broadcast of ``batches``; ``ValueError`` naming ``where``, ``what`` and the
    shapes when they do not broadcast."""
    try:  # jnp's, not numpy's: it takes jax.export's symbolic dimensions
        return tuple(jnp.broadcast_shapes(*batches))
    except ValueError:
        shown = " and ".join(str(b) for b in batches)
        raise ValueError(
            f"{where}: {what} {shown} do not broadcast together (numpy rules)."
        ) from None


def _check_same_group(where: str, first: Any, *rest: Any) -> None:
    """``TypeError`` naming ``where`` when a group element among ``rest`` is not of
    ``first``'s group."""
    for a in rest:
        if isinstance(a, MatrixLieGroup) and type(a) is not type(first):
            raise TypeError(f"{where}: expected {type(first).__name__}, got {type(a).__name__}.")


def _checking_elements(fn: Any, where: str) -> Any:
    """``fn`` preceded by ``check_elements`` on its arguments (``self``, ``other``).
    Constructors cannot check (JAX rebuilds pytrees with shapes, tracers, None, and
    ``jax.jacfwd`` of a group-valued function returns an element holding a Jacobian), so
    the operations do. A method's other elements (``multiply``, ``interpolate``) must be of
    ``self``'s group: ``TypeError`` (an SE3 passed to ``SO3.multiply`` raised
    ``AttributeError: 'SE3' object has no attribute 'wxyz'``). Runs at trace time only."""

    @functools.wraps(fn)
    def checked(*args: Any, **kwargs: Any) -> Any:
        if args and isinstance(args[0], MatrixLieGroup):
            _check_same_group(where, *args, *kwargs.values())
        check_elements(where, *args, *kwargs.values())
        return fn(*args, **kwargs)

    return checked


def _jit_public_methods(cls: type) -> None:
    """Wrap every public method of ``cls`` (inherited ones included) in ``jax.jit``.

    Measured (benchmarks/RESULTS.md): an eager SE3.exp costs ~1.5 ms as a chain of
    primitive dispatches and ~5 µs as one jitted call; inside a user's ``jit`` the wrapper
    is inlined. ``batch_axes`` and ``dtype`` are static; shape errors still raise at trace
    time.

    A classmethod becomes, on each concrete class, a ``jax.jit`` of the function with
    ``cls`` bound (stored as a staticmethod, its signature without ``cls``), as in jaxlie:
    so ``SO3.exp`` is itself a jitted function and ``SO3.exp.lower(tangent)``,
    ``.trace`` and ``.eval_shape`` work (ahead-of-time compilation). A subclass rebinds it.
    """
    for name in dir(cls):
        if (name.startswith("_") and name not in _JITTED_PRIVATE) or name in _NOT_JITTED:
            continue
        raw = inspect.getattr_static(cls, name)
        bound_of = getattr(getattr(raw, "__func__", None), "_classmethod", None)
        if bound_of is not None:  # a classmethod bound to a base class: bind it to cls
            raw = classmethod(bound_of)
        kind = type(raw) if isinstance(raw, (classmethod, staticmethod)) else None
        fn = raw.__func__ if kind else raw
        if not inspect.isfunction(fn) or getattr(fn, "_jitted", False):
            continue
        if getattr(fn, "__isabstractmethod__", False):
            continue
        sig = inspect.signature(fn)
        names = list(sig.parameters)
        static = tuple(n for n in _STATIC_NAMES if n in names)
        where = f"{cls.__name__} {_JITTED_PRIVATE[name]}" if name in _JITTED_PRIVATE else f"{cls.__name__}.{name}"
        checked = _checking_elements(fn, where)
        if kind is classmethod:
            checked = functools.partial(checked, cls)
            sig = sig.replace(parameters=list(sig.parameters.values())[1:])
            names = names[1:]
        argnums = tuple(names.index(n) for n in static)
        jitted = jax.jit(checked, static_argnums=argnums, static_argnames=static)
        if "batch_axes" in names:
            pos = names.index("batch_axes")

            def call(*args: Any, _jitted: Any = jitted, _pos: int = pos, **kwargs: Any) -> Any:
                # Lists are unhashable: make batch_axes a tuple before jit sees it.
                if len(args) > _pos and not isinstance(args[_pos], tuple):
                    args = (*args[:_pos], tuple(args[_pos]), *args[_pos + 1 :])
                elif not isinstance(kwargs.get("batch_axes", ()), tuple):
                    kwargs["batch_axes"] = tuple(kwargs["batch_axes"])
                return _jitted(*args, **kwargs)

            for stage in ("lower", "trace", "eval_shape"):  # AOT, as on a jax.jit
                if hasattr(jitted, stage):
                    setattr(call, stage, getattr(jitted, stage))
            call.__signature__ = sig  # type: ignore[attr-defined]  # (a jax.jit has its own)
        else:
            call = jitted  # type: ignore[assignment]
        wrapper = functools.wraps(fn)(call)
        wrapper._jitted = True  # type: ignore[attr-defined]
        if not fn.__doc__:  # an override documented in the base class: show the base's text
            wrapper.__doc__ = _inherited_doc(cls, name)
        if kind is classmethod:
            wrapper._classmethod = fn  # type: ignore[attr-defined]
            setattr(cls, name, staticmethod(wrapper))
        else:
            setattr(cls, name, kind(wrapper) if kind else wrapper)


_F = TypeVar("_F", bound=Callable[..., Any])


def jit_function(*static_argnames: str) -> Callable[[_F], _F]:
    """Decorator: wrap a module-level public function in ``jax.jit`` (the named arguments
    static), as the group methods are, so that an eager call is one dispatch. Measured
    eager before: ``jacobians.compose`` 228 µs, ``motion.arc`` 1.3 ms (one dispatch per
    primitive). Shape errors still raise at trace time."""

    def wrap(fn: _F) -> _F:
        where = f"{fn.__module__.rsplit('.', 1)[-1]}.{fn.__name__}"
        jitted = jax.jit(_checking_elements(fn, where), static_argnames=static_argnames)
        return cast(_F, functools.wraps(fn)(lambda *args, **kwargs: jitted(*args, **kwargs)))

    return wrap


# ---------------------------------------------------------------------------------
# Base classes.


class MatrixLieGroup(abc.ABC):
    """Interface of a matrix Lie group whose elements are stored as parameter arrays.

    Subclasses are frozen dataclasses with one array field (``unit_complex``, ``wxyz``,
    ...), registered as pytrees with ``pytree_dataclass`` (see there why not
    ``jax.tree_util.register_dataclass``).
    """

    matrix_dim: ClassVar[int]
    """Size n of the n×n matrix from ``as_matrix()``."""
    parameters_dim: ClassVar[int]
    """Length of the parameter vector, ``parameters().shape[-1]``."""
    tangent_dim: ClassVar[int]
    """Dimension k of the tangent space (the Lie algebra)."""
    space_dim: ClassVar[int]
    """Dimension of the points the group acts on."""
    _interpolate_in_chunks: ClassVar[bool] = True
    """Whether large ``interpolate`` batches run in chunks (``_batch.in_chunks``)."""

    # -- construction ---------------------------------------------------------------

    def __init__(self, parameters: jax.Array):  # pragma: no cover - replaced by dataclass
        raise NotImplementedError

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if not inspect.isabstract(cls):
            _jit_public_methods(cls)

    @classmethod
    @abc.abstractmethod
    def identity(cls, batch_axes: Tuple[int, ...] = (), dtype: Any = None) -> Self:
        """The identity element.

        Args:
            batch_axes: leading batch shape of the result.
            dtype: floating dtype of the parameters (default: JAX's default float).
        Returns:
            Identity with parameters of shape ``(*batch_axes, parameters_dim)``.
        """

    @classmethod
    @abc.abstractmethod
    def from_matrix(cls, matrix: hints.Array) -> Self:
        """Element from its matrix, shape ``(*batch, matrix_dim, matrix_dim)``
        (homogeneous for SE groups)."""

    @classmethod
    @abc.abstractmethod
    def exp(cls, tangent: hints.Array) -> Self:
        """Exponential map, ``expm(hat(tangent))``; tangent shape ``(*batch, tangent_dim)``."""

    @classmethod
    @abc.abstractmethod
    def hat(cls, tangent: hints.Array) -> jax.Array:
        """Lie algebra matrix of a tangent (Eberly's ``ToGroup``/L):
        ``(*batch, tangent_dim) -> (*batch, matrix_dim, matrix_dim)``."""

    @classmethod
    @abc.abstractmethod
    def vee(cls, matrix: hints.Array) -> jax.Array:
        """Inverse of ``hat`` (Eberly's ``InverseL``):
        ``(*batch, matrix_dim, matrix_dim) -> (*batch, tangent_dim)``. Reads the
        generator coefficients: the rotation block's antisymmetric part (its symmetric part
        is ignored) and, for SE(n), the translation column as it stands (the bottom row is
        ignored)."""

    @classmethod
    @abc.abstractmethod
    def sample_uniform(
        cls, key: jax.Array, batch_axes: Tuple[int, ...] = (), dtype: Any = None
    ) -> Self:
        """Uniformly distributed rotations (Haar measure); translations, where present,
        uniform in [-1, 1]. Draws the same numbers as jaxlie 1.5 for the same key.

        Args:
            key: PRNG key.
            batch_axes: leading batch shape; every element is drawn independently.
            dtype: floating dtype (default: JAX's default float).
        """

    # -- accessors ------------------------------------------------------------------

    def parameters(self) -> jax.Array:
        """The underlying parameters, shape ``(*batch, parameters_dim)``."""
        return getattr(self, dataclasses.fields(self)[0].name)  # type: ignore[arg-type]

    @abc.abstractmethod
    def as_matrix(self) -> jax.Array:
        """Matrix of the element, ``(*batch, matrix_dim, matrix_dim)``; homogeneous for
        SE groups."""

    @final
    def get_batch_axes(self) -> Tuple[int, ...]:
        """Leading batch shape: ``parameters().shape[:-1]``."""
        return tuple(self.parameters().shape[:-1])

    # -- group operations -----------------------------------------------------------

    @abc.abstractmethod
    def apply(self, target: hints.Array) -> jax.Array:
        """Act on points, shape ``(*batch, space_dim)``; batch axes broadcast."""

    @abc.abstractmethod
    def multiply(self, other: Self) -> Self:
        """Composition ``self @ other``; batch axes broadcast."""

    @abc.abstractmethod
    def inverse(self) -> Self:
        """Group inverse; same batch axes and dtype."""

    def _between(self, other: Self) -> Self:
        """``self⁻¹ @ other``, the relative element of pose graphs, geodesics and
        ``rminus`` (batch axes broadcast; ``TypeError`` for another group)."""
        return self.inverse().multiply(other)

    @abc.abstractmethod
    def log(self) -> jax.Array:
        """Principal logarithm, ``vee(logm(as_matrix()))``, shape ``(*batch, tangent_dim)``
        (rotation angle in [0, π])."""

    @abc.abstractmethod
    def adjoint(self) -> jax.Array:
        """Adjoint matrix Ad, ``(*batch, tangent_dim, tangent_dim)``, with
        ``M hat(x) M⁻¹ = hat(Ad x)`` and ``T @ exp(x) = exp(Ad x) @ T``."""

    @abc.abstractmethod
    def normalize(self) -> Self:
        """Project the parameters back onto the group (same batch axes and dtype): the
        rotation part divided by its norm (unit quaternion / complex), the translation
        kept. Any finite nonzero rotation part works, whatever its scale
        (``_scalar.unit``); a zero or non-finite one has no direction and gives NaN."""

    def jlog(self) -> jax.Array:
        """Jacobian of the log under right perturbations, the inverse right Jacobian at
        ``log()``: ``d/dδ log(T @ exp(δ))`` at δ = 0, shape
        ``(*batch, tangent_dim, tangent_dim)``."""
        return type(self).jac_right_inv(self.log())

    # -- Jacobians of the exponential (Solà et al. 2018, §IV) ------------------------

    @classmethod
    @abc.abstractmethod
    def jac_right(cls, tangent: hints.Array) -> jax.Array:
        """Right Jacobian J_r(x): ``exp(x + δ) ≈ exp(x) @ exp(J_r(x) δ)``;
        ``(*batch, k) -> (*batch, k, k)``. Equal to Σ (−ad x)ⁿ/(n+1)!."""

    @classmethod
    @abc.abstractmethod
    def jac_right_inv(cls, tangent: hints.Array) -> jax.Array:
        """Inverse right Jacobian J_r⁻¹(x), in closed form (not a matrix inverse);
        ``(*batch, k) -> (*batch, k, k)``. Singular where the rotation angle is 2π."""

    @classmethod
    def jac_left(cls, tangent: hints.Array) -> jax.Array:
        """Left Jacobian J_l(x) = J_r(−x) = Ad(exp x) J_r(x):
        ``exp(x + δ) ≈ exp(J_l(x) δ) @ exp(x)``; ``(*batch, k) -> (*batch, k, k)``."""
        return cls.jac_right(-cls._check_tangent(tangent, "jac_left"))

    @classmethod
    def jac_left_inv(cls, tangent: hints.Array) -> jax.Array:
        """Inverse left Jacobian J_l⁻¹(x) = J_r⁻¹(−x); ``(*batch, k) -> (*batch, k, k)``."""
        return cls.jac_right_inv(-cls._check_tangent(tangent, "jac_left_inv"))

    @classmethod
    @abc.abstractmethod
    def ad(cls, tangent: hints.Array) -> jax.Array:
        """Lie-algebra adjoint: the matrix of y ↦ vee([hat x, hat y]);
        ``(*batch, k) -> (*batch, k, k)``. ``Ad(exp x) = expm(ad x)``."""

    @overload
    def __matmul__(self, other: Self) -> Self: ...

    @overload
    def __matmul__(self, other: hints.Array) -> jax.Array: ...

    def __matmul__(self, other: Union[Self, hints.Array]) -> Union[Self, jax.Array]:
        """``T @ U`` composes (``multiply``); ``T @ points`` acts (``apply``)."""
        if isinstance(other, MatrixLieGroup):
            if type(other) is not type(self):
                raise TypeError(
                    f"Cannot compose {type(self).__name__} with {type(other).__name__}."
                )
            return self.multiply(cast(Self, other))
        if isinstance(other, (onp.ndarray, jax.Array)):
            return self.apply(other)
        return NotImplemented

    # -- geodesics (seed 001 §4) ----------------------------------------------------

    def interpolate(self, other: Self, t: hints.Scalar) -> Self:
        """Point at time ``t`` on the geodesic from ``self`` (t = 0) to ``other`` (t = 1).

        Body form ``self @ exp(t · log(self⁻¹ @ other))``, which equals Eberly's left form
        ``exp(t · log(other @ self⁻¹)) @ self`` (seed 001 eq. 9) except where the relative
        rotation is exactly π, and which does not lose ε·|translation| to cancellation far
        from the origin. At a relative rotation of exactly π the principal log's tie-break
        applies (quaternion with w = 0 as stored: the axis is the stored one).

        Args:
            other: end point; batch axes broadcast with ``self``.
            t: scalar or array; it broadcasts numpy-style against the batch axes (unbatched
                endpoints with ``t`` of shape (K,) give K poses; an outer product is
                ``t[:, None]``). Values outside [0, 1] extrapolate along the same curve.

        Memory: when ``self`` and ``other`` share one batch shape of at least 2^19 elements
        and ``t`` broadcasts to it (a scalar ``t`` does), CPU evaluates it in 2^16-element
        chunks, so the temporaries are a few MB instead of a multiple of the output (SE3,
        2^22 elements: 5 MB against 268 MB; SO2, whose whole-batch kernel has no
        temporaries, is not chunked).
        """
        from ._batch import in_chunks
        from ._geodesic import geodesic

        def path(a: Self, b: Self, t: Any) -> Self:
            return geodesic(a, b)(t)

        t = jnp.asarray(t)  # lists and tuples too, as in geodesic
        batch = self.get_batch_axes()
        same = type(other) is type(self) and other.get_batch_axes() == batch
        t_shape = jnp.shape(t)
        t_fits = len(t_shape) <= len(batch) and all(
            a in (1, b) for a, b in zip(t_shape[::-1], batch[::-1]))
        if self._interpolate_in_chunks and same and t_fits:
            where = f"{type(self).__name__} geodesic"
            like = jnp.zeros((), jnp.result_type(self.parameters(), other.parameters()))
            t = jnp.broadcast_to(as_float_array(t, "t", (), where, like=like), batch)
            return in_chunks(path, batch, self, other, t)
        return path(self, other, t)

    # -- batch handling -------------------------------------------------------------

    def __getitem__(self, index: Any) -> Self:
        """Index the batch axes: ``T[0]``, ``T[:, 1]``, ``T[mask]``, ``T[..., None]``. A static
        index out of range (a Python or NumPy integer, or a list or NumPy array of them, also
        after ``...``) raises ``IndexError``, as in NumPy (JAX would clamp it, and Python's
        iteration fallback relies on the error); jax arrays and traced indices clamp, as in
        JAX."""
        index = index if isinstance(index, tuple) else (index,)
        index = tuple(bool(i) if isinstance(i, onp.bool_) else i for i in index)  # jnp fails on them
        batch = self.get_batch_axes()

        def static(i: Any) -> Optional[onp.ndarray]:  # integers or a mask, known now
            if isinstance(i, (bool, onp.bool_)) or not isinstance(
                i, (int, list, onp.ndarray, onp.integer)
            ):
                return None
            a = onp.asarray(i)
            return a if a.dtype.kind in "iu" or (a.dtype.kind == "b" and a.ndim > 0) else None

        def width(i: Any) -> int:  # batch axes an entry consumes
            if i is None or i is Ellipsis or isinstance(i, (bool, onp.bool_)):
                return 0  # a scalar bool adds an axis, as None does
            a = static(i) if not isinstance(i, jax.Array) else i
            return a.ndim if a is not None and a.dtype == bool else 1

        checked = list(index)
        at = [k for k, i in enumerate(checked) if i is Ellipsis]  # `is`: ndarray == ... is elementwise
        if len(at) == 1:
            rest = len(batch) - sum(width(i) for i in checked)
            checked[at[0] : at[0] + 1] = [slice(None)] * max(rest, 0)
        axis = 0
        for i in checked:  # static entries, from the left; a jax array ends the check
            if width(i) == 0 and not isinstance(i, slice):
                continue
            a = None if isinstance(i, slice) else static(i)
            if not isinstance(i, slice) and a is None:
                break
            n = batch[axis] if axis < len(batch) else 0
            if a is not None and a.dtype != bool and isinstance(n, (int, onp.integer)):
                if not onp.all((-n <= a) & (a < n)):  # (symbolic sizes: not checked)
                    raise IndexError(
                        f"{type(self).__name__}: index {i} is out of range for batch axes "
                        f"{batch} (axis {axis})."
                    )
            axis += width(i)
        # In the stored layout, the parameter axis last: NumPy's rules put the advanced
        # indices' axes first when they are not adjacent, which keeps that axis last.
        if not at:
            index = (*index, Ellipsis)
        return type(self)(self.parameters()[(*index, slice(None))])

    def __iter__(self) -> Iterator[Self]:
        """Iterate over the first batch axis (``a, b = T`` for a batch of 2); an unbatched
        element is not iterable (``TypeError``)."""
        if not self.get_batch_axes():
            raise TypeError(f"iteration over an unbatched {type(self).__name__}.")
        for i in range(len(self)):
            yield self[i]

    def __bool__(self) -> bool:
        """Always true, as for jaxlie's elements (without it, ``bool`` would fall back to
        ``len``, which an unbatched element does not have)."""
        return True

    def reshape(self, *shape: Union[int, Sequence[int]]) -> Self:
        """Reshape the batch axes: ``T.reshape(2, 3)`` or ``T.reshape((2, 3))``."""
        if len(shape) == 1 and not isinstance(shape[0], (int, onp.integer)):
            shape = tuple(shape[0])  # type: ignore[assignment]
        p = self.parameters()
        return type(self)(p.reshape((*shape, p.shape[-1])))  # type: ignore[arg-type]

    def __len__(self) -> int:
        batch = self.get_batch_axes()
        if not batch:
            raise TypeError(f"len() of an unbatched {type(self).__name__}.")
        return batch[0]

    def __repr__(self) -> str:
        """``SO3(wxyz=[...])``, ``SE3(wxyz=[...], xyz=[...])`` as jaxlie prints them, values
        rounded to 5 decimals."""
        name = dataclasses.fields(self)[0].name  # type: ignore[arg-type]
        p = self.parameters()
        # Tracers, and the ShapeDtypeStructs of jax.eval_shape, have no values to show.
        if isinstance(p, jax.core.Tracer) or not isinstance(p, (jax.Array, onp.ndarray)):
            return f"{type(self).__name__}({name}={p})"
        v = onp.asarray(p)
        if v.dtype.itemsize < 4:  # float16's range ends at 65504: rounding via v·10^5 gave NaN
            v = onp.round(v.astype(onp.float32), 5).astype(v.dtype)
        else:
            v = onp.round(v, 5)
        parts = [(name, v)]
        rotation = getattr(type(self), "_rotation_type", None)
        if rotation is not None:  # SE: the rotation's field and the translation, jaxlie's labels
            k = rotation.parameters_dim
            parts = [(dataclasses.fields(rotation)[0].name, v[..., :k]),
                     (name.rsplit("_", 1)[1], v[..., k:])]
        return f"{type(self).__name__}({', '.join(f'{n}={v}' for n, v in parts)})"

    # -- shared helpers -------------------------------------------------------------

    @classmethod
    def _check_tangent(
        cls, tangent: hints.Array, where: str = "exp", like: Any = None, name: str = "tangent"
    ) -> jax.Array:
        """``tangent`` as a float array ``(*batch, tangent_dim)``; integers promoted to the
        dtype of ``like`` (the element it acts on), else to the default float. Errors name
        ``where`` (a method name, or a dotted function name such as ``motion.pose_at``)
        and the argument ``name``."""
        where = where if "." in where else f"{cls.__name__}.{where}"
        return as_float_array(tangent, name, (cls.tangent_dim,), where, like=like)

    @classmethod
    def _check_matrix(cls, matrix: hints.Array, where: str) -> jax.Array:
        n = cls.matrix_dim
        return as_float_array(matrix, "matrix", (n, n), f"{cls.__name__}.{where}")

    def _check_points(
        self, target: hints.Array, where: Optional[str] = None, name: str = "target"
    ) -> jax.Array:
        where = where or f"{type(self).__name__}.apply"
        points = as_float_array(target, name, (self.space_dim,), where, like=self.parameters())
        check_batches(
            where, "batch axes of the element and the points",
            self.get_batch_axes(), points.shape[:-1],
        )
        return points

    @abc.abstractmethod
    def _rplus_jacobian(self) -> jax.Array:
        """d parameters(T @ exp(δ)) / dδ at δ = 0: ``(*batch, parameters_dim, tangent_dim)``."""


class SOBase(MatrixLieGroup):
    """Base class for special orthogonal groups."""

    # Barrier-free kernels of ``apply`` and ``multiply``, for the SE groups, which
    # materialize whole elements once and pass the rotation in as a slice: a second
    # barrier on that slice would copy it (jax ≥ 0.11 XLA:CPU materializes a barrier on a
    # slice as a new buffer: 185 MB of temporaries for a 2^22-element SE3 compose). SO2
    # and SO3 override them; the defaults keep other subclasses working.

    _kernels_reread: ClassVar[bool] = True
    """Whether the kernels read each input component several times (SO3's rotation and
    Hamilton product; ``materialize`` has the numbers), so that a computed input is best
    materialized first. SO2's read each twice: ``SE2.exp(x).inverse()`` took 13.6 against 10.2 ns per
    element with a barrier (10^6, float32, 2-core VM)."""

    def _apply_kernel(self, points: jax.Array) -> jax.Array:
        """``apply`` on checked points, with no ``materialize``."""
        return self.apply(points)

    def _multiply_kernel(self, other: Self) -> Self:
        """``multiply`` with no ``materialize``."""
        return self.multiply(other)

    def _matrix_block(self) -> jax.Array:
        """``as_matrix`` in the form that fuses best into a larger matrix (an SE group's
        homogeneous matrix or Jacobians); SO2 overrides it."""
        return self.as_matrix()


ContainedSOType = TypeVar("ContainedSOType", bound=SOBase)


class SEBase(Generic[ContainedSOType], MatrixLieGroup):
    """Base class for special Euclidean groups: a rotation and a translation, stored as
    ``(rotation parameters, translation)``. Composition, inverse, action and
    normalisation are the semidirect-product formulas, written once here in terms of
    the rotation's closed-form operations."""

    _rotation_type: ClassVar[Type[Any]]  # the SO group (ContainedSOType); set by each subclass

    # -- SE-specific interface ------------------------------------------------------

    @classmethod
    def _check_rotation(cls, rotation: Any, where: str) -> None:
        R = cls._rotation_type
        if not isinstance(rotation, R):
            got = type(rotation)
            names = (R.__name__, got.__name__)
            if names[0] == names[1]:  # e.g. jaxlie's SO3 passed to ours
                names = (f"{R.__module__}.{R.__qualname__}", f"{got.__module__}.{got.__qualname__}")
            elif hasattr(rotation, "shape") and hasattr(rotation, "dtype"):
                names = (names[0], f"an array of shape {tuple(rotation.shape)} (wrap it: {R.__name__}(...))")
            raise TypeError(
                f"{cls.__name__}.{where}: `rotation` must be {names[0]}, got {names[1]}."
            )

    @classmethod
    def from_rotation_and_translation(
        cls, rotation: ContainedSOType, translation: hints.Array
    ) -> Self:
        """Rigid transform ``x ↦ R x + t``; batch axes of the two broadcast.

        Args:
            rotation: an element of the matching SO group.
            translation: shape ``(*batch, space_dim)``.
        """
        cls._check_rotation(rotation, "from_rotation_and_translation")
        t = as_float_array(
            translation,
            "translation",
            (cls.space_dim,),
            f"{cls.__name__}.from_rotation_and_translation",
            like=rotation.parameters(),
        )
        r = rotation.parameters()
        dtype = jnp.result_type(r, t)
        where = f"{cls.__name__}.from_rotation_and_translation"
        batch = check_batches(where, "rotation and translation batch axes", r.shape[:-1], t.shape[:-1])
        r = jnp.broadcast_to(r.astype(dtype), (*batch, r.shape[-1]))
        t = jnp.broadcast_to(t.astype(dtype), (*batch, t.shape[-1]))
        return cls(jnp.concatenate([r, t], axis=-1))

    @classmethod
    def from_rotation(cls, rotation: ContainedSOType) -> Self:
        """Pure rotation (zero translation), with the rotation's batch axes."""
        cls._check_rotation(rotation, "from_rotation")
        p = rotation.parameters()
        return cls.from_rotation_and_translation(
            rotation, jnp.zeros((*p.shape[:-1], cls.space_dim), p.dtype)
        )

    @classmethod
    def from_translation(cls, translation: hints.Array) -> Self:
        """Pure translation, ``translation`` of shape ``(*batch, space_dim)``."""
        t = as_float_array(
            translation, "translation", (cls.space_dim,), f"{cls.__name__}.from_translation"
        )
        rot = cls._rotation_type.identity(t.shape[:-1], dtype=t.dtype)
        return cls.from_rotation_and_translation(rot, t)

    def rotation(self) -> ContainedSOType:
        """The rotation part (SO2 / SO3), same batch axes."""
        k = self._rotation_type.parameters_dim
        return self._rotation_type(self.parameters()[..., :k])

    def translation(self) -> jax.Array:
        """The translation part, ``(*batch, space_dim)``."""
        k = self._rotation_type.parameters_dim
        return self.parameters()[..., k:]

    # -- semidirect-product operations ----------------------------------------------

    @classmethod
    def identity(cls, batch_axes: Tuple[int, ...] = (), dtype: Any = None) -> Self:
        rot = cls._rotation_type.identity(batch_axes, dtype)
        return cls.from_rotation(rot)

    # Each operation materializes whole elements once, then uses the rotation's
    # barrier-free kernels on slices of them (see ``SOBase._apply_kernel``).

    def apply(self, target: hints.Array) -> jax.Array:
        T, target = materialize(*aligned(self, self._check_points(target)))
        return T.rotation()._apply_kernel(target) + T.translation()

    def multiply(self, other: Self) -> Self:
        a, b = materialize(*aligned(self, other))
        R = a.rotation()
        return type(self).from_rotation_and_translation(
            R._multiply_kernel(b.rotation()), R._apply_kernel(b.translation()) + a.translation()
        )

    def _between(self, other: Self) -> Self:
        """``self⁻¹ @ other`` as (R_a⁻¹ R_b, R_a⁻¹(t_b − t_a)): the difference of nearby
        translations is exact (Sterbenz), where ``inverse().multiply`` adds −R_a⁻¹t_a to
        R_a⁻¹t_b and cancels ε·|t_a| (float32 poses 2·10⁴ from the origin, 0.5 apart:
        the residual was off by 1e-3, 10⁴ ulp against mpmath; now ≤ 1.5 ulp). One rotation
        of a point instead of two."""
        a, b = materialize(*aligned(self, other))
        R_inv = a.rotation().inverse()
        return type(self).from_rotation_and_translation(
            R_inv._multiply_kernel(b.rotation()),
            R_inv._apply_kernel(b.translation() - a.translation()),
        )

    def inverse(self) -> Self:
        T = materialize(self) if self._rotation_type._kernels_reread else self
        R_inv = T.rotation().inverse()
        return type(self).from_rotation_and_translation(
            R_inv, -R_inv._apply_kernel(T.translation())
        )

    def normalize(self) -> Self:
        return type(self).from_rotation_and_translation(
            self.rotation().normalize(), self.translation()
        )

    def as_matrix(self) -> jax.Array:
        R = self.rotation()._matrix_block()
        t = self.translation()
        n = self.space_dim
        batch = jnp.broadcast_shapes(R.shape[:-2], t.shape[:-1])
        top = jnp.concatenate(
            [jnp.broadcast_to(R, (*batch, n, n)), jnp.broadcast_to(t, (*batch, n))[..., None]],
            axis=-1,
        )
        bottom = jnp.broadcast_to(
            jnp.eye(n + 1, dtype=t.dtype)[n], (*batch, 1, n + 1)
        )
        return jnp.concatenate([top, bottom], axis=-2)

    @classmethod
    def from_matrix(cls, matrix: hints.Array) -> Self:
        m = cls._check_matrix(matrix, "from_matrix")
        n = cls.space_dim
        return cls.from_rotation_and_translation(
            cls._rotation_type.from_matrix(m[..., :n, :n]), m[..., :n, n]
        )

    @classmethod
    def sample_uniform(
        cls, key: jax.Array, batch_axes: Tuple[int, ...] = (), dtype: Any = None
    ) -> Self:
        dtype = resolve_dtype(dtype)
        key0, key1 = jax.random.split(key)
        rot = cls._rotation_type.sample_uniform(key0, batch_axes, dtype)
        t = jax.random.uniform(
            key1, (*batch_axes, cls.space_dim), dtype=dtype, minval=-1.0, maxval=1.0
        )
        return cls.from_rotation_and_translation(rot, t)

    def _rplus_jacobian(self) -> jax.Array:
        # parameters = (q, t); T @ exp(δ) has q' = q·exp(δ_rot) to first order and
        # t' = t + R δ_trans (the V matrix is I + O(δ)).
        R = self.rotation()
        Jq = R._rplus_jacobian()  # (*batch, k_rot_params, k_rot_tangent)
        Rm = R._matrix_block()
        batch = Rm.shape[:-2]
        n, kq = self.space_dim, Jq.shape[-2]
        top = jnp.concatenate(
            [jnp.zeros((*batch, kq, n), Rm.dtype), Jq], axis=-1
        )
        bottom = jnp.concatenate(
            [Rm, jnp.zeros((*batch, n, Jq.shape[-1]), Rm.dtype)], axis=-1
        )
        return jnp.concatenate([top, bottom], axis=-2)
