"""Benchmark the kite lap OCP: build, cold and warm IPOPT solves (times in s, wall clock).

Run: ``python benchmarks/bench_ocp.py [--repeats 10]``. Rows:

* build: ``model_problem`` (symbolic graph) and the first ``nlpsol`` (derivative generation);
* cold: model optimum from ``u0``; realization of an interior setpoint from its figure-eight guess;
* optimizer start-up: DMA's privileged directions (one realization NLP per uncertain parameter, with the
  shape-box model optimum) and then :func:`make_gma` (GMA's NLPs), once each, cold;
* warm: median over ``repeats`` re-solves after a small change (setpoints moved ~0.5 deg; or the model
  optimum with small random GMA modifiers ``lambda^T (y - c_k)``, ``eps + mu^T (y - c_k)``, which is the
  problem the GMA optimizer solves each iteration), each warm-started from the unmodified solution.
"""
from __future__ import annotations

import argparse
import math
import time

import casadi as ca
import numpy as np

from kite_rto.rto.ocp import model_problem
from kite_rto.rto.ocp_solve import realize_setpoints, solve_model_optimum
from kite_rto.rto.settings import KiteRTOSettings
from kite_rto.rto.builder import gma_directions, make_gma

DEG = math.pi / 180.0
WARM = {"print_level": 0, "sb": "yes", "tol": 1e-8, "warm_start_init_point": "yes", "mu_init": 1e-4}


def _modified_solver(pr):
    """GMA's modified model problem with the modifiers as parameters p = (c_k, lambda, eps, mu)."""
    c_k, lam, mu, eps = ca.SX.sym("c", 3), ca.SX.sym("lam", 3), ca.SX.sym("mu", 3), ca.SX.sym("eps")
    g = ca.vertcat(pr.equalities, pr.constraints + eps + ca.dot(mu, pr.outputs - c_k), pr.outputs)
    nlp = {"x": pr.u, "p": ca.vertcat(c_k, lam, mu, eps), "f": pr.cost + ca.dot(lam, pr.outputs - c_k), "g": g}
    n_eq = pr.equalities.numel()
    lbg = np.concatenate([np.zeros(n_eq), [-np.inf], pr.c_lb])
    ubg = np.concatenate([np.zeros(n_eq), [0.0], pr.c_ub])
    return ca.nlpsol("gma_modified", "ipopt", nlp, {"ipopt": WARM, "print_time": False}), lbg, ubg


def main(repeats: int = 10):
    rows = []
    t0 = time.perf_counter()
    pr = model_problem()
    rows.append(("build ModelProblem (symbolic)", time.perf_counter() - t0, "", ""))
    t0 = time.perf_counter()
    opt = solve_model_optimum(pr)
    rows.append(("cold model optimum incl. nlpsol build", time.perf_counter() - t0, opt.iterations, ""))
    opt = solve_model_optimum(pr)
    rows.append(("cold model optimum (IPOPT only)", opt.solve_time, opt.iterations, ""))
    c_int = np.array([28.0, 30.0, 7.0]) * DEG
    base = realize_setpoints(pr, c_int)
    base = realize_setpoints(pr, c_int)
    rows.append(("cold realize c=(28,30,7) deg (IPOPT only)", base.solve_time, base.iterations, ""))
    rng = np.random.default_rng(0)
    for label, ref in (("interior", base), ("model optimum", opt)):
        sols = [realize_setpoints(pr, ref.c + rng.normal(0.0, 0.5, 3) * DEG, warm=ref) for _ in range(repeats)]
        rows.append((f"warm realize, c moved ~0.5 deg ({label})", np.median([s.solve_time for s in sols]),
                     int(np.median([s.iterations for s in sols])), f"max {max(s.solve_time for s in sols):.3f}"))
    solver, lbg, ubg = _modified_solver(pr)
    times, iters, ok = [], [], 0
    lam_g0 = np.concatenate([opt.lam_g[:pr.equalities.numel() + 1], opt.lam_g[-3:]])
    for _ in range(repeats):
        p = np.concatenate([opt.c, rng.normal(0, 20.0, 3), rng.normal(0, 20.0, 3), [rng.normal(0, 2.0)]])
        t0 = time.perf_counter()
        solver(x0=opt.u, lam_x0=opt.lam_x, lam_g0=lam_g0, p=p, lbx=pr.lbu, ubx=pr.ubu, lbg=lbg, ubg=ubg)
        times.append(time.perf_counter() - t0)
        iters.append(solver.stats()["iter_count"])
        ok += bool(solver.stats()["success"])
    rows.append(("warm GMA-modified optimum (|lam|,|mu|~20 kN/rad)", float(np.median(times)), int(np.median(iters)),
                 f"{ok}/{repeats} ok"))

    settings = KiteRTOSettings()
    t0 = time.perf_counter()
    d = gma_directions(settings)
    rows.append(("start-up: DMA privileged directions (cold)", time.perf_counter() - t0, "",
                 f"{len(settings.uncertainty.names())} parameters, {d.directions.shape[1]} directions"))
    t0 = time.perf_counter()
    make_gma(settings)
    rows.append(("start-up: make_gma after that (GMA's NLPs)", time.perf_counter() - t0, "", ""))

    print(f"kite lap OCP: N = {pr.settings.n_intervals}, substeps = {pr.settings.substeps}, n_u = {pr.n_u}")
    print(f"model optimum: c = {np.round(opt.c / DEG, 2)} deg, mean tension {opt.mean_tension_kn:.1f} kN, "
          f"min altitude {opt.min_altitude:.1f} m, period {opt.period:.2f} s")
    print(f"{'case':52s} {'time s':>8s} {'iter':>5s}  note")
    for name, t, it, note in rows:
        print(f"{name:52s} {t:8.3f} {it!s:>5s}  {note}")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=10)
    main(parser.parse_args().repeats)
