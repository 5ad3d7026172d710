"""examples/trajectory_fitting.py: the script end to end (--quick, in a subprocess, as a user
runs it), both of its models (the per-pose fit and the cubic SE(3) spline), and properties of
its objective, its tangent-space gradient and its ground-truth velocity (in process)."""

from __future__ import annotations

import importlib.util
import re
import subprocess
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxlie_geo import SE3, manifold, stack

REPO = Path(__file__).resolve().parents[1]
SCRIPT = REPO / "examples" / "trajectory_fitting.py"


def _load_example():
    spec = importlib.util.spec_from_file_location("trajectory_fitting", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


tf = _load_example()


# ---------------------------------------------------------------------------------------
# The script.


def _rmse_row(label: str, section: str) -> tuple:
    """(position [cm], rotation [deg]) of the row ``label`` in the report section ``section``
    (the text between one " at the ..." header and the next)."""
    match = re.search(rf"^\s+{re.escape(label)}\s+([\d.]+) cm\s+([\d.]+) deg$", section, re.M)
    assert match, f"row {label!r} not found in:\n{section}"
    return float(match.group(1)), float(match.group(2))


def _sections(out: str) -> dict:
    parts = re.split(r"^ at (?:the \d+ (observed|missing) poses|all \d+ poses):$", out, flags=re.M)
    # parts = [preamble, "observed", text, "missing", text, None, text]
    assert len(parts) == 7, out
    return {"observed": parts[2], "missing": parts[4], "all": parts[6]}


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory) -> tuple:
    png = tmp_path_factory.mktemp("traj") / "pictures" / "x.png"  # parent does not exist yet
    proc = subprocess.run(
        [sys.executable, str(SCRIPT), "--quick", "--out", str(png)],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=300,
    )
    return proc, png


def test_quick_run_succeeds_and_writes_a_png(quick_run) -> None:
    """``--quick`` exits 0, reports the problem and writes a non-trivial PNG."""
    proc, png = quick_run
    out = proc.stdout
    assert proc.returncode == 0, f"exit {proc.returncode}\nstdout:\n{out}\nstderr:\n{proc.stderr}"
    assert re.search(r"^80 poses of a banked figure-eight; \d+ noisy reports", out, re.M), out
    assert f"Wrote {png}" in out, out
    assert png.is_file(), out
    data = png.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    assert len(data) > 50_000  # three panels of plots, not an empty canvas


def test_quick_run_loss_decreases(quick_run) -> None:
    """The loss falls by 20x, is the sum of its data and smoothness terms, and ends below the
    ground truth's score (the fit is a near-minimiser)."""
    out = quick_run[0].stdout
    match = re.search(
        r"loss ([\d.]+) -> ([\d.]+) \(data ([\d.]+) \+ smoothness ([\d.]+)\); "
        r"the ground truth scores ([\d.]+)",
        out,
    )
    assert match, out
    start, end, data, smooth, truth = map(float, match.groups())
    assert end < 0.05 * start, out
    assert end == pytest.approx(data + smooth, rel=1e-3), out
    # The fit is a (near-)minimiser, so it scores better than the truth itself.
    assert end < truth, out


def test_quick_run_fit_beats_the_raw_data(quick_run) -> None:
    """Against the ground truth: the raw reports carry the injected noise, and the fit is
    closer than the reports at the observed poses and than geodesic interpolation through
    the gaps."""
    out = quick_run[0].stdout
    s = _sections(out)
    raw_pos, raw_rot = _rmse_row("raw reports", s["observed"])
    fit_pos, fit_rot = _rmse_row("fit", s["observed"])
    gap_pos, gap_rot = _rmse_row("geodesic between the nearest reports (start)", s["missing"])
    fit_gap_pos, fit_gap_rot = _rmse_row("fit", s["missing"])
    all_pos, all_rot = _rmse_row("fit", s["all"])
    # The raw reports have the noise we put in: σ = 10 cm and 6° per axis, so an RMSE of
    # about √3·10 cm ≈ 17 cm and √3·6° ≈ 10° (a sanity check on the error measures).
    assert 13.0 < raw_pos < 21.0 and 8.0 < raw_rot < 13.0, out
    # At the observed poses the smoother removes much of the noise (seed 0: 17 → 9 cm,
    # 11° → 6°; every seed from 0 to 9 halves the position error) ...
    assert fit_pos < 0.7 * raw_pos and fit_rot < 0.7 * raw_rot, out
    # ... and through the gaps it beats geodesic interpolation between the noisy reports on
    # either side, which is where it started (seed 0: 9.1 → 6.6 cm, 6.3° → 4.7°).
    assert fit_gap_pos < 0.9 * gap_pos and fit_gap_rot < 0.9 * gap_rot, out
    assert all_pos < 0.7 * raw_pos and all_rot < 0.7 * raw_rot, out


