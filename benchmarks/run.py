"""Run every benchmark script in this folder and print a summary table.

Usage: ``python benchmarks/run.py [--only plant,lockstep] [--skip ocp] [--timeout 3600]``

Each ``benchmarks/bench_*.py`` runs as its own subprocess (``python benchmarks/bench_X.py``, same interpreter)
so that one benchmark's imports, threads or DDS participants cannot disturb another; its output is printed as
it finishes. Scripts that print a markdown table ``| benchmark | value | target | met |`` contribute its rows
to the final summary; others contribute one row with their exit code and wall time. The machine's load average
is printed before and after, because wall-clock results on a busy machine are not comparable with a quiet one.
Exit code 1 if a script failed (non-zero exit or timeout), else 0.
"""
from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
_ROW = re.compile(r"^\|(.+)\|\s*$")


def find_scripts(only=None, skip=None) -> list[Path]:
    scripts = sorted(HERE.glob("bench_*.py"))
    first = ["bench_plant.py", "bench_lockstep.py"]            # the quick ones first
    scripts.sort(key=lambda p: (first.index(p.name) if p.name in first else len(first), p.name))

    def key(p: Path) -> str:
        return p.stem.removeprefix("bench_")
    if only:
        scripts = [p for p in scripts if key(p) in only or p.stem in only]
    if skip:
        scripts = [p for p in scripts if key(p) not in skip and p.stem not in skip]
    return scripts


def parse_table(text: str) -> list[list[str]]:
    """Rows of the first markdown table whose header is ``benchmark | value | target | met``."""
    rows, inside = [], False
    for line in text.splitlines():
        m = _ROW.match(line.strip())
        if not m:
            if inside and rows:
                break
            continue
        cells = [c.strip() for c in m.group(1).split("|")]
        if [c.lower() for c in cells[:4]] == ["benchmark", "value", "target", "met"]:
            inside = True
            continue
        if inside and set("".join(cells)) <= set("-: "):
            continue
        if inside:
            rows.append((cells + ["", "", "", ""])[:4])
    return rows


def run_script(path: Path, timeout: float) -> dict:
    env = dict(os.environ)
    env.setdefault("PYTHONUNBUFFERED", "1")
    root = str(HERE.parent)
    env["PYTHONPATH"] = root + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    t0 = time.perf_counter()
    try:
        res = subprocess.run([sys.executable, str(path)], cwd=root, env=env, capture_output=True, text=True,
                             timeout=timeout)
        code, out, err = res.returncode, res.stdout, res.stderr
    except subprocess.TimeoutExpired as exc:
        code = None
        out = exc.stdout.decode() if isinstance(exc.stdout, bytes) else (exc.stdout or "")
        err = (exc.stderr.decode() if isinstance(exc.stderr, bytes) else (exc.stderr or "")) + \
            f"\n[run.py] timed out after {timeout:g} s"
    return {"code": code, "out": out, "err": err, "wall": time.perf_counter() - t0}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default="", help="comma-separated names (plant, lockstep, ocp, tracking, ...)")
    ap.add_argument("--skip", default="", help="comma-separated names to leave out")
    ap.add_argument("--timeout", type=float, default=3600.0, help="wall seconds per script")
    args = ap.parse_args(argv)
    only = {s.strip() for s in args.only.split(",") if s.strip()}
    skip = {s.strip() for s in args.skip.split(",") if s.strip()}
    scripts = find_scripts(only, skip)
    load0 = os.getloadavg()
    print(f"benchmarks/run.py: {len(scripts)} script(s) with {sys.executable}; "
          f"load average {load0[0]:.1f} {load0[1]:.1f} {load0[2]:.1f} on {os.cpu_count()} cores", flush=True)
    summary, failed = [], 0
    for path in scripts:
        print(f"\n===== {path.name} =====", flush=True)
        r = run_script(path, args.timeout)
        print(r["out"].rstrip())
        if r["err"].strip():
            print(r["err"].rstrip()[-3000:], file=sys.stderr)
        ok = r["code"] == 0
        failed += not ok
        status = "ok" if ok else ("timeout" if r["code"] is None else f"exit {r['code']}")
        print(f"----- {path.name}: {status}, {r['wall']:.1f} s wall", flush=True)
        rows = parse_table(r["out"])
        if rows:
            summary += [[path.stem] + row for row in rows]
        if not rows or not ok:
            summary.append([path.stem, f"script finished ({status})", f"{r['wall']:.1f} s wall", "exit 0",
                            "yes" if ok else "NO"])
    load1 = os.getloadavg()
    print(f"\n===== summary (load average before {load0[0]:.1f}, after {load1[0]:.1f}; {os.cpu_count()} cores) "
          "=====")
    print("| script | benchmark | value | target | met |")
    print("|---|---|---|---|---|")
    for row in summary:
        print("| " + " | ".join(row) + " |")
    unmet = sum(1 for row in summary if row[4].strip().upper() == "NO")
    print(f"\n{len(scripts)} script(s), {failed} failed, {unmet} row(s) not meeting target")
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main())
