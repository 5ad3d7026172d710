"""Nonlinear least squares on Lie groups as a JAX function: it runs inside ``jax.jit``, under
``jax.vmap`` over problems of one structure, and differentiates through its optimum.

A problem is a set of variables and a list of factors. The variables are a tuple of
*variable sets*, each a batched group element (any of the six groups, leading axis the n
elements of the set) or an array ``(n, d)``. A ``Factor`` is one residual function, vmapped
over its F factors: ``residual(*args, data)`` takes one element (or row) of each of the sets
it names (``sets``), at the indices its ``indices`` give, and that factor's slice of
``data``, and returns its whitened residual, shape ``(r,)``. The cost is ½ Σ_f ρ(‖r_f‖²)
(ρ(s) = s without a robust kernel).

``solve`` minimises the cost by Levenberg–Marquardt (Levenberg, *A method for the solution of
certain non-linear problems in least squares*, 1944; Marquardt, *An algorithm for
least-squares estimation of nonlinear parameters*, 1963) or Gauss–Newton, in one
``lax.while_loop``, with the damping policy ``solve`` describes and the stopping rules
``StopReason`` names (``pose_graph.solve`` is one of its users). Steps are right
perturbations, X ⊕ δ = X @ exp(δ) for a group element and x + δ for an array
(``manifold.rplus``); the residuals' Jacobians in those tangents come from forward-mode
autodiff, or from a closed form the factor supplies (``Factor.jacobian``). The
normal equations (H + λD) δ = −g, H = JᵀJ, are solved by the linear solver ``solve``'s
``linear_solver`` names: a dense Cholesky for problems of up to a few thousand unknowns (a
batch of small problems under ``vmap``, inverse kinematics, calibration, a small pose
graph), conjugate gradients or a sparse Cholesky for larger ones.

The derivative of the solution with respect to every array the residuals read (the factors'
``data``) is the implicit function theorem's at the returned point x*: with G(x, θ) the
gradient of the cost in x's tangent and H* its Hessian (the exact one, by autodiff),
dx*/dθ = −H*⁻¹ ∂G/∂θ. It costs one extra dense Hessian and one solve, and no differentiation
through the iterations. It is the derivative of the optimum where the solve converged; where
it stopped early it is that of the minimiser of the local quadratic model at x*, and it is
kept finite: H* is damped by the final λ (D as in the solve; by ``MIN_DAMPING`` where the
solve stopped because no step lowered the cost, a minimum to working precision at which λ
has grown without meaning), and a system that Cholesky cannot factor gives a zero
derivative. The initial values get no derivative (the optimum does
not depend on them).
"""

from __future__ import annotations

import dataclasses
import enum
import functools
import typing
from typing import Any, Callable, Literal, NamedTuple, Optional, Sequence, Tuple, Union

import jax
import jax.numpy as jnp
import numpy as onp

from . import _sparse, hints
from ._base import MatrixLieGroup

__all__ = [
    "Factor",
    "Solution",
    "StopReason",
    "solve",
    "cost",
    "marginal_covariances",
]

#: λ is divided by this after a step that lowers the cost, and multiplied by ν (then 2ν, ...)
#: after one that does not (ν starts at this value after every accepted step).
DAMPING_FACTOR = 10.0
#: λ is never divided below this, so that a failed step can still raise it.
MIN_DAMPING = 1e-15
#: λ beyond which Levenberg–Marquardt stops: no damped step lowers the cost.
MAX_DAMPING = 1e16
#: The floor of D = diag(H) with ``diagonal_damping``, so that a direction H does not see
#: is still damped.
DAMPING_FLOOR = 1e-6

Variable = Union[MatrixLieGroup, jax.Array]
Robust = Optional[Tuple[Literal["huber", "cauchy"], float]]


class StopReason(enum.IntEnum):
    """Why ``solve`` stopped; ``Solution.stop_reason`` holds the code (an int array under
    ``vmap``). ``converged`` is true for the three middle ones."""

    #: ``max_iterations`` accepted steps were taken.
    MAX_ITERATIONS = 0
    #: An accepted step lowered the cost by less than ``tolerance`` relative.
    DECREASE_BELOW_TOLERANCE = 1
    #: The linear model predicts, for an iteration's first (least damped) step, a relative
    #: decrease below ``tolerance``.
    PREDICTED_DECREASE_BELOW_TOLERANCE = 2
    #: λ passed ``MAX_DAMPING`` without a step lowering the cost: a minimum to working
    #: precision.
    NO_STEP_LOWERS_COST = 3
    #: Gauss–Newton: a step raised the cost; the previous estimate is kept.
    STEP_RAISED_COST = 4
    #: Gauss–Newton: the linear system gave a non-finite step (a singular system).
    NON_FINITE_STEP = 5
    #: The cost at a linearisation point is not finite: NaN or ±inf in data or values that
    #: the residuals read, or residuals that overflow there. The values of that point are
    #: returned.
    NON_FINITE_COST = 6

    @property
    def description(self) -> str:
        """The reason in words."""
        return _DESCRIPTIONS[self]


_DESCRIPTIONS = {
    StopReason.MAX_ITERATIONS: "reached max_iterations",
    StopReason.DECREASE_BELOW_TOLERANCE: "the relative decrease of the cost fell below tolerance",
    StopReason.PREDICTED_DECREASE_BELOW_TOLERANCE: (
        "the linear model predicts a relative decrease below tolerance"
    ),
    StopReason.NO_STEP_LOWERS_COST: f"no step lowers the cost (λ > {MAX_DAMPING:g})",
    StopReason.STEP_RAISED_COST: (
        "a Gauss–Newton step raised the cost; the previous estimate is kept"
    ),
    StopReason.NON_FINITE_STEP: "the linear system gave a non-finite step",
    StopReason.NON_FINITE_COST: "the cost is not finite (NaN or ±inf in the data or values)",
}


