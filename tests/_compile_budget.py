"""The suite's compile budget: a pytest plugin that counts the XLA programs the tests compile.

Compiling is almost all of this suite's time, so the number of programs is what keeps it
fast. Every program that JAX hands to the XLA backend (compiled anew or read from the
persistent cache) is one ``/jax/core/compile/backend_compile_duration`` event; the plugin
attributes each event to the test that was running, sums them per worker and reports, at the
end of the run:

* the total number of programs and their compile time, the peak resident memory and the peak
  number of memory mappings of a worker;
* the ten test modules and the ten tests with the most compile time;

and writes every test's programs and compile seconds to ``out/compile-report.json`` (the
place to look before making a test cheaper).

Each suite has its budget (``BUDGETS``): the fast suite (``-m "not slow"``, ``make test``)
and the full one (every test, ``make test-full``). A whole run of either fails when it
compiles more programs than its budget; ``JAXLIE_GEO_TEST_PROGRAM_BUDGET`` sets another
limit, enforced on any run. The budget counts programs, not seconds: the count is the same
from one run to the next, where the same programs compile up to 1.4x slower on a shared
machine. It counts the programs of the pytest processes; the subprocesses (examples,
notebooks, the multi-device run) compile their own and are bounded by their wall time
instead. Without the variable it applies to whole runs only: a run of selected tests
(``-k``, a file, ``--lf``, another ``-m``) reports but never fails on it.
"""

from __future__ import annotations

import gc
import json
import os
import resource
import time
from collections import defaultdict
from pathlib import Path
from typing import Any, Dict, List, Tuple

import _suites
import jax
import pytest

FAST_BUDGET = 5500  # fresh-clone make test runs compiled 5,287 to 5,367 (least_squares included)
FULL_BUDGET = 11000  # a fresh-clone make test-full compiled 10,118 before least_squares
BUDGETS = {"fast": FAST_BUDGET, "full": FULL_BUDGET}
"""Programs each whole suite may compile, a little above what it needs."""

_EVENT = "/jax/core/compile/backend_compile_duration"


def memory_map_count() -> int:
    """The number of memory mappings of this process (0 where /proc is absent)."""
    try:
        with open("/proc/self/maps", "rb") as f:
            return f.read().count(b"\n")
    except OSError:
        return 0


def _memory_map_limit() -> int:
    try:
        with open("/proc/sys/vm/max_map_count") as f:
            return int(f.read())
    except (OSError, ValueError):
        return 65530  # Linux's default


MAP_BUDGET = _memory_map_limit() // 2
"""Past this many memory mappings a process frees its compiled programs (``_bounded``)."""


def _peak_rss_mib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


class _Counter:
    """Compile events per test module of one process."""

    def __init__(self) -> None:
        self.test = "(collection)"
        self.programs: Dict[str, int] = defaultdict(int)
        self.seconds: Dict[str, float] = defaultdict(float)
        self.peak_maps = 0
        self.clears = 0
        self.start = time.perf_counter()

    def listener(self, event: str, duration: float, **_: Any) -> None:
        if event == _EVENT:
            self.programs[self.test] += 1
            self.seconds[self.test] += duration

    def summary(self) -> Dict[str, Any]:
        return {
            "programs": dict(self.programs),
            "seconds": dict(self.seconds),
            "peak_maps": max(self.peak_maps, memory_map_count()),
            "cache_clears": self.clears,
            "peak_rss_mib": _peak_rss_mib(),
            "wall": time.perf_counter() - self.start,
        }


_COUNTER = _Counter()
jax.monitoring.register_event_duration_secs_listener(_COUNTER.listener)


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: Any) -> Any:
    """Attribute compile events to the test; then bound the compiled code's mappings.

    XLA's CPU backend maps the code and data of every compiled program into memory (one
    executable, one read-only and one writable mapping per code object), and ``jax.jit``
    keeps every program alive. A process that compiles thousands of programs nears Linux's
    default ``vm.max_map_count`` of 65,530; past it ``mmap`` fails inside the compiler and
    the process dies (SIGABRT or SIGSEGV in ``backend_compile_and_load``) in whichever test
    compiles next. Past ``MAP_BUDGET`` the caches are cleared (programs compiled again come
    from the persistent cache); the report gives the peak count and how often it cleared."""
    _COUNTER.test = item.nodeid
    yield
    maps = memory_map_count()
    _COUNTER.peak_maps = max(_COUNTER.peak_maps, maps)
    if maps > MAP_BUDGET:
        _COUNTER.clears += 1
        jax.clear_caches()
        gc.collect()


