"""Execute the tutorial notebooks in ``notebooks/`` and check what they print.

Each notebook runs top to bottom in a fresh kernel, in a temporary working directory, with
``CELL_TIMEOUT_S`` per cell; any error fails the test. The kernel is this interpreter
(``sys.executable``, i.e. the project's virtualenv): a ``python3`` kernelspec pointing at it
is written to a temporary ``JUPYTER_PATH`` entry, which takes precedence over any user or
system kernelspec of that name, and a probe cell appended to the in-memory copy confirms
which Python ran. Then one property per notebook is read back from its outputs, so a
notebook that runs but tells a wrong story fails too.

The committed notebooks are stripped (no outputs, no execution counts: ``make lint`` checks
it with ``tests/check_repository.py``); run them in Jupyter to see the figures
(``notebooks/README.md``).

Needs nbformat, nbclient and ipykernel (and matplotlib, mpmath, jaxlie); a missing one is
an import error here, i.e. a failure, never a skip.
"""

from __future__ import annotations

import json
import re
import sys
import time
from pathlib import Path
from typing import List, Tuple

import ipykernel  # noqa: F401  (the kernel the notebooks run in)
import nbformat
import pytest
from nbclient import NotebookClient

REPO = Path(__file__).resolve().parents[1]
NOTEBOOK_DIR = REPO / "notebooks"
NOTEBOOKS = (
    "01_constant_velocity_motion.ipynb",
    "02_numerics.ipynb",
    "03_tour_for_jaxlie_users.ipynb",
)
CELL_TIMEOUT_S = 120
PROBE = "import sys\nprint('KERNEL_PYTHON=' + sys.executable)"


def _python3_kernelspec(root: Path) -> None:
    """A ``python3`` kernelspec under ``root`` that starts this interpreter."""
    spec = root / "kernels" / "python3"
    spec.mkdir(parents=True)
    (spec / "kernel.json").write_text(
        json.dumps(
            {
                "argv": [sys.executable, "-m", "ipykernel_launcher", "-f", "{connection_file}"],
                "display_name": "Python 3 (test)",
                "language": "python",
            }
        )
    )