_CONVERGED = (
    StopReason.DECREASE_BELOW_TOLERANCE,
    StopReason.PREDICTED_DECREASE_BELOW_TOLERANCE,
    StopReason.NO_STEP_LOWERS_COST,
)


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Factor:
    """F residuals of one form.

    Attributes:
        residual: ``residual(*args, data) -> (r,)`` for one factor (``residual(*args)`` when
            ``data`` is None), the whitened residual (multiply by the square root of the
            information yourself). It sees one element of each variable set it reads:
            a group element with no batch axes, or a ``(d,)`` row. Static: ``jit`` keys its
            programs on it, so pass the same function object for the same residual.
        sets: for each argument of ``residual``, the position of its variable set in
            ``solve``'s ``variables`` (static ints).
        indices: for each argument, an int array ``(F,)`` of elements of that set; all of
            length F.
        data: a pytree of arrays with leading axis F (or None), sliced per factor.
            Differentiable: ``jax.grad`` of a function of ``solve``'s result reaches it.
        robust: None, or ``("huber", k)`` or ``("cauchy", k)``: ρ(s) = s for s ≤ k², and
            2k√s − k² beyond (Huber), or ρ(s) = k² log(1 + s/k²) (Cauchy), s = ‖r‖².
            Applied by reweighting each factor by √ρ'(s) at the linearisation point.
        jacobian: None (forward-mode autodiff of ``residual``), or a closed form with
            ``residual``'s arguments that returns the residual and its Jacobian together,
            ``(r, J)`` with r ``(r,)`` and J ``(r, K)``: K the sum of the arguments' tangent
            dimensions, the arguments' columns side by side in argument order, each in the
            right-perturbation tangent (X ⊕ δ = X @ exp(δ) for a group element, x + δ for a
            row; ``jaxlie_geo.jacobians``' convention). The linearisation calls it instead
            of ``residual``; the cost and the implicit derivative (which needs second
            derivatives) still use ``residual``, so the two must agree. Static, as
            ``residual``.
    """

    residual: Callable[..., jax.Array] = dataclasses.field(metadata=dict(static=True))
    sets: Tuple[int, ...] = dataclasses.field(metadata=dict(static=True))
    indices: Tuple[jax.Array, ...]
    data: Any = None
    robust: Robust = dataclasses.field(default=None, metadata=dict(static=True))
    jacobian: Optional[Callable[..., Tuple[jax.Array, jax.Array]]] = dataclasses.field(
        default=None, metadata=dict(static=True)
    )

    def __post_init__(self) -> None:
        if not callable(self.residual):
            raise TypeError(f"Factor: residual must be callable, got {type(self.residual)}")
        if self.jacobian is not None and not callable(self.jacobian):
            raise TypeError(f"Factor: jacobian must be callable, got {type(self.jacobian)}")
        if len(self.sets) != len(self.indices):
            raise ValueError(f"Factor: {len(self.sets)} sets but {len(self.indices)} index arrays")
        if self.robust is not None and (
            len(self.robust) != 2 or self.robust[0] not in ("huber", "cauchy")
        ):
            raise ValueError(f"Factor: robust must be ('huber' | 'cauchy', k), got {self.robust}")


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Solution:
    """What ``solve`` returns; under ``vmap`` every field has the batch axis.

    Attributes:
        variables: the solution, the structure of ``solve``'s ``variables``.
        cost: the cost ½ Σ ρ(‖r‖²) at the solution.
        initial_cost: the cost at the initial values.
        iterations: accepted steps, an int array.
        stop_reason: a ``StopReason`` code, an int array.
        converged: whether ``stop_reason`` is one of the three converged ones.
        damping: λ at the end (0 for Gauss–Newton).
    """

    variables: Tuple[Variable, ...]
    cost: jax.Array
    initial_cost: jax.Array
    iterations: jax.Array
    stop_reason: jax.Array
    converged: jax.Array
    damping: jax.Array


# -- the problem's layout --------------------------------------------------------------


def _tangent_dim(v: Variable) -> int:
    return type(v).tangent_dim if isinstance(v, MatrixLieGroup) else v.shape[-1]


def _count(v: Variable) -> int:
    shape = v.get_batch_axes() if isinstance(v, MatrixLieGroup) else v.shape[:-1]
    if len(shape) != 1:
        raise ValueError(
            "least_squares: each variable set needs exactly one batch axis (n elements), got "
            f"{type(v).__name__} with batch shape {tuple(shape)}"
        )
    return int(shape[0])


def _offsets(variables: Sequence[Variable]) -> Tuple[int, ...]:
    sizes = [_count(v) * _tangent_dim(v) for v in variables]
    return tuple(int(sum(sizes[:i])) for i in range(len(sizes) + 1))


def _retract(variables: Tuple[Variable, ...], delta: jax.Array) -> Tuple[Variable, ...]:
    """Every set moved by its slice of the flat tangent ``delta``."""
    out, offsets = [], _offsets(variables)
    for i, v in enumerate(variables):
        d = delta[offsets[i] : offsets[i + 1]].reshape(_count(v), _tangent_dim(v))
        out.append(v @ type(v).exp(d) if isinstance(v, MatrixLieGroup) else v + d)
    return tuple(out)


def _take(v: Variable, idx: jax.Array) -> Variable:
    return v[idx] if isinstance(v, MatrixLieGroup) else v[idx, :]


def _check(factors: Sequence[Factor], variables: Tuple[Variable, ...]) -> None:
    """Trace-time errors for factors that do not fit the variables."""
    for j, f in enumerate(factors):
        counts = set()
        for s, index in zip(f.sets, f.indices):
            if not (isinstance(s, int) and 0 <= s < len(variables)):
                raise ValueError(
                    f"least_squares: factor {j} names variable set {s!r}; there are "
                    f"{len(variables)} (0 to {len(variables) - 1})"
                )
            concrete = not isinstance(index, jax.core.Tracer)
            idx: Any = onp.asarray(index) if concrete else index
            if idx.ndim != 1 or not jnp.issubdtype(idx.dtype, jnp.integer):
                raise ValueError(
                    f"least_squares: factor {j}'s indices must be an int array (F,), got "
                    f"shape {idx.shape} dtype {idx.dtype}"
                )
            if concrete:
                n = _count(variables[s])
                if idx.size and (int(idx.min()) < 0 or int(idx.max()) >= n):
                    raise IndexError(
                        f"least_squares: factor {j}'s indices into set {s} span "
                        f"[{int(idx.min())}, {int(idx.max())}], outside [0, {n})"
                    )
            counts.add(idx.shape[0])
        if len(counts) != 1:
            raise ValueError(f"least_squares: factor {j}'s index arrays differ in length")


# -- linearisation ---------------------------------------------------------------------


def _rho(robust: Robust, s: jax.Array) -> Tuple[jax.Array, jax.Array]:
    """ρ(s) and ρ'(s) of a robust kernel (s = ‖r‖²)."""
    if robust is None:
        return s, jnp.ones_like(s)
    kind, k = robust
    k2 = jnp.asarray(k, s.dtype) ** 2
    if kind == "huber":
        root = jnp.sqrt(jnp.maximum(s, k2))
        inside = s <= k2
        return jnp.where(inside, s, 2 * jnp.sqrt(k2) * root - k2), jnp.where(
            inside, 1.0, jnp.sqrt(k2) / root
        )
    return k2 * jnp.log1p(s / k2), 1.0 / (1.0 + s / k2)


def _factor_residuals(f: Factor, variables: Tuple[Variable, ...]) -> jax.Array:
    """``(F, r)``: every factor's residual at the variables."""
    args = tuple(_take(variables[s], jnp.asarray(idx)) for s, idx in zip(f.sets, f.indices))
    call = f.residual if f.data is None else (lambda *a: f.residual(*a[:-1], a[-1]))
    inputs = args if f.data is None else (*args, f.data)
    r = jax.vmap(call)(*inputs)
    if r.ndim != 2:
        raise ValueError(
            f"least_squares: a residual must return a vector (r,), got shape {r.shape[1:]}"
        )
    return r


@jax.jit
def cost(factors: Sequence[Factor], variables: Tuple[Variable, ...]) -> jax.Array:
    """The cost ½ Σ_f ρ(‖r_f‖²) over every factor, a scalar."""
    total = jnp.zeros((), _dtype(variables))
    for f in factors:
        r = _factor_residuals(f, variables)
        total = total + 0.5 * jnp.sum(_rho(f.robust, jnp.sum(r * r, axis=-1))[0])
    return total


def _dtype(variables: Tuple[Variable, ...]) -> Any:
    leaves = jax.tree_util.tree_leaves(variables)
    return jnp.result_type(*leaves) if leaves else jnp.float32


class _Block(NamedTuple):
    """One factor set, linearised: whitened (and robustly reweighted) residuals e ``(F, r)``,
    the Jacobian blocks of all its arguments side by side M ``(F, r, K)``, and the flat
    tangent coordinates of those columns ``(F, K)``."""

    e: jax.Array
    M: jax.Array
    cols: jax.Array


def _columns(f: Factor, variables: Tuple[Variable, ...]) -> jax.Array:
    """``(F, K)``: the flat tangent coordinate of each of a factor's Jacobian columns."""
    offsets = _offsets(variables)
    parts = []
    for s, idx in zip(f.sets, f.indices):
        k = _tangent_dim(variables[s])
        parts.append(offsets[s] + jnp.asarray(idx)[:, None] * k + jnp.arange(k))
    return jnp.concatenate(parts, axis=1)


