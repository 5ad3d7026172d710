"""examples/imu_preintegration.py: the script end to end (--quick, in a subprocess, as a user
runs it), and pieces of it in process.

The subprocess test reads the printed report: the product of increments against the matrix
exponential of the flow, the step's Jacobians against ``jax.jacfwd``, the preintegrated ΔR,
Δv, Δp against the analytic values and their convergence at a 10x finer step, the Monte Carlo
variance ratios, and (where gtsam is installed) the comparisons with GTSAM. The in-process
tests check Γ₂ and its Jacobian against independent references, the helix's closed-form
derivatives, the CSV reader, and that ``predict`` (X_j = Γ Φ(X_i) ΔX_ij) turns the analytic
preintegrated quantities back into the true state, gravity included.
"""

from __future__ import annotations

import importlib.util
import os
import re
import subprocess
import sys
from pathlib import Path
from types import ModuleType
from typing import Dict, List

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg

from jaxlie_geo import SE23

REPO = Path(__file__).resolve().parents[1]
SCRIPT = REPO / "examples" / "imu_preintegration.py"
HAVE_GTSAM = importlib.util.find_spec("gtsam") is not None
NUMBER = r"([-+\d.e]+)"


def _load_example() -> ModuleType:
    spec = importlib.util.spec_from_file_location("example_imu_preintegration", SCRIPT)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # NamedTuple classes look their module up
    spec.loader.exec_module(module)
    return module


imu = _load_example()


# ---------------------------------------------------------------------------------------
# The script, end to end.


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory) -> tuple:
    png = tmp_path_factory.mktemp("imu") / "pictures" / "imu.png"  # parent does not exist yet
    # The run compiles far more than it computes: XLA's backend optimisations off saves a
    # fifth of its time when the compilation cache is cold.
    flags = os.environ.get("XLA_FLAGS", "") + " --xla_backend_optimization_level=0"
    proc = subprocess.run(
        [sys.executable, str(SCRIPT), "--quick", "--out", str(png)],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=600,
        env={**os.environ, "XLA_FLAGS": flags.strip()},
    )
    assert proc.returncode == 0, f"exit {proc.returncode}\n{proc.stdout}\n{proc.stderr}"
    return proc.stdout, png


def _floats(pattern: str, text: str) -> List[float]:
    match = re.search(pattern, text)
    assert match, f"pattern {pattern!r} not found in:\n{text}"
    return [float(x) for x in match.groups()]


def _convergence(out: str) -> Dict[str, Dict[str, np.ndarray]]:
    """{scheme line: {"coarse", "fine", "ratio": (ΔR, Δv, Δp)}} from the table."""
    table = {}
    for name in (
        "exact increment, samples at step start",
        "exact increment, samples mid-step",
        "Forster's increment, samples mid-step",
    ):
        section = out[out.index(f" {name}:") :]
        rows = re.findall(
            rf"^  (dt = [\d.]+ ms|ratio \(10x finer step\))\s+{NUMBER}\s+{NUMBER}\s+"
            rf"{NUMBER}$",
            section,
            re.M,
        )[:3]
        assert len(rows) == 3, section
        table[name] = {
            key: np.array([float(x) for x in row[1:]])
            for key, row in zip(("coarse", "fine", "ratio"), rows)
        }
    return table


def test_quick_run_reports_and_draws(quick_run) -> None:
    """--quick runs the 2 s helix at 100 Hz and writes a non-trivial PNG."""
    out, png = quick_run
    assert "Helix: 2 s at 100 Hz (200 IMU samples)" in out, out
    assert f"Wrote {png}" in out, out
    data = png.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    assert len(data) > 50_000  # a 3D view and six panels, not an empty canvas


def test_increment_is_the_flow_and_forster_is_not(quick_run) -> None:
    """(2) with the exact increment (3) reproduces the matrix exponential of the flow for inputs
    held over each step, to rounding after 200 steps; Forster's increment does not."""
    exact, forster = _floats(rf"exact increment {NUMBER}, Forster's {NUMBER}", quick_run[0])
    assert exact < 1e-12
    assert forster > 1e-3


def test_step_jacobians_match_jacfwd(quick_run) -> None:
    """The A_k = Ad(Υ⁻¹) F and B_k (from the group's adjoint and jac_right) that the scan used
    agree with jax.jacfwd of the step through right perturbations, for both increments, at
    steps of 10 ms and of 1 s (Γ₂ from its series and in closed form)."""
    A, B = _floats(rf"max \|A_k - jacfwd\| {NUMBER}, max \|B_k - jacfwd\| {NUMBER}", quick_run[0])
    assert A < 1e-12 and B < 1e-12


