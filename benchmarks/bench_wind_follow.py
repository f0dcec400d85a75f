"""The figure-eight after a turn of the mean wind: how fast the path follows the vane, and the energy it keeps.

The plant's field with all three components (``components="uvw"``) and IEC 61400-1's extreme direction change
(about 29 deg for the default plant) at ``--turn`` s; the controller's path follows the filtered, rate-limited vane
(``ControllerSettings.follow_wind``, its defaults). Per seed and box (the default 16 km box and a 4 km one, which
repeats every 4.7 min), three closed loops over the same wind: following the vane, a reference that knows the true
mean direction (the same controller handed the true direction), and the path left at the old azimuth.

Measured: the time after the turn's end until the path's direction is first within 5 deg of the new mean direction,
the rms error of the path's direction after the turn, and the energy (time integral of the measured tension) of the
``--window`` s after the turn as a percentage of the reference's. Targets: re-centred within 60 s, energy of
the following 10 minutes >= 97 %.

Usage: ``python benchmarks/bench_wind_follow.py [--seeds 2,3,4,5] [--turn 100] [--window 600]``. Prints a markdown
table; ``main()`` returns its rows.
"""
from __future__ import annotations

import argparse
import math
from dataclasses import replace

import numpy as np

from kite_rto.flight.wind_follow import WindFollowSettings
from kite_rto.kite.mean_wind import EDC_DURATION, MeanWindSettings
from kite_rto.kite.plant import PlantConfig
from kite_rto.kite.wind_field import WindFieldSettings
from kite_rto.testing.wind_turn import fly_following

from _table import print_table

BOXES = {"16 km (default)": (2048, 32, 32), "4 km": (512, 32, 32)}


def main(argv=None) -> list:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", default="2,3,4,5", help="plant seeds, comma-separated")
    ap.add_argument("--turn", type=float, default=100.0, help="start of the direction change, s")
    ap.add_argument("--window", type=float, default=600.0, help="energy window after the turn's end, s")
    args = ap.parse_args(argv)
    seeds = [int(s) for s in args.seeds.split(",")]
    end = args.turn + EDC_DURATION
    rows = []
    for box, points in BOXES.items():
        for seed in seeds:
            config = replace(PlantConfig(), wind_field=WindFieldSettings(points=points, components="uvw"),
                             mean_wind=MeanWindSettings(edc_time=args.turn))
            (t, tension, direction, _), plant = fly_following(config, WindFollowSettings(enabled=True), seed,
                                                              end + args.window)
            (_, best, _, _), _ = fly_following(config, WindFollowSettings(enabled=True, filter_time=1e-9,
                                                                          rate_limit=100.0),
                                               seed, end + args.window, true_vane=True)
            (_, fixed, _, _), _ = fly_following(config, WindFollowSettings(enabled=False), seed, end + args.window)
            new = plant.wind.mean.direction
            after = t > end
            close = t[after & (np.abs(direction - new) < math.radians(5.0))]
            recentred = close[0] - end if close.size else math.inf
            energy = 100 * tension[after].sum() / best[after].sum()
            case = f"{box} box, seed {seed}, turn {math.degrees(new):.1f} deg"
            rows += [(f"{case}: re-centred (within 5 deg) after, s", f"{recentred:.1f}", "<= 60",
                      "yes" if recentred <= 60.0 else "NO"),
                     (f"{case}: energy of {args.window:g} s, % of the true direction's", f"{energy:.2f}", ">= 97",
                      "yes" if energy >= 97.0 else "NO"),
                     (f"{case}: path direction rms error after the turn, deg",
                      f"{math.degrees(math.sqrt(np.mean((direction[after] - new) ** 2))):.1f}", "", ""),
                     (f"{case}: path left at 0 deg, energy %", f"{100 * fixed[after].sum() / best[after].sum():.2f}",
                      "", "")]
            print(f"{case}: re-centred {recentred:.1f} s, energy {energy:.2f} %", flush=True)
    print_table(rows)
    return rows


if __name__ == "__main__":
    main()
