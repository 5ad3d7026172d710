"""The interface of a matrix Lie group, and what every group and every semidirect product
does once.

Conventions used throughout the package:

* Elements are frozen dataclasses with a single array field holding the parameters,
  shape ``(*batch, parameters_dim)``; leading batch axes broadcast numpy-style between
  operands.
* Perturbations are on the right: ``T ⊕ δ = T @ exp(δ)`` (jaxlie's convention, and Solà,
  Deray and Atchuthan, *A micro Lie theory for state estimation in robotics* (2018), §III);
  ``adjoint`` moves tangents across: ``T @ exp(δ) = exp(Ad(T) δ) @ T``.
* Tangent orderings follow jaxlie: SE(2) ``(vx, vy, θ)``, SE(3) ``(v, ω)``. Eberly, *Lie
  Groups and Lie Algebras* (2024), §10, orders SE(3) rotation-first; the formulas here are
  adapted.
* Constructors never validate (JAX rebuilds pytrees with non-array leaves); factories and
  operations do, at trace time, raising ``ValueError`` that names the expected and the
  received shape (``_checks``). The values (finite, a unit rotation part) are checked on
  request, at run time: ``is_valid``, and ``check_valid`` through checkify.
"""

from __future__ import annotations

import abc
import dataclasses
import inspect
from typing import (
    Any,
    ClassVar,
    Generic,
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
from typing_extensions import Self, final

from . import hints
from ._batch import pairwise_in_chunks
from ._checks import (
    as_float_array,
    check_batches,
    check_index,
    check_type,
    default_float,
    resolve_dtype,
)
from ._jit import jit_public_methods
from ._scalar import components
from ._xla import Schedule, aligned, materialize, matmul_unrolled


class MatrixLieGroup(abc.ABC):
    """Interface of a matrix Lie group whose elements are stored as parameter arrays.

    Subclasses are frozen dataclasses with one array field named after its layout
    (``unit_complex``, ``wxyz``, ``wxyz_xyz``, ...), registered as pytrees with
    ``_pytree.pytree_dataclass``. Every public method of a concrete subclass is wrapped in
    ``jax.jit`` with trace-time checks of its element arguments (``_jit``).
    """

    matrix_dim: ClassVar[int]
    """Size n of the n×n matrix from ``as_matrix()``."""
    parameters_dim: ClassVar[int]
    """Length of the parameter vector, ``parameters().shape[-1]``."""
    tangent_dim: ClassVar[int]
    """Dimension k of the tangent space (the Lie algebra)."""
    space_dim: ClassVar[int]
    """Dimension of the points the group acts on."""
    _schedule: ClassVar[Schedule] = Schedule()
    """How XLA schedules the group's kernels, never their values (``_xla.Schedule``)."""

    # -- construction ---------------------------------------------------------------

    def __init__(self, parameters: jax.Array):  # pragma: no cover - replaced by dataclass
        raise NotImplementedError

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if not inspect.isabstract(cls):
            jit_public_methods(cls)

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
    def from_matrix(cls, matrix: hints.Array, project: bool = False) -> Self:
        """The element a matrix represents: its rotation block converted by Shepperd's
        formulas with one power step (a rotation matrix gives its rotation to a few ulp, a
        matrix a little off the rotations the nearest rotation to second order in the
        deviation), or with ``project=True`` projected onto the rotations (the nearest in
        the Frobenius norm, for any block); for SE groups the translation column taken as
        is and the bottom row ignored.

        Args:
            matrix: ``(*batch, matrix_dim, matrix_dim)`` (homogeneous for SE groups).
            project: static; project an arbitrary rotation block exactly.

        Returns:
            The element, with batch axes ``batch``, in the matrix's dtype."""

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

    def is_valid(self, atol: Optional[hints.Scalar] = None) -> jax.Array:
        """Whether each element is a group element: all its parameters are finite and its
        rotation part (the unit complex number of SO2/SE2, the unit quaternion of SO3, SE3,
        Sim3 and SE23) has a norm within ``atol`` of 1 (Sim3's scale e^σ is positive for
        every finite log-scale σ). Constructors do not check this; use it (or
        ``check_valid`` under ``jax.experimental.checkify``) on parameters that come from
        outside the group operations: an optimiser's additive update, a file, a cast.

        Runs under ``jit``, ``vmap`` and ``grad`` (the result is boolean and carries no
        derivative), for any batch axes and floating dtype.

        Args:
            atol: tolerance on | ‖rotation part‖ − 1 |, ≥ 0: a scalar, or an array that
                broadcasts against the batch axes. Default √ε of the parameters' dtype:
                float32 3.5e-4, float64 1.5e-8, float16 3.1e-2, bfloat16 8.8e-2. Each
                composition moves the norm by about an ulp, as a random walk, so √ε
                accepts the chains of compositions a program runs without ``normalize``,
                while unnormalized or mis-scaled parameters are off by far more
                (docs/design/validity-tolerance.md). A float32 element cast to float64
                can be off by about 1e-7, not valid at float64's default: ``normalize()``
                it after the cast.

        Returns:
            Boolean array of shape ``broadcast(batch, atol.shape)``: the batch shape for a
            scalar ``atol``.
        """
        p = self.parameters()
        u = self._unit_part()
        if not jnp.issubdtype(p.dtype, jnp.floating):  # integers: the default float
            p, u = p.astype(default_float()), u.astype(default_float())
        if atol is None:
            tol = jnp.asarray(valid_atol(p.dtype), p.dtype)
        else:
            where = f"{type(self).__name__}.is_valid"
            tol = as_float_array(atol, "atol", (), where, like=p).astype(p.dtype)
        # |‖u‖ − 1| ≤ atol as bounds on ‖u‖², with no square root: NaN fails both
        # comparisons, an overflowing ‖u‖² (inf) the upper one.
        n2 = jnp.sum(jnp.square(u), axis=-1)
        low = jnp.square(jnp.maximum(1 - tol, 0))
        high = jnp.square(1 + tol)
        return (n2 >= low) & (n2 <= high) & jnp.all(jnp.isfinite(p), axis=-1)

    def _unit_part(self) -> jax.Array:
        """The parameters that hold a unit rotation (complex number or quaternion),
        ``(*batch, k)``: all of them for a rotation group, the leading ones for an SE
        group. Groups outside ``SOBase`` and ``SEBase`` override it."""
        raise NotImplementedError(
            f"{type(self).__name__}: is_valid needs _unit_part, the parameters that hold "
            "the unit rotation."
        )

    def jlog(self) -> jax.Array:
        """Jacobian of the log under right perturbations, the inverse right Jacobian at
        ``log()``: ``d/dδ log(T @ exp(δ))`` at δ = 0, shape
        ``(*batch, tangent_dim, tangent_dim)``. (The log is computed into memory first:
        fused into the Jacobian's entries, XLA:CPU would recompute it for each.)"""
        return type(self).jac_right_inv(materialize(self.log()))

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

    def _adjoint_apply(self, tangent: jax.Array) -> jax.Array:
        """``Ad(self) x`` for tangents ``(…, k)`` whose batch broadcasts with ``self``'s.
        Groups whose adjoint has zero or repeated blocks apply it without the matrix."""
        return matmul_unrolled(self.adjoint(), tangent[..., None])[..., 0]

    @classmethod
    def _bracket(cls, a: jax.Array, b: jax.Array) -> jax.Array:
        """The Lie bracket ``[a, b] = ad(a) b = vee(â b̂ − b̂ â)``, batch axes broadcast."""
        return matmul_unrolled(cls.ad(a), b[..., None])[..., 0]

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

    # -- geodesics (Eberly 2024, §4) ----------------------------------------------

    def interpolate(self, other: Self, t: hints.Scalar) -> Self:
        """Point at time ``t`` on the geodesic from ``self`` (t = 0) to ``other`` (t = 1).

        Body form ``self @ exp(t · log(self⁻¹ @ other))``, which equals Eberly's left form
        ``exp(t · log(other @ self⁻¹)) @ self`` (*Lie Groups and Lie Algebras*, 2024, eq. 9)
        except where the relative rotation is exactly π, and which does not lose
        ε·|translation| to cancellation far from the origin. At a relative rotation of
        exactly π the principal log's tie-break applies (quaternion with w = 0: −π times
        the stored vector part's direction, as jaxlie).

        Args:
            other: end point; batch axes broadcast with ``self``.
            t: scalar or array; it broadcasts numpy-style against the batch axes (unbatched
                endpoints with ``t`` of shape (K,) give K poses; an outer product is
                ``t[:, None]``). Values outside [0, 1] extrapolate along the same curve.

        Returns:
            Elements of batch shape ``broadcast(self, other, t)``, dtype of the endpoints.

        Large batches of one shape run in chunks on CPU, which bounds the temporaries
        (``docs/design/memory-and-chunks.md``); the values are the same.
        """
        if self._schedule.interpolate_in_chunks:
            where = f"{type(self).__name__} geodesic"
            return pairwise_in_chunks(_interpolate, self, other, t, where)
        return _interpolate(self, other, jnp.asarray(t))

    def _along(self, tangent: jax.Array, t: hints.Scalar) -> Self:
        """``self @ exp(t · tangent)``, the geodesic through ``self`` with body velocity
        ``tangent`` (``(*B, tangent_dim)``) at times ``t`` (broadcast against ``B``)."""
        G = type(self)
        where = f"{G.__name__} geodesic"
        t = as_float_array(t, "t", (), where, like=tangent)
        batch = check_batches(where, "batch axes of the path and of t", tangent.shape[:-1], t.shape)
        t = jnp.broadcast_to(t.astype(jnp.result_type(t, tangent)), batch)
        t, tangent = aligned(t[..., None], self._schedule.along(tangent))
        return self.multiply(self._schedule.along(G.exp(t * tangent)))

    # -- batch handling -------------------------------------------------------------

    def __getitem__(self, index: Any) -> Self:
        """Index the batch axes: ``T[0]``, ``T[:, 1]``, ``T[mask]``, ``T[..., None]``. A static
        index out of range (a Python or NumPy integer, or a list or NumPy array of them, also
        after ``...``) raises ``IndexError``, as in NumPy (JAX would clamp it, and Python's
        iteration fallback relies on the error); jax arrays and traced indices clamp, as in
        JAX."""
        index = index if isinstance(index, tuple) else (index,)
        index = tuple(
            bool(i) if isinstance(i, onp.bool_) else i for i in index
        )  # jnp fails on them
        check_index(type(self).__name__, self.get_batch_axes(), index)
        # In the stored layout, the parameter axis last: NumPy's rules put the advanced
        # indices' axes first when they are not adjacent, which keeps that axis last.
        if not any(i is Ellipsis for i in index):  # `is`: ndarray == ... is elementwise
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
            parts = [
                (dataclasses.fields(rotation)[0].name, v[..., :k]),
                (name.rsplit("_", 1)[1], v[..., k:]),
            ]
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
            where,
            "batch axes of the element and the points",
            self.get_batch_axes(),
            points.shape[:-1],
        )
        return points

    @abc.abstractmethod
    def _linear_part(self) -> jax.Array:
        """R, the matrix of the action's linear part ``p ↦ R p (+ t)``:
        ``(*batch, space_dim, space_dim)``."""

    @classmethod
    def _generator_action(cls, points: jax.Array) -> jax.Array:
        """K(p) = d (hat(δ) p̃)[:space_dim] / dδ, ``(*batch, space_dim, tangent_dim)``, for
        checked points ``(*batch, space_dim)`` (p̃ = (p, 1) when the matrix is homogeneous).
        Entry (i, j) is Σ_l hat(e_j)[i, l] p̃_l, written out from the constant generators:
        e.g. ``[I, −p̂]`` for SE(3), ``−p̂`` for SO(3)."""
        n, d = cls.matrix_dim, cls.space_dim
        coords = list(components(points))
        if n > d:  # homogeneous coordinates (p, 1, 0, …): SE₂(3)'s velocity column reads 0
            coords.append(jnp.ones_like(coords[0]))
            coords.extend(jnp.zeros_like(coords[0]) for _ in range(n - d - 1))
        with jax.ensure_compile_time_eval():
            E = onp.asarray(cls.hat(onp.eye(cls.tangent_dim)))  # (k, n, n), entries 0 and ±1

        def combine(coeffs: onp.ndarray) -> jax.Array:  # Σ_l coeffs[l] · coords[l]
            terms = [c * x for c, x in zip(coeffs.tolist(), coords) if c != 0.0]
            return sum(terms[1:], terms[0]) if terms else jnp.zeros_like(coords[0])

        rows = [jnp.stack([combine(E[j, i]) for j in range(cls.tangent_dim)], -1) for i in range(d)]
        return jnp.stack(rows, axis=-2)

    def _action_jacobian(self, points: jax.Array) -> jax.Array:
        """d (T ⊕ δ) p / dδ at δ = 0 = R K(p) (Solà et al. 2018, eqs. 166 and 181), for
        points ``(*batch, space_dim)`` of the element's dtype, aligned with it:
        ``(*batch, space_dim, tangent_dim)``."""
        R = self._linear_part()
        batch = jnp.broadcast_shapes(R.shape[:-2], points.shape[:-1])
        K = self._generator_action(jnp.broadcast_to(points, (*batch, points.shape[-1])))
        return matmul_unrolled(jnp.broadcast_to(R, (*batch, *R.shape[-2:])), K)

    @abc.abstractmethod
    def _rplus_jacobian(self) -> jax.Array:
        """d parameters(T @ exp(δ)) / dδ at δ = 0: ``(*batch, parameters_dim, tangent_dim)``."""


