"""An inverse-kinematics-sized program, compiled and run on jaxlie_geo and on jaxlie 1.5.

Forward kinematics of a 7-joint serial chain (revolute joints about each link's z axis,
fixed link transforms between them), the log of the pose residual
r(q) = log(T_target⁻¹ fk(q)), its ``jax.jacfwd``, and one damped Gauss–Newton step
q ← q − (JᵀJ + λI)⁻¹ Jᵀr, λ = 10⁻⁶, jitted as one program; for one problem and vmapped over
1,000, float32, the same source on both libraries. Compile: trace, lower and compile from
empty caches; run: the median of 5 calibrated rounds; each the minimum over ``--repeats``
repetitions in which the libraries alternate.

Usage:
  python -m benchmarks.ik_program [--save]
"""

from __future__ import annotations

import statistics
import sys

import jax
import jax.numpy as jnp
import jaxlie
import numpy as np

import jaxlie_geo
from benchmarks import common as C
from benchmarks.report import ik_program_table, save

JOINTS, SIZES = 7, (1, 1000)


def program(lib, batch: int):
    """(the Gauss–Newton step of ``lib``, vmapped for a batch, and its inputs)."""
    rng = np.random.default_rng(0)
    links = lib.SE3.exp(jnp.asarray(0.4 * rng.normal(size=(JOINTS, 6)), jnp.float32)).parameters()

    def residual(q, target):
        T = lib.SE3(links[0])
        for i in range(JOINTS):
            T = T @ lib.SE3.from_rotation(lib.SO3.from_z_radians(q[i]))
            T = T @ lib.SE3(links[i + 1]) if i + 1 < JOINTS else T
        return (lib.SE3(target).inverse() @ T).log()

    def step(q, target):
        r, J = residual(q, target), jax.jacfwd(residual)(q, target)
        H = J.T @ J + 1e-6 * jnp.eye(JOINTS, dtype=q.dtype)
        return q - jnp.linalg.solve(H, J.T @ r), r

    rng = np.random.default_rng(1)
    shape = (batch,) if batch > 1 else ()
    q = jnp.asarray(rng.uniform(-1, 1, (*shape, JOINTS)), jnp.float32)
    target = lib.SE3.exp(jnp.asarray(0.5 * rng.normal(size=(*shape, 6)), jnp.float32))
    return (jax.vmap(step) if batch > 1 else step), (q, target.parameters())


def seconds(lib, batch: int) -> tuple:
    """(compile seconds from empty caches, run seconds per call)."""
    fn, args = program(lib, batch)
    jax.clear_caches()
    compiled, compile_s = C.compile_fn(fn, args)
    times = C.measure([(compiled, args, C.timed_call(compiled, args)[1])], 5, 0.2)[0]
    return compile_s, statistics.median(times)


def main(argv=None) -> int:
    p = C.parser(__doc__)
    p.add_argument("--repeats", type=int, default=3)
    args = C.parse(p, argv)
    libs, rows = {"ours": jaxlie_geo, "jaxlie": jaxlie}, []
    for batch in SIZES:
        best = {name: (float("inf"), float("inf")) for name in libs}
        for r in range(args.repeats):
            for name in list(libs)[:: 1 if r % 2 == 0 else -1]:
                best[name] = tuple(map(min, best[name], seconds(libs[name], batch)))
        row = {"batch": batch}
        for name, (compile_s, run_s) in best.items():
            row.update({f"compile_{name}_s": compile_s, f"run_{name}_s": run_s})
        rows.append(row)
    info = C.machine_info("benchmarks.ik_program", dtype="float32", joints=JOINTS)
    data = {"machine": info, "results": rows}
    print("\n".join(ik_program_table(data)))
    save("ik-program", data, args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
