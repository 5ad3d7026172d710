"""Every public function of the package as a function of one context dict, for the tests
that run the whole surface under one rule (dtype in = dtype out, rank promotion, debug NaNs).

The context holds ``dtype``, elements ``T`` and ``U``, a tangent ``x``, points ``p``, times
``t`` and angles ``theta`` (built by ``context``); ``public_calls(G)`` maps a name to a function
of it for every method and factory of ``G``, ``module_calls(G)`` for the module functions
(jacobians, uncertainty, manifold, motion) and derivatives through them.
"""

from __future__ import annotations

from typing import Any, Callable, Dict, Tuple

import jax
import jax.numpy as jnp
import numpy as np
from _programs import BATCH
from conftest import is_se, key_of, random_element, random_tangent

import jaxlie_geo
from jaxlie_geo import SE2, SO2, SO3, jacobians, manifold, motion, uncertainty

Call = Callable[[Dict[str, Any]], Any]


def context(
    G: type, dtype: Any, batch_T: Tuple[int, ...] = BATCH, batch_U: Tuple[int, ...] = BATCH
) -> Dict[str, Any]:
    """Inputs for every call: ``T`` and ``x`` of batch ``batch_T``, ``U`` and points of batch
    ``batch_U``, times along ``batch_U``'s last axis and three angles. The default batch is
    the numeric tier's (``_programs.BATCH``), so that the compiled operations are shared with
    the property tests."""
    n = batch_U[-1] if batch_U else 1
    return {
        "dtype": dtype,
        "T": random_element(G, 7, batch_T, dtype),
        "U": random_element(G, 8, batch_U, dtype),
        "x": random_tangent(G, 7, batch_T, dtype),
        "p": np.ones((*batch_U, G.space_dim), dtype),
        "t": np.resize(np.asarray([0.25, 0.75, 1.5]), (n,)).astype(dtype),
        "theta": np.asarray([0.1, -0.4, 2.0], dtype),
    }


def public_calls(G: type) -> Dict[str, Call]:
    """name -> function of a context dict, returning whatever the public method or factory
    returns (the group-specific factories and readers of SO2, SO3 and SE2 included)."""
    calls = {
        "identity": lambda c: G.identity(c["T"].get_batch_axes(), dtype=c["dtype"]),
        "identity_unbatched": lambda c: G.identity(dtype=c["dtype"]),
        "sample_uniform": lambda c: G.sample_uniform(
            key_of(1), c["T"].get_batch_axes(), dtype=c["dtype"]
        ),
        "exp": lambda c: G.exp(c["x"]),
        "log": lambda c: c["T"].log(),
        "multiply": lambda c: c["T"].multiply(c["U"]),
        "matmul_group": lambda c: c["T"] @ c["U"],
        "apply": lambda c: c["T"].apply(c["p"]),
        "matmul_points": lambda c: c["T"] @ c["p"],
        "inverse": lambda c: c["T"].inverse(),
        "adjoint": lambda c: c["T"].adjoint(),
        "jlog": lambda c: c["T"].jlog(),
        "as_matrix": lambda c: c["T"].as_matrix(),
        "from_matrix": lambda c: G.from_matrix(c["T"].as_matrix()),
        "parameters": lambda c: c["T"].parameters(),
        "normalize": lambda c: c["T"].normalize(),
        "interpolate": lambda c: c["T"].interpolate(c["U"], 0.3),
        "interpolate_array_t": lambda c: c["T"].interpolate(c["U"], c["t"]),
        "geodesic": lambda c: jaxlie_geo.geodesic(c["T"], c["U"])(c["t"]),
        "hat": lambda c: G.hat(c["x"]),
        "vee": lambda c: G.vee(G.hat(c["x"])),
        "getitem": lambda c: c["T"][0],
        "reshape": lambda c: c["T"].reshape(*c["T"].get_batch_axes()[::-1]),
        "stack": lambda c: jaxlie_geo.stack([c["T"], c["U"]]),
        "jac_right": lambda c: G.jac_right(c["x"]),
        "jac_right_inv": lambda c: G.jac_right_inv(c["x"]),
        "jac_left": lambda c: G.jac_left(c["x"]),
        "jac_left_inv": lambda c: G.jac_left_inv(c["x"]),
        "ad": lambda c: G.ad(c["x"]),
    }
    if G is SO2:
        calls.update(
            from_radians=lambda c: SO2.from_radians(c["theta"]),
            as_radians=lambda c: c["T"].as_radians(),
        )
    if G is SO3:
        calls.update(
            from_x_radians=lambda c: SO3.from_x_radians(c["theta"]),
            from_y_radians=lambda c: SO3.from_y_radians(c["theta"]),
            from_z_radians=lambda c: SO3.from_z_radians(c["theta"]),
            from_rpy_radians=lambda c: SO3.from_rpy_radians(c["theta"], c["theta"], c["theta"]),
            from_quaternion_xyzw=lambda c: SO3.from_quaternion_xyzw(c["T"].wxyz),
            as_quaternion_xyzw=lambda c: c["T"].as_quaternion_xyzw(),
            as_rpy_radians=lambda c: tuple(c["T"].as_rpy_radians()),
            compute_roll_radians=lambda c: c["T"].compute_roll_radians(),
            compute_pitch_radians=lambda c: c["T"].compute_pitch_radians(),
            compute_yaw_radians=lambda c: c["T"].compute_yaw_radians(),
        )
    if G is SE2:
        calls.update(
            from_xy_theta=lambda c: SE2.from_xy_theta(c["theta"], c["theta"], c["theta"]),
        )
    if is_se(G):
        calls.update(
            from_rotation_and_translation=lambda c: G.from_rotation_and_translation(
                c["T"].rotation(), c["p"]
            ),
            from_rotation=lambda c: G.from_rotation(c["T"].rotation()),
            from_translation=lambda c: G.from_translation(c["p"]),
            rotation=lambda c: c["T"].rotation(),
            translation=lambda c: c["T"].translation(),
        )
    return calls


