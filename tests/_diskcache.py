"""Reference values computed once per machine: a disk cache for the slow mpmath references.

``@disk_cached`` stores a function's result in ``out/test-cache`` (``make clean`` removes it),
under a key made of the source of the function's module and of ``benchmarks/mpref.py``, the
function's name and the ``repr`` of its arguments, so any edit to the references computes them
again.
The pytest-xdist workers share it: the first to need a result computes it while holding a
lock on its file, the others wait for it and read it.
"""

from __future__ import annotations

import fcntl
import functools
import hashlib
import inspect
import os
import pickle
from pathlib import Path
from typing import Any, Callable, TypeVar

_DIR = Path(__file__).resolve().parents[1] / "out" / "test-cache"
_SHARED = Path(__file__).parents[1] / "benchmarks" / "mpref.py"

F = TypeVar("F", bound=Callable[..., Any])


def disk_cached(fn: F) -> F:
    """``fn`` with its results kept on disk (and in memory) by argument ``repr``."""
    module = inspect.getmodule(fn)
    source = Path(inspect.getfile(fn)).read_bytes() + _SHARED.read_bytes()
    version = hashlib.sha256(source).hexdigest()[:16]
    name = f"{getattr(module, '__name__', 'module')}.{fn.__qualname__}"

    @functools.lru_cache(maxsize=None)
    def cached(*args: Any) -> Any:
        key = hashlib.sha256(f"{name}|{version}|{args!r}".encode()).hexdigest()[:32]
        path = _DIR / f"{key}.pickle"
        _DIR.mkdir(parents=True, exist_ok=True)
        with open(path.with_suffix(".lock"), "w") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            try:
                if path.exists():
                    try:
                        return pickle.loads(path.read_bytes())
                    except Exception:  # a truncated file: compute it again
                        pass
                value = fn(*args)
                tmp = path.with_suffix(f".{os.getpid()}.tmp")
                tmp.write_bytes(pickle.dumps(value))
                os.replace(tmp, path)
                return value
            finally:
                fcntl.flock(lock, fcntl.LOCK_UN)

    return functools.wraps(fn)(cached)  # type: ignore[return-value]
