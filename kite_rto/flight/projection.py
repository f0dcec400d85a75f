"""Projection of one periodic lap onto the figure-eight family: the controlled variables y = (theta_0, A_phi, A_theta).

The family (SPEC §3) is ``theta(s) = theta_0 + A_theta sin(2 s)``, ``phi(s) = A_phi sin(s)``. For N samples of
one lap taken uniformly in the lap's phase (uniform in time over one period for a flown or simulated lap):

* ``theta_0`` is the mean of theta;
* phi's first harmonic ``phi ~ a1 cos(w t) + b1 sin(w t) = A_phi sin(w t + s0)`` gives ``A_phi = sqrt(a1^2 + b1^2)``
  and the phase ``s0`` (``A_phi cos s0 = b1``, ``A_phi sin s0 = a1``);
* ``A_theta`` is theta's second harmonic along ``sin(2 (w t + s0))``:
  ``A_theta = B_s cos(2 s0) + B_c sin(2 s0)`` with ``cos 2s0 = (b1^2 - a1^2)/A_phi^2``, ``sin 2s0 = 2 a1 b1 / A_phi^2``.

Every step is smooth in the samples (for A_phi > 0) and independent of where the lap starts, so the optimizer
uses the same formula symbolically (CasADi) as its controlled variables y(u). A lap sampled uniformly in the
path parameter s projects back exactly onto its setpoints; a kite flying the path at varying speed is sampled
non-uniformly in s, which shows up as a small bias that the optimizer's modifiers absorb.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

__all__ = ["project_samples"]


def project_samples(theta, phi):
    """Setpoints ``(theta_0, A_phi, A_theta)`` (rad) of one lap sampled uniformly over its period.

    Args:
        theta, phi: N samples each (rad), N >= 5, either NumPy arrays (returns a NumPy array, shape (3,)) or
            CasADi column vectors (returns a symbolic 3-vector). The samples cover exactly one period and do
            not repeat the first sample at the end.
    """
    symbolic = isinstance(theta, (ca.SX, ca.MX)) or isinstance(phi, (ca.SX, ca.MX))
    if not symbolic:
        theta = np.asarray(theta, dtype=float).ravel()
        phi = np.asarray(phi, dtype=float).ravel()
        if theta.shape != phi.shape or theta.size < 5:
            raise ValueError(f"project_samples: theta and phi need the same length >= 5, got {theta.size} and {phi.size}")
    n = theta.shape[0]
    wt = 2 * np.pi * np.arange(n) / n
    s1, c1, s2, c2 = np.sin(wt), np.cos(wt), np.sin(2 * wt), np.cos(2 * wt)
    if symbolic:
        dot = lambda a, b: ca.dot(ca.DM(a), b)  # noqa: E731
        sqrt = ca.sqrt
    else:
        dot, sqrt = np.dot, np.sqrt
    theta_0 = dot(np.ones(n), theta) / n
    a1, b1 = 2 * dot(c1, phi) / n, 2 * dot(s1, phi) / n
    b_s, b_c = 2 * dot(s2, theta) / n, 2 * dot(c2, theta) / n
    amp2 = a1**2 + b1**2
    a_phi = sqrt(amp2)
    a_theta = (b_s * (b1**2 - a1**2) + b_c * 2 * a1 * b1) / amp2
    if symbolic:
        return ca.vertcat(theta_0, a_phi, a_theta)
    return np.array([theta_0, a_phi, a_theta])
