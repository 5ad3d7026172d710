"""Kernel sizes: no operation's optimised program grows more than 20% past its record.

Reference: ``tests/kernel_sizes.json``, per jax version, the optimised HLO instruction
counts of each group's ``exp``, ``log``, ``jac_right``, ``jac_right_inv``, ``jlog``,
gradient of log∘exp and ``from_matrix`` on a batch of 1,000, as
``benchmarks/kernel_sizes.py --record`` counts them (the results page has the table, with
compile times). The counts are XLA's, so they are compared with the record of the jax
minor release that runs (XLA's optimisations differ between releases: SE₂(3)'s ``jlog`` is 3,692
instructions with jax 0.5.3, 1,952 with 0.10.2). A kernel that grows makes every user's
program compile longer; a change that grows one on purpose re-records the file, and the
diff shows by how much. A kernel that shrinks more than 20% below its record fails too, so
that the record stays a real bound.
"""

from __future__ import annotations

import json
from pathlib import Path

import jax
import pytest
from conftest import GROUPS, group_name

from benchmarks import kernel_sizes as K

RECORD = json.loads((Path(__file__).parent / "kernel_sizes.json").read_text())
TOLERANCE = 0.2


@pytest.mark.parametrize("dtype", K.DTYPES)
@pytest.mark.parametrize("G", GROUPS, ids=group_name)
def test_kernels_stay_within_their_recorded_size(G, dtype):
    """Each operation's instruction count within ±20% of the record of this jax minor
    release (CI's and the oldest supported one are recorded; another release fails until
    it is recorded)."""
    assert RECORD["batch"] == K.N, "the record was taken at another batch size"
    release = K.release(jax.__version__)
    record = RECORD["instructions"].get(release)
    assert record is not None, (
        f"no kernel sizes recorded for jax {release} (recorded: "
        f"{', '.join(RECORD['instructions'])}): python -m benchmarks.kernel_sizes --record "
        "adds them"
    )
    out = {}
    for op in K.OPS:
        out[op] = (K.instructions(G.__name__, op, dtype), record[f"{G.__name__}.{op}.{dtype}"])
    bad = {op: gw for op, gw in out.items() if abs(gw[0] - gw[1]) > TOLERANCE * gw[1]}
    assert not bad, (
        f"instructions (now, recorded) with jax {jax.__version__} off by more than 20%: "
        f"{bad}; re-record with python -m benchmarks.kernel_sizes --record if intended"
    )
