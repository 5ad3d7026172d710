"""Smoke test for the examples: run them in --quick mode as a user would."""

from __future__ import annotations

import importlib.util
import re
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
HAVE_JAXLIE = importlib.util.find_spec("jaxlie") is not None  # the test extra installs it


def _float(pattern: str, text: str) -> float:
    match = re.search(pattern, text)
    assert match, f"pattern {pattern!r} not found in output:\n{text}"
    return float(match.group(1))


def _run_quick(script: str, *args: str, timeout: int = 300) -> str:
    """``examples/<script> --quick *args`` in a fresh process; its stdout, after asserting
    that it exited 0."""
    proc = subprocess.run(
        [sys.executable, f"examples/{script}", "--quick", *args],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=timeout,
    )
    out = proc.stdout
    assert proc.returncode == 0, f"exit {proc.returncode}\nstdout:\n{out}\nstderr:\n{proc.stderr}"
    return out


def test_pose_interpolation_quick(tmp_path: Path) -> None:
    """``examples/pose_interpolation.py --quick`` runs, prints its timing report, agrees with an
    independent float64 NumPy implementation (and with jaxlie where installed), and writes a
    PNG."""
    png = tmp_path / "pictures" / "pose_interpolation.png"  # parent does not exist yet
    out = _run_quick("pose_interpolation.py", "--out", str(png), timeout=120)

    # The expected report lines.
    assert re.search(r"Interpolating 10,000 SE3 pose pairs \(float32\)", out), out
    assert _float(r"compile \(first call, incl\. tracing\)\s+([\d.]+) (?:s|ms)\b", out) > 0
    assert re.search(r"jaxlie_geo, one jit call\s+[\d.]+ [nµm]?s/pose .*median of 3 runs", out), out
    assert re.search(
        r"Python loop, NumPy per pose\s+[\d.]+ [nµm]?s/pose -> jaxlie_geo is [\d,]+x faster", out
    ), out
    assert re.search(r"Python loop, jaxlie_geo call per pose\s+.*x faster", out), out
    assert "extrapolated to 10,000" in out, out

    # Our float32 result agrees with an independent float64 NumPy implementation.
    assert _float(r"max \|ours - float64 NumPy\| over the \d+ looped pairs: (\S+)", out) < 1e-5

    if HAVE_JAXLIE:
        assert re.search(
            r"jaxlie 1\.5, same expression, jit\s+[\d.]+ [nµm]?s/pose -> jaxlie_geo is [\d.]+x "
            r"faster",
            out,
        ), out
        # Same computation as jaxlie: the 4x4 matrices agree to float32 accuracy ...
        pattern = r"max \|ours - jaxlie\| over 10,000 poses, as 4x4 matrices: (\S+)"
        assert _float(pattern, out) < 1e-4
        # ... and where they differ most, ours is the one close to the float64 reference.
        assert _float(r"worst pair #[\d,]+ vs a float64 NumPy reference: ours (\S+),", out) < 1e-5
    else:
        assert "jaxlie not installed" in out, out

    # A real, non-trivial PNG.
    assert png.is_file(), out
    data = png.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    assert len(data) > 20_000


def test_bundle_adjustment_quick() -> None:
    """``examples/bundle_adjustment.py --quick`` runs and its synthetic solve ends at the noise
    level: an RMS reprojection error no larger than at the true values."""
    out = _run_quick("bundle_adjustment.py")
    after = _float(
        r"synthetic:.*?RMS reprojection error [\d.]+ px -> ([\d.]+) px", out.replace("\n", " ")
    )
    truth = _float(r"RMS at the true values ([\d.]+) px", out)
    assert after <= truth, out


def test_batched_pose_fits_quick() -> None:
    """``examples/batched_pose_fits.py --quick``: every vmapped fit converges to the Kabsch
    optimum (``SE3.align``, closed form) and equals the same problem solved alone."""
    out = _run_quick("batched_pose_fits.py")
    assert re.search(r"converged (\d+)/\1,", out), out
    assert _float(r"against Kabsch \(SE3.align\): (\S+) rad", out) < 1e-6, out
    assert _float(r"against Kabsch \(SE3.align\): \S+ rad, (\S+) m", out) < 1e-6, out
    assert _float(r"against three solved alone: (\S+) rad", out) < 1e-12, out
    assert _float(r"against three solved alone: \S+ rad, (\S+) m", out) < 1e-12, out


def test_learn_odometry_scale_quick() -> None:
    """``examples/learn_odometry_scale.py --quick``: the implicit derivative through the solve
    equals central differences, and the learned scale lands near the true one and lowers the
    trajectory error."""
    out = _run_quick("learn_odometry_scale.py")
    assert _float(r"relative difference (\S+)", out) < 1e-6, out
    scale = _float(r"learned odometry scale (\S+)", out)
    assert abs(scale - 1.08) < 0.02, out
    before = _float(r"RMS position error (\S+) m ->", out)
    after = _float(r"RMS position error \S+ m -> (\S+) m", out)
    assert after < 0.5 * before, out


def test_readme_python_blocks_run() -> None:
    """Every ```python block of README.md runs as written, in order, in a fresh process
    (float32 defaults, as a user's would be); the quick start asserts its own round trip."""
    text = (REPO / "README.md").read_text(encoding="utf-8")
    blocks = re.findall(r"^```python\n(.*?)^```", text, flags=re.S | re.M)
    assert blocks, "README.md has no python block"
    proc = subprocess.run(
        [sys.executable, "-c", "\n".join(blocks)],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
