"""Plots of flown paths on the N-W plane (seed fig. 2.2) and of lap statistics (matplotlib, no display needed)."""
from __future__ import annotations

import math

import numpy as np

__all__ = ["nw_coordinates", "plot_paths"]


def nw_coordinates(theta, phi, r: float, theta_bar: float):
    """Project sphere points (rad) on the N-W plane tangent at (theta_bar, 0): returns (W, N) in m.

    e_W = [0, 1, 0], e_N = [-sin(theta_bar), 0, cos(theta_bar)]; p = r [cos th, sin th sin ph, sin th cos ph].
    """
    theta, phi = np.asarray(theta), np.asarray(phi)
    px, py, pz = r * np.cos(theta), r * np.sin(theta) * np.sin(phi), r * np.sin(theta) * np.cos(phi)
    return py, -math.sin(theta_bar) * px + math.cos(theta_bar) * pz


def plot_paths(filename, flown: list, r: float, theta_bar: float, title: str = "") -> None:
    """Save a figure of flown laps over their references.

    Args:
        flown: list of dicts with ``theta``, ``phi`` arrays (rad) of the flown samples, ``ref`` = (theta, phi)
            arrays of the reference path, and ``label``.
    """
    # Not on import: choosing the Agg backend is a global change that only drawing a file should make.
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 5))
    colors = plt.cm.viridis(np.linspace(0, 1, max(len(flown), 2)))
    for item, col in zip(flown, colors):
        w, n = nw_coordinates(item["theta"], item["phi"], r, theta_bar)
        ax.plot(w, n, color=col, lw=1.0, label=f"flown {item['label']}")
        if item.get("ref") is not None:
            wr, nr = nw_coordinates(*item["ref"], r, theta_bar)
            ax.plot(wr, nr, "--", color=col, lw=1.5, alpha=0.8, label=f"reference {item['label']}")
    ax.set_xlabel("W (m)")
    ax.set_ylabel("N (m)")
    ax.set_aspect("equal")
    ax.grid(alpha=0.3)
    ax.set_title(title or f"flown path on the N-W plane (theta_bar = {math.degrees(theta_bar):.1f} deg)")
    ax.legend(fontsize=7, loc="upper right")
    fig.tight_layout()
    fig.savefig(filename, dpi=110)
    plt.close(fig)
