"""Bundle adjustment: BAL files, the pinhole reprojection residual with radial distortion,
and its ``least_squares.Factor``.

The model is that of the Bundle Adjustment in the Large files (Agarwal, Snavely, Seitz,
Szeliski, *Bundle Adjustment in the Large*, ECCV 2010, §2). A camera is a pose
T = (R, t), world to camera, and intrinsics (f, k₁, k₂); a world point X is seen at

    P = R X + t,   p = −(P_x, P_y) / P_z,   u = f (1 + k₁‖p‖² + k₂‖p‖⁴) p,

in pixels from the image centre (the camera looks down its −z axis). The residual of an
observation z is u − z; the cost is ½ Σ ρ(‖u − z‖²) over the observations, in pixels².

A BAL file holds, whitespace separated: ``n_cameras n_points n_observations``; one line
``camera point x y`` per observation; then 9 numbers per camera (Rodrigues rotation vector
ω with R = exp([ω]×), t, f, k₁, k₂) and 3 per point. GTSAM reads the same file
(``gtsam.readBal``) into ``PinholeCamera<Cal3Bundler>`` cameras, turned to its z-forward,
camera-to-world convention, with the image y axis negated in the observations; its
``GeneralSFMFactor`` on those cameras has the same residual up to the sign of y, so the two
costs agree at the same values.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
from typing import Tuple, Union

import jax
import jax.numpy as jnp
import numpy as onp

from . import least_squares
from ._se3 import SE3
from ._so3 import SO3
from ._xla import x64

__all__ = [
    "Problem",
    "read_bal",
    "synthetic",
    "project",
    "reprojection_residual",
    "reprojection_jacobian",
    "factor",
]

PathLike = Union[str, "os.PathLike[str]"]


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Problem:
    """A bundle-adjustment problem: its variables' values and its observations.

    Attributes:
        cameras: ``SE3`` with batch axis ``(n_cameras,)``, T_camera_world (P = R X + t).
        intrinsics: ``(n_cameras, 3)``, (f, k₁, k₂) per camera.
        points: ``(n_points, 3)``, the world points.
        camera_index: int ``(n_observations,)``, the camera of each observation.
        point_index: int ``(n_observations,)``, the point of each observation.
        observations: ``(n_observations, 2)``, pixels from the image centre, BAL's axes.
    """

    cameras: SE3
    intrinsics: jax.Array
    points: jax.Array
    camera_index: jax.Array
    point_index: jax.Array
    observations: jax.Array

    @property
    def variables(self) -> Tuple[SE3, jax.Array, jax.Array]:
        """``(cameras, intrinsics, points)``, the variable sets ``factor`` names."""
        return self.cameras, self.intrinsics, self.points


def _problem(camera, points, camera_index, point_index, observations, dtype) -> Problem:
    """A ``Problem`` from BAL's per-camera rows (ω, t, f, k₁, k₂), in ``dtype``."""
    with x64(True) if dtype == onp.float64 else contextlib.nullcontext():
        camera = jnp.asarray(camera, dtype)
        cameras = SE3.from_rotation_and_translation(SO3.exp(camera[:, :3]), camera[:, 3:6])
        return Problem(
            cameras=cameras,
            intrinsics=camera[:, 6:9],
            points=jnp.asarray(points, dtype),
            camera_index=jnp.asarray(camera_index, jnp.int32),
            point_index=jnp.asarray(point_index, jnp.int32),
            observations=jnp.asarray(observations, dtype),
        )


def read_bal(path: PathLike, dtype: "onp.typing.DTypeLike" = onp.float64) -> Problem:
    """Read a BAL file (the format in the module docstring).

    Args:
        path: the file.
        dtype: the floating dtype of the result (float64 needs ``jax_enable_x64``).

    Returns:
        A ``Problem`` with the file's values.

    Raises:
        ValueError: for a file whose number of tokens does not match its header, or an
            observation naming a camera or point outside the header's counts.
    """
    with open(path, encoding="utf-8") as stream:
        tokens = stream.read().split()
    if len(tokens) < 3:
        raise ValueError(f"read_bal: {path}: no header 'n_cameras n_points n_observations'")
    nc, npt, no = (int(t) for t in tokens[:3])
    expected = 3 + 4 * no + 9 * nc + 3 * npt
    if len(tokens) != expected:
        raise ValueError(
            f"read_bal: {path}: the header ({nc} cameras, {npt} points, {no} observations) "
            f"asks for {expected} tokens, the file has {len(tokens)}"
        )
    obs = onp.asarray(tokens[3 : 3 + 4 * no], onp.float64).reshape(no, 4)
    rest = onp.asarray(tokens[3 + 4 * no :], onp.float64)
    ci, pi = obs[:, 0].astype(onp.int64), obs[:, 1].astype(onp.int64)
    if no and (ci.min() < 0 or ci.max() >= nc or pi.min() < 0 or pi.max() >= npt):
        raise ValueError(f"read_bal: {path}: an observation names a camera or point out of range")
    camera = rest[: 9 * nc].reshape(nc, 9)
    points = rest[9 * nc :].reshape(npt, 3)
    return _problem(camera, points, ci, pi, obs[:, 2:], onp.dtype(dtype))