def _linearise(
    factors: Sequence[Factor], variables: Tuple[Variable, ...]
) -> Tuple[jax.Array, Tuple[_Block, ...]]:
    """The cost and every factor set's ``_Block`` at the variables: Jacobians by forward-mode
    autodiff in the right-perturbation tangent of each argument; a robust kernel reweights
    e and M by √ρ'(‖r‖²) (iteratively reweighted least squares)."""
    dtype = _dtype(variables)
    total = jnp.zeros((), dtype)
    blocks = []
    for f in factors:
        args = tuple(_take(variables[s], jnp.asarray(idx)) for s, idx in zip(f.sets, f.indices))
        dims = tuple(_tangent_dim(variables[s]) for s in f.sets)

        def one(arg_values, data, f=f, dims=dims):
            def at(delta):
                parts = jnp.split(delta, onp.cumsum(dims)[:-1])
                moved = [
                    a @ type(a).exp(d) if isinstance(a, MatrixLieGroup) else a + d
                    for a, d in zip(arg_values, parts)
                ]
                return f.residual(*moved) if f.data is None else f.residual(*moved, data)

            if f.jacobian is not None:
                return f.jacobian(*arg_values) if f.data is None else f.jacobian(*arg_values, data)
            zero = jnp.zeros((sum(dims),), dtype)
            return at(zero), jax.jacfwd(at)(zero)

        r, M = jax.vmap(one)(args, f.data)
        if r.ndim != 2:
            raise ValueError(
                f"least_squares: a residual must return a vector (r,), got shape {r.shape[1:]}"
            )
        if M.shape != (*r.shape, sum(dims)):
            raise ValueError(
                f"least_squares: a factor's Jacobian must be (r, K) = {(r.shape[1], sum(dims))}, "
                f"got {M.shape[1:]}"
            )
        rho, w = _rho(f.robust, jnp.sum(r * r, axis=-1))
        total = total + 0.5 * jnp.sum(rho)
        root = jnp.sqrt(w)[:, None]
        blocks.append(_Block(root * r, root[..., None] * M, _columns(f, variables)))
    return total, tuple(blocks)


def _gradient(blocks: Sequence[_Block], n: int) -> jax.Array:
    """g = Σ Mᵀe, flat ``(n,)``."""
    g = jnp.zeros((n,), blocks[0].e.dtype if blocks else jnp.float32)
    for b in blocks:
        g = g.at[b.cols].add(jnp.einsum("fr,frk->fk", b.e, b.M))
    return g


def _dense_hessian(blocks: Sequence[_Block], n: int) -> jax.Array:
    """H = Σ MᵀM, dense ``(n, n)``."""
    H = jnp.zeros((n, n), blocks[0].e.dtype if blocks else jnp.float32)
    for b in blocks:
        H = H.at[b.cols[:, :, None], b.cols[:, None, :]].add(jnp.einsum("frk,frl->fkl", b.M, b.M))
    return H


def _normal_equations(
    factors: Sequence[Factor], variables: Tuple[Variable, ...]
) -> Tuple[jax.Array, jax.Array, jax.Array]:
    """The cost, H = JᵀWJ and g = JᵀW r (W the robust weights ρ'), dense, in the flat
    tangent of ``_retract``."""
    n = _offsets(variables)[-1]
    total, blocks = _linearise(factors, variables)
    return total, _dense_hessian(blocks, n), _gradient(blocks, n)


def _free_mask(variables: Tuple[Variable, ...], fixed: Any) -> jax.Array:
    """1 for each free tangent coordinate, 0 for a fixed one (``fixed``: per set, None or a
    bool array ``(n,)``)."""
    parts = []
    for i, v in enumerate(variables):
        n, k = _count(v), _tangent_dim(v)
        f = None if fixed is None else fixed[i]
        keep = jnp.ones((n,), bool) if f is None else ~jnp.asarray(f, bool).reshape(n)
        parts.append(jnp.repeat(keep, k))
    return jnp.concatenate(parts) if parts else jnp.zeros((0,), bool)


def _damped_solve(H, g, damping, free):
    """δ = −(H + diag(damping))⁻¹ g on the free coordinates (0 on the fixed ones)."""
    A = jnp.where(free[:, None] & free[None, :], H, 0.0)
    A = A + jnp.diag(jnp.where(free, damping, 1.0))
    c = jax.scipy.linalg.cho_factor(A, lower=True)
    return -jnp.where(free, jax.scipy.linalg.cho_solve(c, jnp.where(free, g, 0.0)), 0.0)


# -- linear solvers --------------------------------------------------------------------
#
# Each is a pair: ``system(blocks, n) -> (state, diagonal of H)``, what the loop keeps while
# it tries dampings at one point, and ``step(state, g, damping, free) -> δ``. Both run
# inside the loop; the host solvers call out through ``jax.pure_callback``.


def _diagonal_blocks(factors, blocks: Sequence[_Block], variables) -> Tuple[jax.Array, ...]:
    """Per variable set, H's diagonal blocks ``(n_s, k_s, k_s)``."""
    out = [
        jnp.zeros((_count(v), _tangent_dim(v), _tangent_dim(v)), _dtype(variables))
        for v in variables
    ]
    for f, b in zip(factors, blocks):
        o = 0
        for s, idx in zip(f.sets, f.indices):
            k = _tangent_dim(variables[s])
            Ma = b.M[:, :, o : o + k]
            out[s] = out[s].at[jnp.asarray(idx)].add(jnp.einsum("frk,frl->fkl", Ma, Ma))
            o += k
    return tuple(out)


def _flat_diagonal(diagonal_blocks: Sequence[jax.Array]) -> jax.Array:
    return jnp.concatenate([jnp.diagonal(D, axis1=-2, axis2=-1).ravel() for D in diagonal_blocks])


def _matvec(blocks: Sequence[_Block], x: jax.Array) -> jax.Array:
    """H x = Σ Mᵀ(M x), matrix-free."""
    y = jnp.zeros_like(x)
    for b in blocks:
        u = jnp.einsum("frk,fk->fr", b.M, x[b.cols])
        y = y.at[b.cols].add(jnp.einsum("frk,fr->fk", b.M, u))
    return y


def _block_jacobi(diagonal_blocks, damping, free, variables) -> Callable:
    """r ↦ (diagonal blocks + diag(damping))⁻¹ r per variable element, identity on the fixed
    coordinates."""
    offsets = _offsets(variables)
    inverses = []
    for s, D in enumerate(diagonal_blocks):
        n, k = D.shape[0], D.shape[-1]
        f = free[offsets[s] : offsets[s + 1]].reshape(n, k)
        d = jnp.where(f, damping[offsets[s] : offsets[s + 1]].reshape(n, k), 1.0)
        A = jnp.where(f[:, :, None] & f[:, None, :], D, 0.0) + d[:, :, None] * jnp.eye(k)
        inverses.append(jnp.linalg.inv(A))

    def apply(r):
        parts = []
        for s, inv in enumerate(inverses):
            n, k = inv.shape[0], inv.shape[-1]
            rs = r[offsets[s] : offsets[s + 1]].reshape(n, k)
            parts.append(jnp.einsum("nkl,nl->nk", inv, rs).ravel())
        return jnp.concatenate(parts)

    return apply


def _cg(matvec, rhs, precondition, tolerance, max_iterations):
    x, _ = jax.scipy.sparse.linalg.cg(
        matvec, rhs, tol=tolerance, maxiter=max_iterations, M=precondition
    )
    return x