def _execute(name: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Tuple[str, int, float]:
    """Run notebook ``name``; return its text output, its number of PNG outputs and the
    wall time. Raises (test failure) on any cell error or timeout."""
    jupyter_dir, workdir = tmp_path / "jupyter", tmp_path / "work"
    workdir.mkdir()
    _python3_kernelspec(jupyter_dir)
    monkeypatch.setenv("JUPYTER_PATH", str(jupyter_dir))

    nb = nbformat.read(NOTEBOOK_DIR / name, as_version=4)
    nb.cells.append(nbformat.v4.new_code_cell(PROBE))
    client = NotebookClient(
        nb,
        timeout=CELL_TIMEOUT_S,
        kernel_name="python3",
        allow_errors=False,
        resources={"metadata": {"path": str(workdir)}},
    )
    start = time.perf_counter()
    client.execute()
    seconds = time.perf_counter() - start

    texts: List[str] = []
    images = 0
    for cell in nb.cells:
        for out in cell.get("outputs", []):
            assert out.output_type != "error", f"{name}: {out.ename}: {out.evalue}"
            if out.output_type == "stream" and out.name == "stdout":
                texts.append(out.text)
            elif out.output_type in ("display_data", "execute_result"):
                images += "image/png" in out.data
                texts.append(out.data.get("text/plain", ""))
    text = "".join(texts)

    python = re.search(r"KERNEL_PYTHON=(.*)", text)
    assert python, f"{name}: the probe cell printed nothing"
    assert Path(python.group(1).strip()).resolve() == Path(sys.executable).resolve(), (
        f"{name} ran in {python.group(1)}, not in {sys.executable}"
    )
    print(f"{name}: executed in {seconds:.1f} s")
    return text, images, seconds


def _number(pattern: str, text: str) -> float:
    match = re.search(pattern, text)
    assert match, f"pattern {pattern!r} not found in the notebook output:\n{text}"
    return float(match.group(1))


NUM = r"([-+]?\d[\d.]*(?:e[-+]?\d+)?)"


def test_01_constant_velocity_motion(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The constant-velocity notebook runs and tells its story: the geometric circle agrees with
    ``motion.arc``/``pose_at``, §5.3's velocity arrives and §5.4's as printed does not, and
    the duck game's answer is the example's."""
    text, images, _ = _execute("01_constant_velocity_motion.ipynb", tmp_path, monkeypatch)
    # The geometric circle of Zhang (2022), §5.1 and motion.arc / motion.pose_at agree.
    assert _number(r"arc centre agreement: " + NUM, text) < 1e-6
    assert _number(r"pose agreement \(50 times\): " + NUM, text) < 1e-6
    # §5.3's velocity reaches the target; §5.4's as printed (a sign slip) does not.
    assert re.search(r"§5\.3's velocity arrives at \[\s*1\.\s+0\.\s*\]", text), text
    assert re.search(r"§5\.4's velocity arrives at \[\s*0\.\s+1\.\s*\]", text), text
    # The duck game's answer, as in examples/duck_game.py.
    assert "duck at t = 3: (3.115405, 0.243283), heading 56.2500 deg" in text, text
    assert _number(r"distance to the bread: " + NUM + " m -> rescued!", text) < 0.5
    assert images >= 4


def test_02_numerics(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The numerics notebook runs; its naive kernels are hundreds of ulp off and ours under 8,
    and d log(exp ξ)/dξ at a pure translation is the identity (jaxlie's is off by 0.5)."""
    text, images, _ = _execute("02_numerics.ipynb", tmp_path, monkeypatch)
    for kernel in ("F1", "F2", "G"):
        line = re.search(rf"^\s*{kernel}\s*: naive (\S+) ulp.*jaxlie_geo (\S+) ulp$", text, re.M)
        assert line, f"no error line for {kernel}:\n{text}"
        naive, ours = float(line.group(1)), float(line.group(2))
        assert ours < 8, f"{kernel}: jaxlie_geo {ours} ulp"
        assert naive > 100, f"{kernel}: naive only {naive} ulp (the story needs it bad)"
    # d log(exp ξ)/dξ at a pure SE(3) translation: jaxlie off by 0.5, ours the identity.
    jaxlie_err = _number(r"at the pure translation: jaxlie " + NUM, text)
    ours_err = _number(r"at the pure translation: jaxlie \S+, jaxlie_geo " + NUM, text)
    assert jaxlie_err == pytest.approx(0.5, abs=1e-3)
    assert ours_err <= 1e-6
    assert _number(r"over all \d+ angles: jaxlie \S+, jaxlie_geo " + NUM, text) < 8 * 1.2e-7
    assert images >= 3


def test_03_tour_for_jaxlie_users(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The tour notebook runs: the same jaxlie code gives the same numbers, errors name the
    function, argument and shapes, and the propagated covariance matches Monte Carlo."""
    text, images, _ = _execute("03_tour_for_jaxlie_users.ipynb", tmp_path, monkeypatch)
    # The same jaxlie code gives the same numbers with either library (float64).
    assert _number(r"same code, max \|jaxlie_geo - jaxlie\| over all outputs = " + NUM, text) < 1e-9
    # The trace-time error names the function, the argument and both shapes.
    assert "ValueError: SE3.exp: `tangent` must have shape (*batch, 6), got shape (5,)." in text, (
        text
    )
    assert _number(r"rminus: \|J_a - autodiff\| = " + NUM, text) < 1e-9
    # First-order covariance propagation within Monte Carlo noise (4000 samples).
    assert _number(r"/ \|propagate_compose\| = " + NUM, text) < 0.1
    assert images >= 1


def test_every_notebook_is_tested() -> None:
    """Every notebook in ``notebooks/`` is in ``NOTEBOOKS`` (so each is executed above)."""
    assert sorted(p.name for p in NOTEBOOK_DIR.glob("*.ipynb")) == sorted(NOTEBOOKS)