def test_agreement_with_the_analytic_values_and_convergence(quick_run) -> None:
    """Against the closed-form ΔR, Δv, Δp over 2 s: samples held from the start of each step
    give first-order errors (10x finer step: 10x smaller); mid-step samples make the exact
    increment second order (100x) but leave Forster's increment first order in Δv and Δp."""
    table = _convergence(quick_run[0])
    start = table["exact increment, samples at step start"]
    mid = table["exact increment, samples mid-step"]
    forster = table["Forster's increment, samples mid-step"]
    # Seed-free numbers: ΔR 4.5e-3 rad, Δv 0.06 m/s, Δp 0.06 m at 10 ms; 1e-4 mid-step.
    assert np.all(start["coarse"] < [1e-2, 0.15, 0.15]), start
    assert np.all(mid["coarse"] < [1e-4, 1e-3, 1e-3]), mid
    assert np.all((start["ratio"] > 9) & (start["ratio"] < 11)), start
    assert np.all((mid["ratio"] > 90) & (mid["ratio"] < 110)), mid
    assert 90 < forster["ratio"][0] < 110  # the rotation is the same product of Exp(ω dt)
    assert np.all((forster["ratio"][1:] > 9) & (forster["ratio"][1:] < 11)), forster
    assert np.all(forster["coarse"][1:] > 50 * mid["coarse"][1:]), forster


def test_monte_carlo_matches_the_propagated_covariance(quick_run) -> None:
    """The empirical variance of 300 noisy runs over the propagated one, per block, is 1
    within 4 standard errors; the NEES is 9 within 4 standard errors; about 99.7% of the
    errors lie inside the 3σ bounds."""
    out = quick_run[0]
    for block in ("position", "rotation", "velocity"):
        ratio, stderr = _floats(rf"{block} {NUMBER} ± {NUMBER}", out)
        assert 0.01 < stderr < 0.1
        assert abs(ratio - 1) < 4 * stderr, (block, ratio, stderr)
    nees, stderr = _floats(rf"NEES {NUMBER} \(expected 9 ± {NUMBER}\)", out)
    assert abs(nees - 9) < 4 * stderr
    (inside,) = _floats(r"inside ±3σ: ([\d.]+)%", out)
    assert 99.0 < inside <= 100.0


@pytest.mark.skipif(not HAVE_GTSAM, reason="gtsam is not installed")
def test_gtsam_data_and_gtsam(quick_run) -> None:
    """GTSAM's imuAndGPSdata.csv, preintegrated and propagated from its initial state, lands on
    its GPS fixes (to the file's 6 decimals); Forster's increment and its covariance agree with
    GTSAM's to rounding, and so does ``predict`` with gravity (``MakeSharedU``)."""
    out = quick_run[0]
    (gps,) = _floats(rf"max \|position - GPS\| over the fixes {NUMBER} m", out)
    assert gps < 1e-6
    window = _floats(
        rf"gtsam.PreintegratedImuMeasurements: max \|ΔR\| {NUMBER}, \|Δv\| {NUMBER} m/s, "
        rf"\|Δp\| {NUMBER} m; covariance {NUMBER}",
        out,
    )
    assert max(window) < 1e-12, window
    import gtsam

    if hasattr(gtsam, "PreintegratedImuMeasurementsManifold"):  # gtsam 4.3
        manifold = _floats(rf"Manifold: {NUMBER}, {NUMBER}, {NUMBER}; covariance {NUMBER}", out)
        assert max(manifold) < 1e-10, manifold
        predict = _floats(
            rf"predict\(\) from the true state at 0 vs ours: {NUMBER}, {NUMBER}, {NUMBER};", out
        )
        assert max(predict) < 1e-10, predict


def test_without_gtsam_the_script_says_so(quick_run) -> None:
    """gtsam is optional: without it the script skips the comparisons and says so."""
    if HAVE_GTSAM:
        assert "gtsam not installed" not in quick_run[0]
    else:
        assert "gtsam not installed: skipping" in quick_run[0], quick_run[0]


# ---------------------------------------------------------------------------------------
# In process (conftest enables float64).


def _gamma2_reference(phi: np.ndarray) -> np.ndarray:
    """Γ₂(φ) = Σ φ̂ⁿ/(n + 2)!: the top-right block of expm([[φ̂, I, 0], [0, 0, I], [0, 0, 0]])."""
    W = np.array([[0, -phi[2], phi[1]], [phi[2], 0, -phi[0]], [-phi[1], phi[0], 0]])
    M = np.zeros((9, 9))
    M[:3, :3], M[:3, 3:6], M[3:6, 6:9] = W, np.eye(3), np.eye(3)
    return scipy.linalg.expm(M)[:3, 6:9]


_gamma2 = jax.jit(imu.gamma2)
_gamma2_jacobian = jax.jit(imu.gamma2_jacobian)
_gamma2_jacfwd = jax.jit(jax.jacfwd(lambda phi, a: imu.gamma2(phi) @ a))