class SOBase(MatrixLieGroup):
    """Base class for special orthogonal groups."""

    # ``apply`` and ``multiply`` check and align their inputs, then call the group's
    # kernels, which the SE groups also call on the rotation part of their elements.

    def apply(self, target: hints.Array) -> jax.Array:
        R, p = self._schedule.inputs(*aligned(self, self._check_points(target)))
        return R._apply_kernel(p)

    def multiply(self, other: Self) -> Self:
        a, b = self._schedule.inputs(*aligned(self, other))
        return a._multiply_kernel(b)

    @abc.abstractmethod
    def _apply_kernel(self, points: jax.Array) -> jax.Array:
        """The rotated points, ``(*batch, space_dim)``, for checked points whose batch axes
        have the element's rank."""

    @abc.abstractmethod
    def _multiply_kernel(self, other: Self) -> Self:
        """``self @ other`` for an element of the same batch rank."""

    def _matrix_block(self) -> jax.Array:
        """``as_matrix`` in the form that fuses best into a larger matrix (an SE group's
        homogeneous matrix or Jacobians); SO2 overrides it."""
        return self.as_matrix()

    def _linear_part(self) -> jax.Array:
        return self._matrix_block()

    def _unit_part(self) -> jax.Array:
        return self.parameters()


ContainedSOType = TypeVar("ContainedSOType", bound=SOBase)
GroupT = TypeVar("GroupT", bound=MatrixLieGroup)
"""An element of any one group (shared by the modules that take elements)."""