def project(T_camera_world: SE3, intrinsics: jax.Array, point: jax.Array) -> jax.Array:
    """BAL's projection u of one point, ``(2,)`` (the formula in the module docstring).

    Args:
        T_camera_world: one ``SE3`` (no batch axes).
        intrinsics: ``(3,)``, (f, k₁, k₂).
        point: ``(3,)``, the world point.
    """
    P = T_camera_world @ point
    p = -P[:2] / P[2]
    r2 = jnp.sum(p * p)
    f, k1, k2 = intrinsics[0], intrinsics[1], intrinsics[2]
    return f * (1.0 + r2 * (k1 + k2 * r2)) * p


def reprojection_residual(
    T_camera_world: SE3, intrinsics: jax.Array, point: jax.Array, observation: jax.Array
) -> jax.Array:
    """u − z, ``(2,)``, in pixels: ``project`` minus the observation."""
    return project(T_camera_world, intrinsics, point) - observation


def reprojection_jacobian(
    T_camera_world: SE3, intrinsics: jax.Array, point: jax.Array, observation: jax.Array
) -> Tuple[jax.Array, jax.Array]:
    """The residual and its Jacobian in closed form, ``((2,), (2, 12))``.

    The columns are the pose's right-perturbation tangent (δt, δω) (T ⊕ δ = T exp(δ)),
    then (f, k₁, k₂), then the point. With P = R X + t, T exp(δ) X ≈ T X + R δt − R[X]×δω,
    so ∂P/∂δt = R, ∂P/∂δω = −R[X]×, ∂P/∂X = R; with g = 1 + k₁s + k₂s², s = ‖p‖²,
    ∂u/∂p = f (g I + 2 (k₁ + 2k₂s) p pᵀ) and ∂p/∂P = −[[1, 0, −P_x/P_z], [0, 1, −P_y/P_z]]/P_z;
    ∂u/∂(f, k₁, k₂) = (g p, f s p, f s² p).
    """
    R = T_camera_world.rotation().as_matrix()
    P = R @ point + T_camera_world.translation()
    inv_z = 1.0 / P[2]
    p = -P[:2] * inv_z
    s = jnp.sum(p * p)
    f, k1, k2 = intrinsics[0], intrinsics[1], intrinsics[2]
    g = 1.0 + s * (k1 + k2 * s)
    u = f * g * p
    du_dp = f * (g * jnp.eye(2, dtype=p.dtype) + 2.0 * (k1 + 2.0 * k2 * s) * jnp.outer(p, p))
    dp_dP = -inv_z * jnp.stack(
        [
            jnp.stack([jnp.ones_like(inv_z), jnp.zeros_like(inv_z), p[0]]),
            jnp.stack([jnp.zeros_like(inv_z), jnp.ones_like(inv_z), p[1]]),
        ]
    )
    du_dP = du_dp @ dp_dP  # (2, 3)
    dP_dX = R
    x, y, z = point[0], point[1], point[2]
    zero = jnp.zeros_like(x)
    X_hat = jnp.stack(
        [jnp.stack([zero, -z, y]), jnp.stack([z, zero, -x]), jnp.stack([-y, x, zero])]
    )
    J_pose = jnp.concatenate([du_dP @ R, -(du_dP @ R) @ X_hat], axis=1)
    J_intrinsics = jnp.stack([g * p, f * s * p, f * s * s * p], axis=1)
    J = jnp.concatenate([J_pose, J_intrinsics, du_dP @ dP_dX], axis=1)
    return u - observation, J