def _velocity_row(label: str, out: str) -> tuple:
    """(linear [m/s], angular [deg/s]) of the velocity row ``label``."""
    match = re.search(rf"^\s+{re.escape(label)}\s+([\d.]+) m/s\s+([\d.]+) deg/s$", out, re.M)
    assert match, f"velocity row {label!r} not found in:\n{out}"
    return float(match.group(1)), float(match.group(2))


def test_quick_run_spline_fit_converges_to_the_noise_level(quick_run) -> None:
    """The Levenberg–Marquardt fit of the cubic spline converges, and its final cost is what
    a correct model leaves: ½χ² with 6N − 6n degrees of freedom (seed 0: 141.5 against
    129.0; the rest is the spline's bias), far below the cost of its starting point."""
    out = quick_run[0].stdout
    head = re.search(
        r"^Cubic SE\(3\) spline, Δt = 2\.5 s, (\d+) control points on \[0\.00 s, 30\.00 s\]: "
        r"Levenberg–Marquardt \(splines\.fit\), (\d+) iterations, [\d.]+ s \(compilation "
        r"included\), converged$",
        out,
        re.M,
    )
    assert head, out
    # One loop of 30 s in 2.5 s segments: 12 segments, 12 + 3 control points.
    assert int(head.group(1)) == 15, out
    match = re.search(
        r"cost ([\d.]+) -> ([\d.]+); ½χ² expectation ½\(6N − 6n\) = ([\d.]+) "
        r"\(N = (\d+) reports, n = (\d+)\)",
        out,
    )
    assert match, out
    start, end, expected = map(float, match.groups()[:3])
    N, n = int(match.group(4)), int(match.group(5))
    assert expected == pytest.approx(3 * (N - n)), out
    assert end < 0.5 * start, out
    # The χ² of 6N − 6n = 258 degrees of freedom has a relative spread of √(2/258) ≈ 9%.
    assert 0.8 * expected < end < 1.4 * expected, out


def test_quick_run_spline_beats_the_raw_reports(quick_run) -> None:
    """The spline, fitted to the reports that arrived and nothing else, is closer to the
    truth than they are (seed 0: 17.0 → 9.0 cm, 11.1° → 5.6°), and through the gaps it stays
    about as close as one report (seed 0: 10.5 cm, 11.1°; the 3 s outage is 1.2 knot
    intervals)."""
    out = quick_run[0].stdout
    s = _sections(out)
    raw_pos, raw_rot = _rmse_row("raw reports", s["observed"])
    obs_pos, obs_rot = _rmse_row("cubic spline", s["observed"])
    gap_pos, gap_rot = _rmse_row("cubic spline", s["missing"])
    all_pos, all_rot = _rmse_row("cubic spline", s["all"])
    assert obs_pos < 0.7 * raw_pos and obs_rot < 0.7 * raw_rot, out
    assert gap_pos < raw_pos and gap_rot < 1.3 * raw_rot, out
    assert all_pos < 0.8 * raw_pos and all_rot < 0.9 * raw_rot, out


