"""How one measurement runs: timed repeats of a call (:func:`timed`) and, for the large sizes, a child
process with memory and time limits (:func:`guarded`), so that a failure there is recorded, not fatal."""

from __future__ import annotations

import gc
import importlib
import json
import math
import os
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from .config import REPEAT_BUDGET_S


def timed(fn: Callable[[], Any], repeats: int) -> tuple[Any, float, int]:
    """Warm up once, then time up to ``repeats`` calls; returns (warm-up result, min time, timed calls)."""
    ((result, best),), count = timed_together((fn,), repeats)
    return result, best, count


def timed_together(fns: tuple[Callable[[], Any], ...], repeats: int,
                   budget_s: float | None = None, warmed: list | None = None) -> tuple[list[tuple[Any, float]], int]:
    """Warm up each of ``fns`` once, then time up to ``repeats`` rounds, each round calling every function once
    in turn, and no new round once their total passes ``budget_s`` (default ``REPEAT_BUDGET_S`` per function);
    returns ([(warm-up result, min time) per function], rounds). ``warmed``: the warm-up results, when the
    caller has already made that call of each function (to see which ones fail).

    Interleaved rounds make a ratio of two timings fair on a shared machine: a slow spell (another job, a
    frequency change) lasting seconds hits both sides of the ratio, where timing one side after the other
    puts it in one of them (we saw the same code at 0.33 and 0.63 µs a step a minute apart).
    """
    results = [fn() for fn in fns] if warmed is None else list(warmed)
    best = [math.inf] * len(fns)
    count, total = 0, 0.0
    enabled = gc.isenabled()
    # As timeit: one collection before, none during the repeats. (A gc.collect() before every call
    # walks every live object and leaves the CPU caches cold: ~0.4 ms added to each call of either
    # library, which swamps short runs.)
    gc.collect()
    gc.disable()
    try:
        budget = REPEAT_BUDGET_S * len(fns) if budget_s is None else budget_s
        while count < repeats and (count == 0 or total < budget):
            for i, fn in enumerate(fns):
                start = time.perf_counter()
                fn()
                dt = time.perf_counter() - start
                best[i], total = min(best[i], dt), total + dt
            count += 1
    finally:
        if enabled:
            gc.enable()
    return list(zip(results, best, strict=True)), count


def affordable_steps(run: Callable[[int], Any], wanted: int, budget_s: float, minimum: int = 2) -> int:
    """At most ``wanted`` steps, fewer if one call ``run(steps)`` would take longer than about ``budget_s``.

    Probes ``run(k)`` for k = ``minimum``, 8 ``minimum``, … until a call takes a tenth of the budget (the
    first call may compile or fill caches and is not counted), then extrapolates: the fixed cost of a
    call is then small against its steps, so a fast path is not cut short by its call overhead. Keeps a
    slow path (numpy stepping each trajectory of a large batch in Python) from turning one measurement
    into minutes.
    """
    k = min(minimum, wanted)
    run(k)
    while True:
        start = time.perf_counter()
        run(k)
        dt = time.perf_counter() - start
        if k >= wanted:
            return wanted
        if dt >= 0.1 * budget_s:
            break
        k = min(wanted, 8 * k)
    return int(min(wanted, max(minimum, budget_s * k / max(dt, 1e-12))))


#: Sizes measured in a child process with memory and time limits (a failure there is recorded, not fatal).
ISOLATE_N, ISOLATE_BATCH = 64, 10_000


def _memory_budget() -> int:
    """Bytes of address space a child measurement may add: half the available memory, at most 8 GiB."""
    avail = 4 << 30
    try:
        with open("/proc/meminfo", encoding="utf-8") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    avail = int(line.split()[1]) * 1024
                    break
    except (OSError, ValueError):
        pass
    return int(min(avail // 2, 8 << 30))


def child_env(**extra: str) -> dict:
    """The environment of a child process: this one's, with ``extra`` set and this liesuslov importable.

    The child must import the same liesuslov, also when it runs from a source tree that is not installed.
    """
    env = dict(os.environ)
    root = str(Path(__file__).resolve().parents[2])
    env["PYTHONPATH"] = root + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    env.update(extra)
    return env


def _resolve(spec: str) -> Callable[..., dict]:
    """The measurement function named ``"module:function"``."""
    module, name = spec.split(":")
    return getattr(importlib.import_module(module), name)


def guarded(fn: Callable[..., dict], kwargs: dict, *, isolate: bool, timeout: float) -> dict:
    """Run the measurement ``fn(**kwargs)``; in a child process with memory and time limits when ``isolate``.

    ``fn`` must be a module-level function (the child imports it by name) taking and returning JSON data.
    Any failure (out of memory, time limit, an exception) comes back as ``status = "failed"`` with the reason.
    """
    if not isolate:
        try:
            return fn(**kwargs)
        except (MemoryError, ValueError, RuntimeError, np.linalg.LinAlgError) as exc:
            return {"status": "failed", "message": f"{type(exc).__name__}: {exc}"}
    env = child_env()
    payload = json.dumps({"fn": f"{fn.__module__}:{fn.__name__}", "kwargs": kwargs, "budget": _memory_budget()})
    try:
        res = subprocess.run([sys.executable, "-c", f"from {__name__} import child_main; child_main()"],
                             input=payload, capture_output=True, text=True, timeout=timeout, env=env, check=False)
    except subprocess.TimeoutExpired:
        return {"status": "failed", "message": f"time limit: not done in {timeout:.0f} s"}
    lines = [ln for ln in res.stdout.splitlines() if ln.startswith("{")]
    if res.returncode == 0 and lines:
        return json.loads(lines[-1])
    err = (res.stderr.strip().splitlines() or [f"exit status {res.returncode}"])[-1]
    return {"status": "failed", "message": f"child process: {err}"[:300]}


def child_main() -> None:
    """Entry point of an isolated measurement: JSON in on stdin, one JSON row out on stdout."""
    job = json.loads(sys.stdin.read())
    try:
        import resource

        with open("/proc/self/status", encoding="utf-8") as fh:
            vm = next(int(ln.split()[1]) * 1024 for ln in fh if ln.startswith("VmSize:"))
        hard = resource.getrlimit(resource.RLIMIT_AS)[1]
        limit = vm + int(job["budget"])
        if hard != resource.RLIM_INFINITY:
            limit = min(limit, hard)
        resource.setrlimit(resource.RLIMIT_AS, (limit, hard))
    except (ImportError, OSError, ValueError, StopIteration):  # pragma: no cover - not Linux
        pass
    try:
        row = _resolve(job["fn"])(**job["kwargs"])
    except MemoryError:
        row = {"status": "failed", "message": f"out of memory (limit {job['budget'] / 2**30:.1f} GiB)"}
    except (ValueError, RuntimeError, np.linalg.LinAlgError) as exc:
        row = {"status": "failed", "message": f"{type(exc).__name__}: {exc}"}
    print(json.dumps(row, default=float))