def factor(
    problem: Problem,
    robust: least_squares.Robust = None,
    sets: Tuple[int, int, int] = (0, 1, 2),
) -> least_squares.Factor:
    """The reprojection factors of a problem, one per observation.

    Args:
        problem: the observations and their indices.
        robust: None, ``("huber", k)`` or ``("cauchy", k)`` with k in pixels.
        sets: the positions of the cameras, the intrinsics and the points in ``solve``'s
            variables (``Problem.variables`` is ``(0, 1, 2)``).

    Returns:
        A ``least_squares.Factor`` with ``reprojection_residual`` and the closed-form
        ``reprojection_jacobian``.
    """
    return least_squares.Factor(
        reprojection_residual,
        sets,
        (problem.camera_index, problem.camera_index, problem.point_index),
        problem.observations,
        robust=robust,
        jacobian=reprojection_jacobian,
    )


def synthetic(
    n_cameras: int = 100,
    n_points: int = 10_000,
    observations_per_point: int = 10,
    pixel_noise: float = 0.5,
    key: int = 0,
) -> Tuple[Problem, Problem]:
    """A deterministic synthetic problem: points in a ball of radius 1 at the origin, cameras
    on a ring of radius 4 around it looking at its centre (f = 500, k₁ = k₂ = 0), each point
    seen by ``observations_per_point`` distinct cameras drawn at random, observations with
    Gaussian pixel noise, and initial values perturbed (rotations by about 0.01 rad,
    translations by 0.05, points by 0.05, f by 1%).

    Args:
        n_cameras: the number of cameras.
        n_points: the number of points.
        observations_per_point: the number of distinct cameras that see each point
            (n_observations = n_points · observations_per_point).
        pixel_noise: the observations' noise standard deviation, pixels.
        key: the NumPy random generator's key; the same key gives the same problem.

    Returns:
        ``(initial, truth)``: the problem with perturbed initial values, and the same
        observations with the true values, float64.
    """
    if not 2 <= observations_per_point <= n_cameras:
        raise ValueError(
            f"synthetic: observations_per_point must be in [2, n_cameras = {n_cameras}], got "
            f"{observations_per_point}"
        )
    rng = onp.random.default_rng(key)
    points = rng.normal(size=(n_points, 3))
    points *= (rng.uniform(size=(n_points, 1)) ** (1 / 3)) / onp.linalg.norm(points, axis=1)[
        :, None
    ]
    angle = 2 * onp.pi * onp.arange(n_cameras) / n_cameras
    height = rng.uniform(-1.0, 1.0, n_cameras)
    centre = onp.stack([4 * onp.cos(angle), 4 * onp.sin(angle), height], axis=1)
    # The camera looks down −z at the origin: its z axis points from the origin to it.
    z = centre / onp.linalg.norm(centre, axis=1)[:, None]
    x = onp.cross(onp.array([0.0, 0.0, 1.0]), z)
    x /= onp.linalg.norm(x, axis=1)[:, None]
    y = onp.cross(z, x)
    R_world_camera = onp.stack([x, y, z], axis=2)
    R = onp.transpose(R_world_camera, (0, 2, 1))
    t = -onp.einsum("nij,nj->ni", R, centre)
    intrinsics = onp.tile([500.0, 0.0, 0.0], (n_cameras, 1))
    ci = onp.argsort(rng.uniform(size=(n_points, n_cameras)), axis=1)[:, :observations_per_point]
    ci = ci.ravel()
    pi = onp.repeat(onp.arange(n_points), observations_per_point)
    with x64(True):
        rotvec = onp.asarray(SO3.from_matrix(jnp.asarray(R)).log())
        camera = onp.concatenate([rotvec, t, intrinsics], axis=1)
        truth = _problem(camera, points, ci, pi, onp.zeros((len(ci), 2)), onp.float64)
        u = jax.vmap(project)(
            truth.cameras[jnp.asarray(ci)],
            truth.intrinsics[jnp.asarray(ci)],
            truth.points[jnp.asarray(pi)],
        )
        observations = onp.asarray(u) + pixel_noise * rng.normal(size=u.shape)
        noisy = camera.copy()
        noisy[:, :3] = onp.asarray(
            (
                SO3.exp(jnp.asarray(rotvec))
                @ SO3.exp(jnp.asarray(0.01 * rng.normal(size=(n_cameras, 3))))
            ).log()
        )
        noisy[:, 3:6] += 0.05 * rng.normal(size=(n_cameras, 3))
        noisy[:, 6] *= 1 + 0.01 * rng.normal(size=n_cameras)
        noisy_points = points + 0.05 * rng.normal(size=points.shape)
        initial = _problem(noisy, noisy_points, ci, pi, observations, onp.float64)
        truth = dataclasses.replace(truth, observations=initial.observations)
    return initial, truth