@dataclasses.dataclass(frozen=True)
class _HostPattern:
    """The upper triangle of H in compressed-column form, built once per problem structure
    from the factors' concrete columns, and the host solver that factorises it (symbolic
    analysis once, numeric at every damping). Hashable by identity: ``solve`` keeps one per
    structure, so ``jit`` reuses its program."""

    size: int
    nnz: int
    indices: onp.ndarray
    indptr: onp.ndarray
    columns: onp.ndarray
    scatter: onp.ndarray
    diagonal: onp.ndarray
    bandwidth: int
    triu: Tuple[Tuple[onp.ndarray, onp.ndarray], ...]
    segments: Tuple[Optional[onp.ndarray], ...]
    backend: str
    solver: Any = dataclasses.field(compare=False, hash=False)

    __hash__ = object.__hash__
    __eq__ = object.__eq__  # type: ignore[assignment]

    @staticmethod
    def build(cols: Sequence[onp.ndarray], size: int, backend: str) -> "_HostPattern":
        rows_all, cols_all, triu, segments = [], [], [], []
        for c in cols:
            # Factors on the same columns (a spline's samples in one segment) are summed on
            # the device first: the host's work grows with the distinct column tuples.
            unique_cols, ids = onp.unique(c, axis=0, return_inverse=True)
            repeats = len(unique_cols) < len(c)
            segments.append(ids.ravel().astype(onp.int32) if repeats else None)
            c = unique_cols if repeats else c
            p, q = onp.triu_indices(c.shape[1])
            r, cc = c[:, p], c[:, q]
            rows_all.append(onp.minimum(r, cc).ravel())
            cols_all.append(onp.maximum(r, cc).ravel())
            triu.append((p, q))
        row, col = onp.concatenate(rows_all), onp.concatenate(cols_all)
        diagonal = onp.arange(size)
        keys = onp.concatenate([col * size + row, diagonal * size + diagonal])
        unique, inverse = onp.unique(keys, return_inverse=True)
        indices = (unique % size).astype(onp.int64)
        indptr = onp.searchsorted(unique // size, onp.arange(size + 1)).astype(onp.int64)
        columns = onp.repeat(onp.arange(size), onp.diff(indptr))
        pattern = _HostPattern(
            size=size,
            nnz=len(unique),
            indices=indices,
            indptr=indptr,
            columns=columns,
            scatter=inverse[: len(row)].astype(onp.int64),
            diagonal=inverse[len(row) :].astype(onp.int64),
            bandwidth=int(onp.max(columns - indices)),
            triu=tuple(triu),
            segments=tuple(segments),
            backend=backend,
            solver=None,
        )
        solver = (
            _sparse.BandedCholesky(pattern, dense=False)  # type: ignore[arg-type]
            if backend == "banded"
            else _sparse.SparseCholesky(pattern, backend)  # type: ignore[arg-type]
        )
        object.__setattr__(pattern, "solver", solver)
        return pattern

    def solve(self, values, damping, g, free) -> onp.ndarray:
        """The host side: assemble, damp, mask the fixed coordinates, factorise, solve."""
        values = onp.asarray(values, onp.float64)
        free = onp.asarray(free, bool)
        data = onp.bincount(self.scatter, weights=values, minlength=self.nnz)
        data = onp.where(free[self.indices] & free[self.columns], data, 0.0)
        damp = onp.where(free, onp.asarray(damping, onp.float64), 1.0)
        g = onp.where(free, onp.asarray(g, onp.float64), 0.0)
        delta = self.solver.solve(data, damp, g)
        return onp.where(free, delta, 0.0)


_PATTERNS: dict = {}


def _host_pattern(factors, variables, backend: str) -> _HostPattern:
    """The ``_HostPattern`` of a structure, built once (keyed by the index arrays' bytes)."""
    cols = []
    for f in factors:
        for idx in f.indices:
            if isinstance(idx, jax.core.Tracer):
                raise ValueError(
                    f"least_squares.solve: linear_solver={backend!r} builds H's sparsity "
                    "pattern on the host and needs concrete index arrays; close over them "
                    "instead of passing them through jit or vmap, or use 'dense' or 'pcg'"
                )
    offsets = _offsets(variables)
    for f in factors:
        parts = []
        for s, idx in zip(f.sets, f.indices):
            k = _tangent_dim(variables[s])
            parts.append(offsets[s] + onp.asarray(idx)[:, None] * k + onp.arange(k))
        cols.append(onp.concatenate(parts, axis=1))
    size = offsets[-1]
    key = (backend, size, tuple((c.shape, hash(c.tobytes())) for c in cols))
    if key not in _PATTERNS:
        _PATTERNS[key] = _HostPattern.build(cols, size, backend)
    return _PATTERNS[key]


# -- Schur complement ------------------------------------------------------------------
#
# ``linear_solver="schur"``: the elements of one variable set E (a bundle adjustment's
# points) are eliminated first. Where every factor reads at most one element of E, H's block
# on E is block diagonal, V = diag(V_p); with W the coupling to the other unknowns R and A
# their block, (H + diag(d)) δ = −g is solved by the reduced system
#   (Ã − W Ṽ⁻¹ Wᵀ) δ_R = −g_R + W Ṽ⁻¹ g_E,   δ_E = −Ṽ⁻¹ (g_E + Wᵀ δ_R)
# (Ã, Ṽ damped), the reduced matrix dense and factorised by Cholesky on the device
# (Triggs, McLauchlan, Hartley, Fitzgibbon, *Bundle Adjustment — A Modern Synthesis*, 2000,
# §6.1). W Ṽ⁻¹ Wᵀ = Σ_p G G ᵀ over the pairs of factors that share an element p, with
# G_a = W_a L_p⁻ᵀ (Ṽ_p = L_p L_pᵀ): the pairs are listed once per structure on the host and
# summed in chunks per pair of R-column tuples (cameras, for bundle adjustment).

#: Pairs of factors summed at once in the reduced matrix.
SCHUR_CHUNK = 1 << 16


def _eliminable(factors, variables) -> Optional[int]:
    """The set ``"schur"`` eliminates: of those read by some factor and by none at two of its
    arguments, the one with the most unknowns (None if there is none)."""
    best, size = None, 0
    for s, v in enumerate(variables):
        counts = [f.sets.count(s) for f in factors]
        n = _count(v) * _tangent_dim(v)
        if max(counts, default=0) == 1 and n > size:
            best, size = s, n
    return best


@dataclasses.dataclass(frozen=True)
class _SchurPattern:
    """The layout of the elimination of set ``eliminated``, built once per structure from the
    factors' concrete indices. Reduced coordinates: the flat tangent without E's, plus one
    padding coordinate (``reduced``) that padded columns point to. Hashable by identity, as
    ``_HostPattern``."""

    eliminated: int
    reduced: int  # N_R; the padding coordinate
    # Per factor set: the positions of its R columns and of its E columns among its K, its
    # rows' R-column tuple ids and those tuples' reduced columns, and (for one that reads E)
    # the offset of its rows among the E rows.
    r_pos: Tuple[onp.ndarray, ...]
    e_pos: Tuple[Optional[onp.ndarray], ...]
    tuple_ids: Tuple[onp.ndarray, ...]
    tuple_cols: Tuple[onp.ndarray, ...]
    row_offset: Tuple[Optional[int], ...]
    # The rows that read E (every such factor set's, in order, R columns padded to K_max):
    rows_cols: onp.ndarray  # (rows, K_max) reduced columns
    rows_element: onp.ndarray  # (rows,) the element of E
    rows_tuple: onp.ndarray  # (rows,) R-column tuple id among these rows
    rows_tuple_cols: onp.ndarray  # (T, K_max)
    # Pairs a < b of rows on one element, sorted by their pair of tuples, in chunks:
    pairs: onp.ndarray  # (chunks, 3, SCHUR_CHUNK): row a, row b, pair-of-tuples id
    pair_cols: onp.ndarray  # (U, 2, K_max): the reduced columns of each pair of tuples

    __hash__ = object.__hash__
    __eq__ = object.__eq__  # type: ignore[assignment]

    @staticmethod
    def build(factors, variables, e: int) -> "_SchurPattern":
        offsets = _offsets(variables)
        start, stop = offsets[e], offsets[e + 1]
        N_R = offsets[-1] - (stop - start)
        r_pos: list = []
        e_pos: list = []
        tuple_ids: list = []
        tuple_cols: list = []
        row_offset: list = []
        rows_cols: list = []
        rows_element: list = []
        for f in factors:
            c = onp.concatenate(
                [
                    offsets[s]
                    + onp.asarray(idx)[:, None] * _tangent_dim(variables[s])
                    + onp.arange(_tangent_dim(variables[s]))
                    for s, idx in zip(f.sets, f.indices)
                ],
                axis=1,
            )
            in_e = (c[0] >= start) & (c[0] < stop) if len(c) else onp.zeros(c.shape[1], bool)
            rp = onp.flatnonzero(~in_e)
            r_pos.append(rp)
            rc = onp.where(c[:, rp] >= stop, c[:, rp] - (stop - start), c[:, rp])
            unique, ids = onp.unique(rc, axis=0, return_inverse=True)
            tuple_ids.append(ids.ravel().astype(onp.int32))
            tuple_cols.append(unique)
            if in_e.any():
                e_pos.append(onp.flatnonzero(in_e))
                row_offset.append(sum(len(r) for r in rows_cols))
                rows_cols.append(rc)
                k = int(in_e.sum())
                rows_element.append((c[:, onp.flatnonzero(in_e)[0]] - start) // k)
            else:
                e_pos.append(None)
                row_offset.append(None)
        K = max(r.shape[1] for r in rows_cols)
        padded = onp.concatenate(
            [onp.pad(r, ((0, 0), (0, K - r.shape[1])), constant_values=N_R) for r in rows_cols]
        )
        element = onp.concatenate(rows_element).astype(onp.int64)
        unique_rows, row_tuple = onp.unique(padded, axis=0, return_inverse=True)
        row_tuple = row_tuple.ravel()
        # Every pair a < b of rows on one element, by track length.
        order = onp.argsort(element, kind="stable")
        _, first, length = onp.unique(element[order], return_index=True, return_counts=True)
        pa, pb = [], []
        for L in onp.unique(length):
            if L < 2:
                continue
            starts = first[length == L]
            i, j = onp.triu_indices(int(L), 1)
            pa.append(order[starts[:, None] + i].ravel())
            pb.append(order[starts[:, None] + j].ravel())
        a = onp.concatenate(pa) if pa else onp.zeros(0, onp.int64)
        b = onp.concatenate(pb) if pb else onp.zeros(0, onp.int64)
        T = len(unique_rows)
        keys, pair_id = onp.unique(row_tuple[a] * T + row_tuple[b], return_inverse=True)
        pair_id = pair_id.ravel()
        sort = onp.argsort(pair_id, kind="stable")
        n = len(a)
        chunk = min(SCHUR_CHUNK, max(n, 1))
        chunks = max(-(-n // chunk), 1)
        flat = onp.empty((3, chunks * chunk), onp.int32)
        flat[0], flat[1] = len(padded), len(padded)  # a zero row
        flat[2] = len(keys)  # a discarded pair id
        flat[0, :n], flat[1, :n], flat[2, :n] = a[sort], b[sort], pair_id[sort]
        pairs = flat.reshape(3, chunks, chunk).transpose(1, 0, 2)
        pair_cols = onp.stack([unique_rows[keys // T], unique_rows[keys % T]], axis=1)
        return _SchurPattern(
            e, N_R, tuple(r_pos), tuple(e_pos), tuple(tuple_ids), tuple(tuple_cols),
            tuple(row_offset), padded.astype(onp.int32), element.astype(onp.int32),
            row_tuple.astype(onp.int32), unique_rows.astype(onp.int32), pairs, pair_cols,
        )  # fmt: skip


def _schur_pattern(factors, variables) -> _SchurPattern:
    """The ``_SchurPattern`` of a structure, built once (keyed as ``_host_pattern``)."""
    for f in factors:
        if any(isinstance(i, jax.core.Tracer) for i in f.indices):
            raise ValueError(
                "least_squares.solve: linear_solver='schur' lists the pairs of factors that "
                "share an eliminated element on the host and needs concrete index arrays; "
                "close over them instead of passing them through jit or vmap"
            )
    e = _eliminable(factors, variables)
    if e is None:
        raise ValueError(
            "least_squares.solve: linear_solver='schur' needs a variable set that every "
            "factor reads at most once (its elements' Hessian blocks independent); none is"
        )
    key = (
        "schur",
        tuple((type(v).__name__, _count(v), _tangent_dim(v)) for v in variables),
        tuple((f.sets, tuple(hash(onp.asarray(i).tobytes()) for i in f.indices)) for f in factors),
    )
    if key not in _PATTERNS:
        _PATTERNS[key] = _SchurPattern.build(factors, variables, e)
    return _PATTERNS[key]


class _SchurSystem(NamedTuple):
    """What ``"schur"`` keeps at one point: A = H's block on R, dense ``(N_R + 1, N_R + 1)``
    (the padding coordinate last), V ``(n_E, k, k)`` and the E rows' W_a = M_Rᵀ M_E
    ``(rows, K_max, k)``."""

    A: jax.Array
    V: jax.Array
    W: jax.Array


def _schur_system(pattern: _SchurPattern, factors, blocks, variables) -> _SchurSystem:
    n = pattern.reduced + 1
    dtype = _dtype(variables)
    A = jnp.zeros((n, n), dtype)
    W = jnp.zeros(
        (
            len(pattern.rows_cols),
            pattern.rows_cols.shape[1],
            _tangent_dim(variables[pattern.eliminated]),
        ),
        dtype,
    )
    for j, b in enumerate(blocks):
        rp = pattern.r_pos[j]
        MR = b.M[:, :, rp]
        if len(rp):
            ids = jnp.asarray(pattern.tuple_ids[j])
            sums = jax.ops.segment_sum(
                jnp.einsum("frk,frl->fkl", MR, MR), ids, num_segments=len(pattern.tuple_cols[j])
            )
            cols = pattern.tuple_cols[j]
            A = A.at[cols[:, :, None], cols[:, None, :]].add(sums)
        ep, o = pattern.e_pos[j], pattern.row_offset[j]
        if ep is not None and o is not None:
            Wj = jnp.einsum("frk,frl->fkl", MR, b.M[:, :, ep])
            W = W.at[o : o + Wj.shape[0], : Wj.shape[1]].set(Wj)
    V = _diagonal_blocks(factors, blocks, variables)[pattern.eliminated]
    return _SchurSystem(A, V, W)


def _schur_step(pattern: _SchurPattern, variables, state: _SchurSystem, g, damping, free):
    """δ = −(H + diag(damping))⁻¹ g on the free coordinates, by the reduced system."""
    offsets = _offsets(variables)
    e = pattern.eliminated
    start, stop = offsets[e], offsets[e + 1]
    n_e, k = state.V.shape[0], state.V.shape[-1]

    def reduced(x, pad):
        return jnp.concatenate([x[:start], x[stop:], jnp.asarray([pad], x.dtype)])

    fR, dR, gR = reduced(free, False), reduced(damping, 1.0), reduced(jnp.where(free, g, 0.0), 0.0)
    fE = free[start:stop].reshape(n_e, k)
    dE = damping[start:stop].reshape(n_e, k)
    gE = jnp.where(fE, g[start:stop].reshape(n_e, k), 0.0)
    A = jnp.where(fR[:, None] & fR[None, :], state.A, 0.0) + jnp.diag(jnp.where(fR, dR, 1.0))
    V = jnp.where(fE[:, :, None] & fE[:, None, :], state.V, 0.0)
    V = V + jnp.where(fE, dE, 1.0)[:, :, None] * jnp.eye(k, dtype=V.dtype)
    elem, cols = jnp.asarray(pattern.rows_element), jnp.asarray(pattern.rows_cols)
    W = state.W * fR[cols][:, :, None] * fE[elem][:, None, :]
    L = jnp.linalg.cholesky(V)
    # G_a = W_a L⁻ᵀ: Gᵀ = L⁻¹ Wᵀ.
    G = jnp.swapaxes(
        jax.scipy.linalg.solve_triangular(L[elem], jnp.swapaxes(W, 1, 2), lower=True), 1, 2
    )
    # The pairs a = b, per R-column tuple, then a < b in chunks (and their transposes).
    S = A
    tcols = jnp.asarray(pattern.rows_tuple_cols)
    own = jax.ops.segment_sum(
        jnp.einsum("akl,aml->akm", G, G),
        jnp.asarray(pattern.rows_tuple),
        num_segments=len(pattern.rows_tuple_cols),
    )
    S = S.at[tcols[:, :, None], tcols[:, None, :]].add(-own)
    U = len(pattern.pair_cols)
    if U:
        Gz = jnp.concatenate([G, jnp.zeros_like(G[:1])])
        pairs = jnp.asarray(pattern.pairs)

        def chunk(i, acc):
            a, b, s = pairs[i, 0], pairs[i, 1], pairs[i, 2]
            blocks = jnp.einsum("akl,aml->akm", Gz[a], Gz[b])
            return acc + jax.ops.segment_sum(blocks, s, num_segments=U + 1, indices_are_sorted=True)

        K = G.shape[1]
        acc = jax.lax.fori_loop(0, pairs.shape[0], chunk, jnp.zeros((U + 1, K, K), G.dtype))
        ca, cb = jnp.asarray(pattern.pair_cols[:, 0]), jnp.asarray(pattern.pair_cols[:, 1])
        off = jnp.zeros_like(S).at[ca[:, :, None], cb[:, None, :]].add(acc[:U])
        S = S - off - off.T
    y = jax.vmap(lambda l, v: jax.scipy.linalg.cho_solve((l, True), v))(L, gE)  # Ṽ⁻¹ g_E
    rhs = (-gR).at[cols].add(jnp.einsum("akl,al->ak", W, y[elem]))
    xR = jax.scipy.linalg.cho_solve(jax.scipy.linalg.cho_factor(S, lower=True), rhs)
    back = jax.ops.segment_sum(jnp.einsum("akl,ak->al", W, xR[cols]), elem, num_segments=n_e)
    xE = -jax.vmap(lambda l, v: jax.scipy.linalg.cho_solve((l, True), v))(L, gE + back)
    delta = jnp.concatenate([xR[:start], xE.ravel(), xR[start:-1]])
    return jnp.where(free, delta, 0.0)


# -- the loop --------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class _Options:
    method: str
    max_iterations: int
    tolerance: float
    initial_damping: float
    diagonal_damping: bool
    linear_solver: str  # "dense", "pcg", "host" or "schur"
    cg_tolerance: float
    cg_max_iterations: int
    pattern: Union[_HostPattern, _SchurPattern, None] = None
    callback: Optional[Callable[..., None]] = None


def _system(opts: _Options, factors, variables):
    """The cost, the state the linear solver keeps at one point, g and diag(H)."""
    n = _offsets(variables)[-1]
    c, blocks = _linearise(factors, variables)
    g = _gradient(blocks, n)
    if opts.linear_solver == "dense":
        H = _dense_hessian(blocks, n)
        return c, H, g, jnp.diagonal(H)
    D = _diagonal_blocks(factors, blocks, variables)
    if isinstance(opts.pattern, _SchurPattern):
        return c, _schur_system(opts.pattern, factors, blocks, variables), g, _flat_diagonal(D)
    if opts.linear_solver == "pcg":
        return c, (blocks, D), g, _flat_diagonal(D)
    assert opts.pattern is not None
    parts = []
    for b, (p, q), ids in zip(blocks, opts.pattern.triu, opts.pattern.segments):
        v = jnp.einsum("frk,frl->fkl", b.M, b.M)
        if ids is not None:
            v = jax.ops.segment_sum(v, jnp.asarray(ids), num_segments=int(ids.max()) + 1)
        parts.append(v[:, p, q].ravel())
    return c, jnp.concatenate(parts), g, _flat_diagonal(D)


def _step(opts: _Options, variables, state, g, damping, free) -> jax.Array:
    """δ = −(H + diag(damping))⁻¹ g on the free coordinates."""
    if opts.linear_solver == "dense":
        return _damped_solve(state, g, damping, free)
    if opts.linear_solver == "pcg":
        blocks, D = state
        matvec = lambda v: (  # noqa: E731
            jnp.where(free, _matvec(blocks, jnp.where(free, v, 0.0)), 0.0)
            + jnp.where(free, damping, 1.0) * v
        )
        precondition = _block_jacobi(D, damping, free, variables)
        rhs = -jnp.where(free, g, 0.0)
        return _cg(matvec, rhs, precondition, opts.cg_tolerance, opts.cg_max_iterations)
    pattern = opts.pattern
    if isinstance(pattern, _SchurPattern):
        return _schur_step(pattern, variables, state, g, damping, free)
    assert pattern is not None
    # float64 travels as its bits both ways (``_as_bits``).
    out = jax.eval_shape(_as_bits, g)

    def host(values, damping, g, free):
        delta = pattern.solve(*(_from_bits(onp.asarray(a)) for a in (values, damping, g)), free)
        delta = onp.asarray(delta, onp.float64 if out.dtype == onp.uint32 else out.dtype)
        return delta[..., None].view(onp.uint32) if out.dtype == onp.uint32 else delta

    args = (_as_bits(state), _as_bits(damping), _as_bits(g), free)
    delta = jax.pure_callback(host, out, *args, vmap_method="sequential")
    return jax.lax.bitcast_convert_type(delta, g.dtype) if delta.dtype != g.dtype else delta


@functools.lru_cache(maxsize=None)
def _report(callback: Callable[..., None]) -> Callable[..., None]:
    """``callback(iteration, cost, step, damping)`` on the host, at linearisation points
    only (one wrapper per callback, so that ``jit`` keys on the callback itself)."""

    def at_point(moved, it, values):
        if bool(moved):
            c, step, lam = (float(v) for v in _from_bits(onp.asarray(values)))
            callback(int(it), c, step, lam)

    return at_point


def _as_bits(x: jax.Array) -> jax.Array:
    """float64 as its bits, ``(..., 2)`` uint32, for a host callback: it may run on a thread
    where x64 is off (a caller's ``jax.experimental.enable_x64`` context is per thread),
    where JAX would pass, and check, float64 values as float32. Other dtypes as they are."""
    return jax.lax.bitcast_convert_type(x, jnp.uint32) if x.dtype == jnp.float64 else x


def _from_bits(a: onp.ndarray) -> onp.ndarray:
    """The inverse of ``_as_bits``, on the host."""
    return onp.ascontiguousarray(a).view(onp.float64)[..., 0] if a.dtype == onp.uint32 else a


def _minimise(opts: _Options, factors, variables, fixed) -> Solution:
    """The loop. Each pass linearises if x moved (and stops on the decrease or the iteration
    limit), then tries one damped step; the linearisation and the cost are traced once
    each."""
    free = _free_mask(variables, fixed)
    lm = opts.method == "lm"
    dtype = _dtype(variables)
    R = StopReason
    c0 = cost(factors, variables)
    shapes = jax.eval_shape(lambda: _system(opts, factors, variables))
    zeros = jax.tree_util.tree_map(lambda a: jnp.zeros(a.shape, a.dtype), shapes)
    st0 = dict(
        x=variables,
        cost=c0,
        system=zeros[1],
        g=zeros[2],
        diag=zeros[3],
        fresh=jnp.asarray(False),  # the system is that of x
        lam=jnp.asarray(opts.initial_damping if lm else 0.0, dtype),
        nu=jnp.asarray(DAMPING_FACTOR, dtype),
        it=jnp.asarray(0, jnp.int32),
        reason=jnp.asarray(-1, jnp.int32),
        step=jnp.zeros((), dtype),  # max |δ| of the last accepted step
    )

    def body(st):
        moved = ~st["fresh"]
        c, system, g, diag = jax.lax.cond(
            moved,
            lambda: _system(opts, factors, st["x"]),
            lambda: (st["cost"], st["system"], st["g"], st["diag"]),
        )
        if opts.callback is not None:
            # Partitioned: under a sharded solve each device calls it (with the same
            # replicated scalars); one call on one device deadlocks the others' collectives.
            values = _as_bits(jnp.stack([c, st["step"], st["lam"]]))
            jax.debug.callback(_report(opts.callback), moved, st["it"], values, partitioned=True)
        # The decrease between the costs at two linearisation points.
        decrease = jnp.where(st["cost"] > 0, (st["cost"] - c) / st["cost"], 0.0)
        converged = moved & (st["it"] > 0) & (decrease < opts.tolerance)
        at_limit = moved & (st["it"] >= opts.max_iterations)

        D = st["lam"] * (jnp.maximum(diag, DAMPING_FLOOR) if opts.diagonal_damping else 1.0)
        D = jnp.broadcast_to(D, g.shape)
        delta = _step(opts, variables, system, g, D, free)
        predicted = 0.5 * (jnp.sum(D * delta * delta) - jnp.sum(g * delta))
        finite = jnp.isfinite(predicted)
        # Only the first, least damped step at a point speaks for the model: raising λ
        # after a failure shrinks every prediction.
        small = moved & finite & ~(predicted > opts.tolerance * c)
        trial = _retract(st["x"], jnp.where(finite, delta, 0.0))
        c_trial = cost(factors, trial)
        if lm:
            accept = finite & ~small & (c_trial < c)
            raised = jnp.asarray(False)
        else:
            accept = finite & ~small & (c_trial <= c)
            raised = finite & ~small & ~(c_trial <= c)  # also a NaN cost
        lam_up = st["lam"] * st["nu"]
        conditions = (  # the first that holds is the reason
            (moved & ~jnp.isfinite(c), R.NON_FINITE_COST),
            (converged, R.DECREASE_BELOW_TOLERANCE),
            (at_limit, R.MAX_ITERATIONS),
            (jnp.asarray(not lm) & ~finite, R.NON_FINITE_STEP),
            (small, R.PREDICTED_DECREASE_BELOW_TOLERANCE),
            (raised, R.STEP_RAISED_COST),
            (jnp.asarray(lm) & ~accept & (lam_up > MAX_DAMPING), R.NO_STEP_LOWERS_COST),
        )
        reason = jnp.asarray(-1, jnp.int32)
        for cond, code in reversed(conditions):
            reason = jnp.where(cond, jnp.int32(code), reason)
        go = accept & (reason < 0)
        if lm:
            lam = jnp.where(go, jnp.maximum(st["lam"] / DAMPING_FACTOR, MIN_DAMPING), lam_up)
            nu = jnp.where(go, DAMPING_FACTOR, 2 * st["nu"])
        else:
            lam, nu = st["lam"], st["nu"]
        lam = jnp.where(reason < 0, lam, st["lam"])
        x = jax.tree_util.tree_map(lambda a, b: jnp.where(go, a, b), trial, st["x"])
        return dict(
            x=x,
            cost=c,
            system=system,
            g=g,
            diag=diag,
            fresh=~go,
            lam=lam,
            nu=nu,
            it=st["it"] + go.astype(jnp.int32),
            reason=reason,
            step=jnp.where(go, jnp.max(jnp.abs(delta), initial=0.0), st["step"]),
        )

    st = jax.lax.while_loop(lambda st: st["reason"] < 0, body, st0)
    return Solution(
        variables=st["x"],
        cost=st["cost"],
        initial_cost=c0,
        iterations=st["it"],
        stop_reason=st["reason"],
        converged=jnp.isin(st["reason"], jnp.asarray([int(c) for c in _CONVERGED])),
        damping=st["lam"],
    )


# -- implicit differentiation ----------------------------------------------------------


def _tangent_gradient(factors, x):
    """∇_δ cost(x ⊕ δ) at δ = 0, flat."""
    n = _offsets(x)[-1]
    return jax.grad(lambda d: cost(factors, _retract(x, d)))(jnp.zeros((n,), _dtype(x)))


@functools.partial(jax.custom_vjp, nondiff_argnums=(0,))
def _solve_values(opts, factors, variables, fixed):
    return _minimise(opts, factors, variables, fixed)


def _solve_fwd(opts, factors, variables, fixed):
    sol = _minimise(opts, factors, variables, fixed)
    return sol, (factors, variables, sol, fixed)


def _solve_bwd(opts, res, cot):
    factors, initial, sol, fixed = res
    x = sol.variables
    n = _offsets(x)[-1]
    zero = jnp.zeros((n,), _dtype(x))
    # The cotangent of the parameters, pulled back to x's tangent: d/dδ ⟨x̄, x ⊕ δ⟩ at 0.
    _, pull = jax.vjp(lambda d: _retract(x, d), zero)
    (xbar,) = pull(cot.variables)
    free = _free_mask(x, fixed)
    rhs = jnp.where(free, xbar, 0.0)
    curvature = lambda d: cost(factors, _retract(x, d))  # noqa: E731
    if opts.linear_solver == "dense":
        H = jax.hessian(curvature)(zero)
        diag = jnp.diagonal(H)
    else:
        _, blocks = _linearise(factors, x)
        Dblocks = _diagonal_blocks(factors, blocks, x)
        diag = _flat_diagonal(Dblocks)
    # Where no step lowered the cost, λ grew only to find x* a minimum to working precision:
    # the derivative is the optimum's, damped by MIN_DAMPING alone.
    lam = jnp.where(sol.stop_reason == StopReason.NO_STEP_LOWERS_COST, MIN_DAMPING, sol.damping)
    damping = lam * (jnp.maximum(diag, DAMPING_FLOOR) if opts.diagonal_damping else 1.0)
    damping = jnp.broadcast_to(damping, zero.shape)
    if opts.linear_solver == "dense":
        w = -_damped_solve(H, rhs, damping, free)  # (H + λD)⁻¹ x̄ on the free coordinates
    else:
        # The exact Hessian's products (forward over reverse), by conjugate gradients
        # preconditioned with the Gauss–Newton blocks.
        gradient_at = jax.grad(curvature)

        def matvec(v):
            hv = jax.jvp(gradient_at, (zero,), (jnp.where(free, v, 0.0),))[1]
            return jnp.where(free, hv, 0.0) + jnp.where(free, damping, 1.0) * v

        precondition = _block_jacobi(Dblocks, damping, free, x)
        w = _cg(matvec, rhs, precondition, opts.cg_tolerance, opts.cg_max_iterations)
    w = jnp.where(jnp.all(jnp.isfinite(w)), w, 0.0)

    # θ̄ = −(∂G/∂θ)ᵀ w, G(θ) the tangent gradient at the fixed x; the costs at x* and at the
    # initial values depend on θ directly (at x*, ∂cost/∂x = 0).
    def through(fs):
        return _tangent_gradient(fs, x), cost(fs, x), cost(fs, initial)

    _, pull_theta = jax.vjp(through, factors)
    (fbar,) = pull_theta((-w, cot.cost, cot.initial_cost))
    return fbar, None, None


_solve_values.defvjp(_solve_fwd, _solve_bwd)


@functools.partial(jax.jit, static_argnums=(0,))
def _solve(opts, factors, variables, fixed):
    return _solve_values(opts, factors, variables, fixed)


#: Below this many unknowns ``"auto"`` takes the dense Cholesky.
DENSE_LIMIT = 1000


def solve(
    factors: Sequence[Factor],
    variables: Sequence[Variable],
    *,
    fixed: Optional[Sequence[Optional[jax.Array]]] = None,
    method: hints.SolverMethod = "lm",
    max_iterations: int = 100,
    tolerance: float = 1e-7,
    initial_damping: float = 1e-5,
    diagonal_damping: bool = False,
    linear_solver: hints.LinearSolver = "auto",
    cg_tolerance: float = 1e-10,
    cg_max_iterations: int = 2000,
    callback: Optional[Callable[[int, float, float, float], None]] = None,
) -> Solution:
    """Minimise ½ Σ ρ(‖r‖²) over the variables, from their given values.

    Args:
        factors: the ``Factor`` s of the problem.
        variables: the variable sets, each a group element with one batch axis ``(n,)`` or an
            array ``(n, d)``; their values are the initial estimate.
        fixed: None, or one entry per set: None, or a bool array ``(n,)``, true for the
            elements held at their initial value.
        method: ``"lm"``, Levenberg–Marquardt: (H + λD)δ = −g, a step kept only if it lowers
            the cost, then λ ← max(λ/10, 10⁻¹⁵); after one that does not, λ ← λν and ν ← 2ν
            (ν = 10 after every kept step). ``"gn"``, Gauss–Newton (λ = 0): every step taken,
            stopping with the previous estimate if one raises the cost.
        max_iterations: the most accepted steps.
        tolerance: it stops when an accepted step lowers the cost by less than this
            relative, or when the first (least damped) step of an iteration is predicted to.
        initial_damping: λ at the start (``"lm"``).
        diagonal_damping: D = max(diag H, 10⁻⁶) (Marquardt) instead of D = I.
        linear_solver: how (H + λD)δ = −g is solved, a choice made once, outside the loop:
            ``"dense"``, Cholesky of all of H on the device (N unknowns: O(N³)); ``"pcg"``,
            conjugate gradients on the device with the block-Jacobi preconditioner (the
            inverse of H's diagonal block of each element), matrix-free; ``"cholmod"``,
            ``"qdldl"`` or ``"banded"``, a sparse (or banded) Cholesky on the host through
            ``jax.pure_callback``, its symbolic analysis done once per structure (these need
            the index arrays concrete: close over them); ``"cholesky"``, CHOLMOD if cvxopt is
            installed, else QDLDL; ``"schur"``, the elements of one variable set eliminated
            first (the set every factor reads at most once with the most unknowns: a bundle
            adjustment's points), their 3 × 3 (k × k) blocks inverted, and the reduced system
            on the other sets factorised dense on the device (the indices concrete, as for
            the host solvers). ``"auto"``: dense up to
            ``DENSE_LIMIT`` unknowns, else CHOLMOD or QDLDL when installed and the indices
            are concrete, else PCG.
        cg_tolerance: PCG's relative residual (also that of the implicit derivative's solve,
            for every solver but ``"dense"``).
        cg_max_iterations: PCG's iteration limit (the same).
        callback: None, or ``callback(iteration, cost, step, damping)``, called on the host
            (``jax.debug.callback``) at the initial point and after every accepted step,
            with the number of accepted steps so far, the cost there, max |δ| of the step
            that led there (0 at the start) and λ; for progress lines and timing. Static
            (``jit`` keys on it); without ``vmap``, once per point in order (with the
            factors' data sharded over devices, once per device and point).

    Returns:
        A ``Solution``. Under ``jax.vmap`` (initial values, data and indices batched over
        problems of one structure) each problem is solved as it would be alone; under
        ``jax.grad`` the derivative with respect to the factors' data is the implicit one
        described in the module docstring.

    Raises:
        ValueError: at trace time, for a set without exactly one batch axis, a factor naming
            a set that does not exist, indices that are not ``(F,)`` ints, residuals that are
            not vectors, or ``method`` or an option out of range.
        IndexError: at trace time, for concrete indices out of range.

    A cost that is not finite at a linearisation point (NaN or ±inf in data or values that
    the residuals read, or residuals that overflow) ends the solve with
    ``StopReason.NON_FINITE_COST``, not converged, the values those of that point; eager or
    traced alike.
    """
    if method not in ("lm", "gn"):
        raise ValueError(f"least_squares.solve: method must be 'lm' or 'gn', got {method!r}")
    if not (isinstance(max_iterations, int) and max_iterations >= 0):
        raise ValueError(
            f"least_squares.solve: max_iterations must be a non-negative int, got "
            f"{max_iterations!r}"
        )
    for name, value in (("tolerance", tolerance), ("initial_damping", initial_damping)):
        if not value > 0:
            raise ValueError(f"least_squares.solve: {name} must be positive, got {value!r}")
    variables = tuple(variables)
    factors = tuple(factors)
    _check(factors, variables)
    if fixed is not None:
        fixed = tuple(fixed)
        if len(fixed) != len(variables):
            raise ValueError(
                f"least_squares.solve: fixed has {len(fixed)} entries for {len(variables)} sets"
            )
    solvers = typing.get_args(hints.LinearSolver)
    if linear_solver not in solvers:
        raise ValueError(
            f"least_squares.solve: linear_solver must be one of {solvers}, got {linear_solver!r}"
        )
    kind, pattern = _choose(linear_solver, factors, variables)
    opts = _Options(
        method, max_iterations, float(tolerance), float(initial_damping), bool(diagonal_damping),
        kind, float(cg_tolerance), int(cg_max_iterations), pattern, callback,
    )  # fmt: skip
    return _solve(opts, factors, variables, fixed)


def _choose(name: str, factors, variables) -> Tuple[str, Union[_HostPattern, _SchurPattern, None]]:
    """The solver kind (``"dense"``, ``"pcg"``, ``"host"``, ``"schur"``) and its pattern."""
    if name == "auto":
        concrete = not any(isinstance(i, jax.core.Tracer) for f in factors for i in f.indices)
        if _offsets(variables)[-1] <= DENSE_LIMIT:
            name = "dense"
        elif concrete and _sparse.installed("cholmod"):
            name = "cholmod"
        elif concrete and _sparse.installed("qdldl"):
            name = "qdldl"
        else:
            name = "pcg"
    if name == "cholesky":
        name = "cholmod" if _sparse.installed("cholmod") else "qdldl"
    if name in ("dense", "pcg"):
        return name, None
    if name == "schur":
        return name, _schur_pattern(factors, variables)
    if name in ("cholmod", "qdldl"):
        _sparse.require(name)
    return "host", _host_pattern(factors, variables, name)


@jax.jit
def marginal_covariances(factors: Sequence[Factor], solution: Solution) -> jax.Array:
    """The Laplace covariance of the solution, (JᵀWJ)⁻¹ at it, as GTSAM's ``Marginals``:
    a dense ``(N, N)`` array in the flat tangent (the sets in order, each set's elements in
    order, each element's tangent in the group's ordering); a block of it is the joint
    marginal of those elements. Each residual is whitened, so this is in the units of the
    variables' tangents."""
    _, H, _ = _normal_equations(tuple(factors), tuple(solution.variables))
    c = jax.scipy.linalg.cho_factor(H, lower=True)
    return jax.scipy.linalg.cho_solve(c, jnp.eye(H.shape[0], dtype=H.dtype))