@pytest.mark.parametrize("theta_sq", [0.0, 1e-12, 1e-4, 0.0999999, 0.1000001, 0.7, 9.0])
def test_gamma2_and_its_jacobian(theta_sq: float) -> None:
    """Γ₂ against a block matrix exponential (both sides of the switch to its series), and
    ∂(Γ₂(φ) a)/∂φ against ``jax.jacfwd`` of Γ₂(φ) a."""
    rng = np.random.default_rng(3)
    direction = rng.normal(size=3)
    phi = np.sqrt(theta_sq) * direction / np.linalg.norm(direction)
    a = rng.normal(size=3)
    phi_, a_ = jnp.asarray(phi), jnp.asarray(a)
    np.testing.assert_allclose(
        np.asarray(_gamma2(phi_)), _gamma2_reference(phi), rtol=0, atol=2e-15
    )
    want, got = _gamma2_jacfwd(phi_, a_), _gamma2_jacobian(phi_, a_)
    np.testing.assert_allclose(np.asarray(got), np.asarray(want), rtol=0, atol=1e-14)


def test_helix_derivatives() -> None:
    """The helix's closed-form velocity, acceleration and body rates are the derivatives of its
    position, velocity and attitude (central differences, error ~h²)."""
    helix, h = imu.Helix(), 1e-5
    t = np.linspace(0.0, 9.0, 7)
    s, plus, minus = helix.state(t), helix.state(t + h), helix.state(t - h)
    np.testing.assert_allclose(s["v"], (plus["p"] - minus["p"]) / (2 * h), atol=1e-8)
    np.testing.assert_allclose(s["a"], (plus["v"] - minus["v"]) / (2 * h), atol=1e-8)
    W = np.einsum("kji,kjl->kil", s["R"], (plus["R"] - minus["R"]) / (2 * h))  # Rᵀ Ṙ = ω̂
    np.testing.assert_allclose(W, -np.swapaxes(W, 1, 2), atol=1e-8)
    np.testing.assert_allclose(
        s["omega"], np.stack([W[:, 2, 1], W[:, 0, 2], W[:, 1, 0]], -1), atol=1e-8
    )
    np.testing.assert_allclose(imu._quat_matrix(s["q"]), s["R"], atol=1e-15)


def test_predict_turns_the_analytic_deltas_into_the_true_state() -> None:
    """X_j = Γ_Δt Φ_Δt(X_i) ΔX_ij with the closed-form ΔR, Δv, Δp is the true state at t_j
    (gravity (0, 0, −9.81)): the decomposition of the flow that preintegration relies on."""
    helix = imu.Helix()
    t_i, t_j = 1.3, 4.1
    dR, dv, dp = imu.analytic_delta(helix, t_i, t_j)
    q_i, q_j = helix.state(t_i)["q"], helix.state(t_j)["q"]
    dq = imu._quat_multiply(q_i * np.array([1.0, -1.0, -1.0, -1.0]), q_j)
    np.testing.assert_allclose(imu._quat_matrix(dq), dR, atol=1e-14)
    delta = SE23(jnp.asarray(np.concatenate([dq, dp, dv])))
    got = imu.matrices(imu.predict(helix.extended_pose(t_i), delta, t_j - t_i, imu.GRAVITY))
    want = imu.matrices(helix.extended_pose(t_j))
    np.testing.assert_allclose(got, want, atol=1e-12)


def test_read_imu_csv(tmp_path: Path) -> None:
    """GTSAM's format: the initial state's ten numbers are (p, v, q_xyzw); IMU rows are
    (a, ω); a GPS row records how many IMU rows precede it."""
    csv = tmp_path / "imu.csv"
    csv.write_text(
        "i,1.0,2.0,3.0,0.1,0.2,0.3,0.0,0.0,0.6,0.8\n"
        "0,0.5,0.0,0.0,0.0,0.0,0.01\n"
        "1,1.0,2.0,3.0,0.0,0.0,0.0,1.0\n"
        "0,0.6,0.0,0.0,0.0,0.0,0.02\n"
        "0,0.7,0.0,0.0,0.0,0.0,0.03\n"
        "1,1.1,2.0,3.0,0.0,0.0,0.0,1.0\n"
    )
    data = imu.read_imu_csv(csv)
    np.testing.assert_array_equal(data["x0"], [0.8, 0.0, 0.0, 0.6, 1.0, 2.0, 3.0, 0.1, 0.2, 0.3])
    np.testing.assert_array_equal(data["imu"][:, 0], [0.5, 0.6, 0.7])
    np.testing.assert_array_equal(data["imu"][:, 5], [0.01, 0.02, 0.03])
    np.testing.assert_array_equal(data["gps_index"], [1, 3])
    np.testing.assert_array_equal(data["gps"][:, 0], [1.0, 1.1])
    csv.write_text("i,0,0,0,0,0,0,0,0,0,2.0\n0,0,0,0,0,0,0\n1,0,0,0,0,0,0,1\n")
    with pytest.raises(ValueError, match="unit quaternion"):
        imu.read_imu_csv(csv)
