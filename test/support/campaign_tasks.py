"""Closed-form tasks for the campaign executor's tests (importable by Dask workers: test/support/ is on their path)."""
import os
import time
import uuid


def square(x):
    return {"x": x, "y": x * x}


def total(*parts):
    return sum(p["y"] for p in parts)


def offset(x, base):
    return {"x": x, "z": base + x}


def fail(x):
    raise ValueError(f"fail: x = {x} is refused")


def held(marker_dir, x):
    """Write ``started-<x>-<pid>-<uuid>``, wait for the file ``release`` (at most 120 s), then answer."""
    with open(os.path.join(marker_dir, f"started-{x}-{os.getpid()}-{uuid.uuid4().hex}"), "w"):
        pass
    end = time.monotonic() + 120.0
    while not os.path.exists(os.path.join(marker_dir, "release")):
        if time.monotonic() > end:
            raise TimeoutError("held: no release file within 120 s")
        time.sleep(0.05)
    with open(os.path.join(marker_dir, f"done-{x}-{uuid.uuid4().hex}"), "w"):
        pass
    return {"x": x, "y": x * x}


def closed_form_tasks(n=4):
    """Squares of 0..n-1 (stored), their unstored total, and each x offset by that total (stored)."""
    from kite_rto.campaign.executor import Task
    tasks = [Task(f"sq-{x}", square, (x,)) for x in range(n)]
    tasks.append(Task("total", total, deps=tuple(f"sq-{x}" for x in range(n)), store=False))
    tasks += [Task(f"off-{x}", offset, (x,), deps=("total",)) for x in range(n)]
    return tasks


def expected(n=4):
    base = sum(x * x for x in range(n))
    return {**{f"sq-{x}": {"x": x, "y": x * x} for x in range(n)},
            **{f"off-{x}": {"x": x, "z": base + x} for x in range(n)}}