def module_calls(G: type) -> Dict[str, Call]:
    """The module functions (jacobians, uncertainty, manifold, motion) and derivatives,
    as functions of the context dict of ``public_calls``."""
    k = G.tangent_dim
    cov = np.eye(k) * 0.01
    calls = {
        "jacobians.compose": lambda c: jacobians.compose(c["T"], c["U"]),
        "jacobians.inverse": lambda c: jacobians.inverse(c["T"]),
        "jacobians.between": lambda c: jacobians.between(c["T"], c["U"]),
        "jacobians.rminus": lambda c: jacobians.rminus(c["T"], c["U"]),
        "jacobians.rplus": lambda c: jacobians.rplus(c["T"], c["x"]),
        "jacobians.apply": lambda c: jacobians.apply(c["T"], c["p"]),
        "jacobians.exp": lambda c: jacobians.exp(G, c["x"]),
        "jacobians.log": lambda c: jacobians.log(c["T"]),
        "propagate_compose": lambda c: uncertainty.propagate_compose(
            c["T"], cov.astype(c["dtype"]), c["U"], cov.astype(c["dtype"])
        ),
        "propagate_inverse": lambda c: uncertainty.propagate_inverse(
            c["T"], cov.astype(c["dtype"])
        ),
        "propagate_apply": lambda c: uncertainty.propagate_apply(
            c["T"], cov.astype(c["dtype"]), c["p"]
        ),
        "sample": lambda c: uncertainty.sample(key_of(3), c["T"], cov.astype(c["dtype"])),
        "mean": lambda c: uncertainty.mean(c["U"]),
        "mean_grad": lambda c: jax.grad(lambda x: jnp.sum(uncertainty.mean(G.exp(x)).log() ** 2))(
            c["x"]
        ),
        "rplus": lambda c: manifold.rplus(c["T"], c["x"]),
        "rminus": lambda c: manifold.rminus(c["T"], c["U"]),
        "rplus_jacobian": lambda c: manifold.rplus_jacobian_parameters_wrt_delta(c["T"]),
        "velocity_between": lambda c: motion.velocity_between(c["T"], c["U"], c["t"] + 1.0),
        "pose_at": lambda c: motion.pose_at(c["T"], c["x"], c["t"]),
        "grad": lambda c: jax.grad(
            lambda x: jnp.sum(G.exp(x).interpolate(c["U"], c["t"]).log() ** 2)
        )(c["x"]),
        "jacfwd": lambda c: jax.jacfwd(lambda x: (c["T"] @ G.exp(x)).log())(
            c["x"].reshape(-1, k)[0]
        ),
        "hessian": lambda c: jax.hessian(lambda x: jnp.sum(G.exp(x).log() ** 2))(c["x"][0]),
    }
    if G is SE2:
        calls["arc"] = lambda c: motion.arc(c["T"], c["x"])
    return calls


TWO_OPERANDS = {
    "multiply",
    "matmul_group",
    "apply",
    "matmul_points",
    "interpolate",
    "interpolate_array_t",
    "geodesic",
    "from_rotation_and_translation",
    "jacobians.compose",
    "jacobians.between",
    "jacobians.rminus",
    "jacobians.apply",
    "propagate_compose",
    "propagate_apply",
    "rminus",
    "velocity_between",
    "pose_at",
    "grad",
}