def test_quick_run_spline_velocity_follows_the_ground_truth(quick_run) -> None:
    """``spline.velocity`` against the ground truth's body velocity (forward-mode autodiff
    of the generating function), at the 79 midpoints between reports. Seed 0: 0.119 m/s and
    7.7 deg/s, against a velocity of RMS 0.66 m/s and 26 deg/s; the per-pose fit's finite
    differences: 0.070 m/s and 7.0 deg/s. Bounds with about 1.5x margin: a wrong frame
    (world instead of body) or tangent order ((ω, v)) would be off by the size of the
    velocity itself."""
    out = quick_run[0].stdout
    assert re.search(r"against the ground truth at 79 midpoints t_i \+ h/2", out), out
    size_lin, size_ang = _velocity_row("zero (the ground truth's own RMS, for scale)", out)
    lin, ang = _velocity_row("cubic spline, spline.velocity(t)", out)
    fit_lin, fit_ang = _velocity_row("fit, log(T_i⁻¹ T_{i+1}) / h", out)
    assert 0.5 < size_lin < 0.8 and 20.0 < size_ang < 32.0, out
    assert lin < 0.18 and ang < 12.0, out
    assert lin < 0.3 * size_lin and ang < 0.45 * size_ang, out
    assert fit_lin < 0.3 * size_lin and fit_ang < 0.45 * size_ang, out


# ---------------------------------------------------------------------------------------
# The objective (in process; conftest enables float64). Every test uses K = 10 poses and the
# jitted functions below, so the gradient is compiled once for all of them.

K = 10
_loss = jax.jit(tf.loss)
_value_and_grad = jax.jit(tf.tangent_value_and_grad)


def _directional_derivative(T: SE3, problem, delta: jax.Array, eps: float = 1e-6) -> float:
    """d/dε loss(T ⊕ εδ) at ε = 0, by central differences in float64 (error ~ ε², 1e-10
    relative here), through ``manifold.rplus``: independent of any autodiff."""
    plus = _loss(manifold.rplus(T, eps * delta), problem)
    minus = _loss(manifold.rplus(T, -eps * delta), problem)
    return float(plus - minus) / (2 * eps)


def _problem(Z: SE3, observed, w_smooth: float = 1.0):
    return tf.Problem(
        Z_world_body=Z,
        observed=jnp.asarray(observed, dtype=jnp.float64),
        w_data=jnp.asarray([4.0, 4.0, 4.0, 9.0, 9.0, 9.0]),
        w_smooth=jnp.full((6,), w_smooth, dtype=jnp.float64),
    )


def _random_trajectory(seed: int, K: int) -> SE3:
    """A smooth-ish random trajectory: random body steps, accumulated."""
    rng = np.random.default_rng(seed)
    steps = SE3.exp(jnp.asarray(rng.normal(scale=[0.3] * 3 + [0.4] * 3, size=(K, 6))))
    T = SE3.sample_uniform(jax.random.key(seed), dtype=jnp.float64)
    poses = []
    for i in range(K):
        T = T @ steps[i]
        poses.append(T)
    return stack(poses)


def test_prior_vanishes_on_constant_body_velocity() -> None:
    """On a screw motion T_i = T_0 exp(i ξ) every body step is ξ, so the smoothness term and
    its tangent gradient are zero; with the reports on the trajectory, so is the data term."""
    T0 = SE3.sample_uniform(jax.random.key(1), dtype=jnp.float64)
    xi = jnp.asarray([0.4, -0.1, 0.2, 0.3, -0.5, 0.9])  # 1.07 rad per step: a fast screw
    T = T0 @ SE3.exp(jnp.arange(K, dtype=jnp.float64)[:, None] * xi)
    problem = _problem(T, np.ones(K), w_smooth=1e4)
    steps = jax.jit(tf.body_steps)(T)
    np.testing.assert_allclose(np.asarray(steps), np.tile(xi, (K - 1, 1)), atol=1e-12)
    # (A Euclidean second difference of the positions would not vanish: the path is a helix.)
    p = np.asarray(T.translation())
    assert np.min(np.linalg.norm(p[2:] - 2 * p[1:-1] + p[:-2], axis=-1)) > 0.1
    (_, (data, smooth)), grad = _value_and_grad(T, problem)
    assert float(data) < 1e-20 and float(smooth) < 1e-20
    assert grad.shape == (K, 6)
    np.testing.assert_allclose(np.asarray(grad), 0.0, atol=1e-8)


def test_objective_is_left_invariant() -> None:
    """Both residuals are logs of relative poses (Z⁻¹T and T_i⁻¹T_{i+1}), so moving the world
    frame — G @ every pose and every report — changes nothing."""
    T = _random_trajectory(2, K)
    Z = _random_trajectory(3, K)
    G = SE3.sample_uniform(jax.random.key(4), dtype=jnp.float64)
    observed = np.array([1, 0, 1, 1, 0, 1, 1, 1, 0, 1])
    a = _loss(T, _problem(Z, observed))
    b = _loss(G @ T, _problem(G @ Z, observed))
    assert float(a) > 1.0
    np.testing.assert_allclose(float(b), float(a), rtol=1e-10)


