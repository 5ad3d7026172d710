"""An inverse-kinematics-sized program, compiled and run on jaxlie_geo and on jaxlie 1.5.

The program a robotics user jits: forward kinematics of a 7-joint serial chain (revolute
joints about each link's z axis, fixed link transforms between them: 13 SE3 products, and
one more in the residual),
the log of the pose residual r(q) = log(T_target⁻¹ · fk(q)), its Jacobian by
``jax.jacfwd``, and one damped Gauss–Newton step q ← q − (JᵀJ + λI)⁻¹ Jᵀr, λ = 10⁻⁶; for
one problem and vmapped over B = 1,000 targets, in float32. The same source runs on both
libraries (``lib.SE3``, ``lib.SO3``).

Reported: trace + lower + compile seconds from empty caches, and run time per call (the
median of calibrated rounds), each the minimum over ``--repeats`` repetitions in which the
two libraries alternate.

Usage:
  python -m benchmarks.ik_program                 # prints the table
  python -m benchmarks.ik_program --save          # raw/<machine>/ik-program.json, page
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time

from benchmarks import common as C

JOINTS = 7
SIZES = (1, 1000)


def step_program(lib):
    """(gn_step(q, target_params) -> q, residual) for library ``lib``."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    rng = np.random.default_rng(0)
    link_params = lib.SE3.exp(jnp.asarray(0.4 * rng.normal(size=(JOINTS, 6)), jnp.float32))
    links = [lib.SE3(link_params.parameters()[i]) for i in range(JOINTS)]

    def fk(q):
        T = links[0]
        for i in range(JOINTS):
            T = T @ lib.SE3.from_rotation(lib.SO3.from_z_radians(q[i]))
            if i + 1 < JOINTS:
                T = T @ links[i + 1]
        return T

    def residual(q, target):
        return (lib.SE3(target).inverse() @ fk(q)).log()

    def gn_step(q, target):
        r = residual(q, target)
        J = jax.jacfwd(residual)(q, target)
        H = J.T @ J + 1e-6 * jnp.eye(JOINTS, dtype=q.dtype)
        return q - jnp.linalg.solve(H, J.T @ r), r

    return gn_step


def inputs(lib, batch: int):
    import jax.numpy as jnp
    import numpy as np

    rng = np.random.default_rng(1)
    shape = (batch,) if batch > 1 else ()
    q = jnp.asarray(rng.uniform(-1, 1, (*shape, JOINTS)), jnp.float32)
    target = lib.SE3.exp(jnp.asarray(0.5 * rng.normal(size=(*shape, 6)), jnp.float32))
    return q, target.parameters()


def build(lib, batch: int):
    import jax

    step = step_program(lib)
    return jax.vmap(step) if batch > 1 else step


def compile_seconds(lib, batch: int) -> float:
    import jax

    fn, args = build(lib, batch), inputs(lib, batch)
    jax.clear_caches()
    t0 = time.perf_counter()
    jax.jit(fn).lower(*args).compile()
    return time.perf_counter() - t0


def run_seconds(lib, batch: int) -> float:
    import jax

    fn, args = build(lib, batch), inputs(lib, batch)
    compiled = jax.jit(fn).lower(*args).compile()
    calls = C.calibrate(compiled, args, 0.2)
    return statistics.median(C.run_n(compiled, args, calls) for _ in range(5))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--repeats", type=int, default=3)
    C.add_save_arguments(p)
    args = p.parse_args(argv)
    import jaxlie

    import jaxlie_geo

    libs = {"jaxlie_geo": jaxlie_geo, "jaxlie": jaxlie}
    rows = []
    for batch in SIZES:
        best = {name: [float("inf"), float("inf")] for name in libs}
        for r in range(args.repeats):
            for name in list(libs) if r % 2 == 0 else list(libs)[::-1]:
                lib = libs[name]
                best[name][0] = min(best[name][0], compile_seconds(lib, batch))
                best[name][1] = min(best[name][1], run_seconds(lib, batch))
        row = {
            "batch": batch,
            "compile_ours_s": best["jaxlie_geo"][0],
            "compile_jaxlie_s": best["jaxlie"][0],
            "run_ours_s": best["jaxlie_geo"][1],
            "run_jaxlie_s": best["jaxlie"][1],
        }
        rows.append(row)
        print(
            f"B={batch:5d}  compile ours {row['compile_ours_s']:.2f} s  jaxlie "
            f"{row['compile_jaxlie_s']:.2f} s  run ours {C.fmt_ns(row['run_ours_s'] * 1e9)}  "
            f"jaxlie {C.fmt_ns(row['run_jaxlie_s'] * 1e9)}",
            flush=True,
        )
    from benchmarks.report import save

    info = C.machine_info(
        "benchmarks.ik_program", dtype="float32", jaxlie=C.version_of("jaxlie"), joints=JOINTS
    )
    save("ik-program", {"machine": info, "results": rows}, args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