_WORKERS: List[Dict[str, Any]] = []


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    config = session.config
    if hasattr(config, "workerinput"):  # a pytest-xdist worker: hand the counts over
        config.workeroutput["compile_budget"] = _COUNTER.summary()
        return
    workers = _WORKERS or [_COUNTER.summary()]
    total = sum(sum(w["programs"].values()) for w in workers)
    if _whole_run(config) and total > _budget(config):
        session.exitstatus = pytest.ExitCode.TESTS_FAILED


def pytest_testnodedown(node: Any, error: Any) -> None:
    summary = getattr(node, "workeroutput", {}).get("compile_budget")
    if summary is not None:
        _WORKERS.append(summary)


def _budget(config: pytest.Config) -> int:
    if "JAXLIE_GEO_TEST_PROGRAM_BUDGET" in os.environ:
        return int(os.environ["JAXLIE_GEO_TEST_PROGRAM_BUDGET"])
    return BUDGETS.get(_suites.suite(config) or "full", FULL_BUDGET)


def _whole_run(config: pytest.Config) -> bool:
    """Whether the budget applies: a whole suite ran, or the limit was set explicitly."""
    return "JAXLIE_GEO_TEST_PROGRAM_BUDGET" in os.environ or _suites.suite(config) is not None


def _write_report(
    config: pytest.Config, per_test: Dict[str, Tuple[int, float]], workers: List[Dict[str, Any]]
) -> None:
    out = Path(str(config.rootpath)) / "out"
    out.mkdir(exist_ok=True)
    report = {
        "tests": {
            t: {"programs": n, "seconds": round(s, 3)}
            for t, (n, s) in sorted(per_test.items(), key=lambda kv: -kv[1][1])
        },
        "workers": [
            {k: v for k, v in w.items() if k not in ("programs", "seconds")} for w in workers
        ],
    }
    (out / "compile-report.json").write_text(json.dumps(report, indent=1))


def pytest_terminal_summary(terminalreporter: Any, exitstatus: int, config: pytest.Config) -> None:
    if hasattr(config, "workerinput"):
        return
    workers = _WORKERS or [_COUNTER.summary()]
    per_test: Dict[str, Tuple[int, float]] = {}
    per_module: Dict[str, Tuple[int, float]] = {}
    for w in workers:
        for test, n in w["programs"].items():
            secs = w["seconds"][test]
            for table, key in ((per_test, test), (per_module, test.split("::")[0])):
                count, total_secs = table.get(key, (0, 0.0))
                table[key] = (count + n, total_secs + secs)
    _write_report(config, per_test, workers)
    total = sum(n for n, _ in per_module.values())
    seconds = sum(s for _, s in per_module.values())
    tr = terminalreporter
    tr.section("compile budget")
    for title, table in (("modules", per_module), ("tests", per_test)):
        tr.write_line(f"the ten {title} with the most compile time:")
        for name, (n, secs) in sorted(table.items(), key=lambda kv: -kv[1][1])[:10]:
            tr.write_line(f"{secs:8.1f} s {n:6d} programs  {name}")
    budget = _budget(config)
    name = _suites.suite(config)
    tr.write_line(
        f"total: {total} programs, {seconds:.1f} s compiling, budget {budget} programs"
        f"{f' ({name} suite)' if name else ''}; "
        f"per worker: peak RSS {max(w['peak_rss_mib'] for w in workers):.0f} MiB, "
        f"peak memory mappings {max(w['peak_maps'] for w in workers)} "
        f"(caches cleared {sum(w['cache_clears'] for w in workers)} times past {MAP_BUDGET})"
    )
    if total > budget:
        verdict = "fails the run" if _whole_run(config) else "not enforced on a partial run"
        tr.write_line(
            f"the suite compiled {total} programs, more than its budget of {budget}: {verdict}. "
            "Put new checks into the existing per-group programs (tests/README.md), mark a "
            "check slow whose code path a fast check covers, or, if the growth is "
            "deliberate, raise BUDGETS in tests/_compile_budget.py.",
            red=True,
        )