def test_tangent_gradient_is_the_derivative_along_right_perturbations() -> None:
    """⟨grad, δ⟩ = d/dε loss(T ⊕ εδ) at ε = 0 for any direction δ: the gradient lives in the
    (K, 6) tangent space of right perturbations, not on the 7 quaternion/translation
    parameters. A small step against it lowers the loss."""
    T = _random_trajectory(5, K)
    Z = _random_trajectory(6, K)
    problem = _problem(Z, np.array([1, 1, 0, 1, 1, 1, 0, 0, 1, 1]), w_smooth=3.0)
    (value, terms), grad = _value_and_grad(T, problem)
    assert grad.shape == (K, 6)
    np.testing.assert_allclose(float(value), float(_loss(T, problem)), rtol=1e-12)
    np.testing.assert_allclose(float(value), float(terms[0] + terms[1]), rtol=1e-12)
    rng = np.random.default_rng(7)
    for _ in range(3):
        delta = jnp.asarray(rng.normal(size=(K, 6)))
        directional = _directional_derivative(T, problem, delta)
        np.testing.assert_allclose(float(jnp.sum(grad * delta)), directional, rtol=1e-7)
    stepped = manifold.rplus(T, -1e-4 * grad)
    assert float(_loss(stepped, problem)) < float(value)


def test_fill_gaps_keeps_reports_and_follows_geodesics() -> None:
    """The starting point: reports where they exist; a gap is filled along the geodesic
    between the reports on either side; the ends hold the nearest report."""
    Z = _random_trajectory(8, 8)
    observed = np.array([False, True, False, False, True, True, False, False])
    T = tf.fill_gaps(Z, observed)
    M, MZ = np.asarray(T.as_matrix()), np.asarray(Z.as_matrix())
    for i in (1, 4, 5):
        np.testing.assert_allclose(M[i], MZ[i], atol=1e-12)
    np.testing.assert_allclose(M[0], MZ[1], atol=1e-12)  # before the first report
    np.testing.assert_allclose(M[6], MZ[5], atol=1e-12)  # after the last report
    np.testing.assert_allclose(M[7], MZ[5], atol=1e-12)
    for i, t in ((2, 1 / 3), (3, 2 / 3)):  # between reports 1 and 4
        want = np.asarray(Z[1].interpolate(Z[4], t).as_matrix())
        np.testing.assert_allclose(M[i], want, atol=1e-12)


# ---------------------------------------------------------------------------------------
# The ground truth's velocity: the conventions the spline is compared in.


def test_ground_truth_velocity_is_the_body_velocity() -> None:
    """``ground_truth_velocity`` is the body velocity (v, ω) with T⁻¹ Ṫ = hat(ω): it equals
    the central difference log(T(t − ε)⁻¹ T(t + ε)) / 2ε of the generating function, and,
    with the body x axis along the direction of travel, its linear part is (speed, 0, 0),
    the speed |ṗ| from the analytic derivative of the figure-eight's position."""
    t = jnp.asarray([0.3, 4.1, 9.7, 15.0, 22.2, 29.9])
    w = np.asarray(tf.ground_truth_velocity(t))
    assert w.shape == (6, 6)
    eps = 1e-4
    fd = np.asarray(manifold.rminus(tf.figure_eight(t - eps), tf.figure_eight(t + eps)) / (2 * eps))
    np.testing.assert_allclose(w, fd, atol=1e-7)
    s = 2 * np.pi * np.asarray(t) / tf.PERIOD
    p_dot = (2 * np.pi / tf.PERIOD) * np.stack(
        [3 * np.cos(s), 3 * np.cos(2 * s), 1.5 * np.cos(3 * s)], -1
    )
    np.testing.assert_allclose(w[:, 0], np.linalg.norm(p_dot, axis=-1), rtol=1e-12)
    np.testing.assert_allclose(w[:, 1:3], 0.0, atol=1e-12)
    # The angular part turns the body: banked turns, so all three axes move somewhere.
    assert np.all(np.max(np.abs(w[:, 3:]), axis=0) > 0.05)