class SEBase(Generic[ContainedSOType], MatrixLieGroup):
    """Base class for special Euclidean groups: a rotation and a translation, stored as
    ``(rotation parameters, translation)``. Composition, inverse, action and
    normalisation are the semidirect-product formulas, written once here in terms of
    the rotation's closed-form operations."""

    _rotation_type: ClassVar[Type[Any]]  # the SO group (ContainedSOType); set by each subclass

    # -- SE-specific interface ------------------------------------------------------

    @classmethod
    def from_rotation_and_translation(
        cls, rotation: ContainedSOType, translation: hints.Array
    ) -> Self:
        """Rigid transform ``x ↦ R x + t``; batch axes of the two broadcast.

        Args:
            rotation: an element of the matching SO group.
            translation: shape ``(*batch, space_dim)``.
        """
        check_type(
            f"{cls.__name__}.from_rotation_and_translation",
            "rotation",
            rotation,
            cls._rotation_type,
        )
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
        batch = check_batches(
            where, "rotation and translation batch axes", r.shape[:-1], t.shape[:-1]
        )
        r = jnp.broadcast_to(r.astype(dtype), (*batch, r.shape[-1]))
        t = jnp.broadcast_to(t.astype(dtype), (*batch, t.shape[-1]))
        return cls(jnp.concatenate([r, t], axis=-1))

    @classmethod
    def from_rotation(cls, rotation: ContainedSOType) -> Self:
        """Pure rotation (zero translation), with the rotation's batch axes."""
        check_type(f"{cls.__name__}.from_rotation", "rotation", rotation, cls._rotation_type)
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

    def _linear_part(self) -> jax.Array:
        return self.rotation()._matrix_block()

    def _unit_part(self) -> jax.Array:
        return self.rotation()._unit_part()

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

    # Barriers on whole elements only, then the rotation's kernels on slices: with jax ≥ 0.11
    # XLA:CPU turns a barrier on a slice into a copy of it.

    def apply(self, target: hints.Array) -> jax.Array:
        T, target = self._schedule.inputs(*aligned(self, self._check_points(target)))
        return T.rotation()._apply_kernel(target) + T.translation()

    def multiply(self, other: Self) -> Self:
        a, b = self._schedule.inputs(*aligned(self, other))
        R = a.rotation()
        return type(self).from_rotation_and_translation(
            R._multiply_kernel(b.rotation()), R._apply_kernel(b.translation()) + a.translation()
        )

    def _between(self, other: Self) -> Self:
        """``self⁻¹ @ other`` as (R_a⁻¹ R_b, R_a⁻¹(t_b − t_a)): the difference of nearby
        translations is exact (Sterbenz), where ``inverse().multiply`` adds −R_a⁻¹t_a to
        R_a⁻¹t_b and cancels ε·|t_a| (docs/design/relative-poses.md). One rotation of a
        point instead of two."""
        a, b = self._schedule.inputs(*aligned(self, other))
        R_inv = a.rotation().inverse()
        return type(self).from_rotation_and_translation(
            R_inv._multiply_kernel(b.rotation()),
            R_inv._apply_kernel(b.translation() - a.translation()),
        )

    def inverse(self) -> Self:
        T = self._schedule.inputs(self)
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
        bottom = jnp.broadcast_to(jnp.eye(n + 1, dtype=t.dtype)[n], (*batch, 1, n + 1))
        return jnp.concatenate([top, bottom], axis=-2)

    @classmethod
    def from_matrix(cls, matrix: hints.Array, project: bool = False) -> Self:
        """Pose from a ``(*batch, n+1, n+1)`` homogeneous matrix [[A, t], [·, ·]]: the
        rotation of the block A by the rotation group's ``from_matrix`` (with ``project``:
        the rotation nearest to any A), the translation t as is; the bottom row is not
        read (it is not checked to be (0, …, 0, 1)). Batch axes ``batch``, the matrix's
        dtype."""
        m = cls._check_matrix(matrix, "from_matrix")
        n = cls.space_dim
        return cls.from_rotation_and_translation(
            cls._rotation_type.from_matrix(m[..., :n, :n], project), m[..., :n, n]
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
        top = jnp.concatenate([jnp.zeros((*batch, kq, n), Rm.dtype), Jq], axis=-1)
        bottom = jnp.concatenate([Rm, jnp.zeros((*batch, n, Jq.shape[-1]), Rm.dtype)], axis=-1)
        return jnp.concatenate([top, bottom], axis=-2)


def valid_atol(dtype: Any) -> float:
    """``is_valid``'s default tolerance on | ‖rotation part‖ − 1 |: √ε of ``dtype``
    (float32 3.5e-4, float64 1.5e-8, float16 3.1e-2, bfloat16 8.8e-2)."""
    return float(onp.sqrt(float(jnp.finfo(dtype).eps)))


def _interpolate(a: GroupT, b: GroupT, t: Any) -> GroupT:
    """``a @ exp(t · log(a⁻¹ @ b))``: ``interpolate``'s body, element by element."""
    return a._along(a._schedule.along(a._between(b)).log(), t)
