"""Convergence of the critical depth on the robot-plus-spindle pose of issue 17 (the demo
model's pose x1700_y-100_z600_b40; 3 teeth, Kt 796 MPa, Kn 169 MPa, a/D 0.5, down milling) at
1000, 2000, 5000 and 12,000 rpm: the converged engine (`posedyn.stability.floquet`) with its
resolution fixed at 4 to 64 sub-steps per radian of engagement and as it chooses it, beside
the semi-discretization at 40 and 80 steps (zeroth order, the old default knob) and the
independent time-domain simulation's bracket (tests/independent_milling_sim.py; its numbers,
from a run of 5-13 simulations per speed, are quoted, not recomputed: about 1-2 minutes a speed).

    .venv/bin/python bench/stability_convergence.py [--sdm]     (--sdm adds the SDM columns, slow)
"""

from __future__ import annotations

import argparse
import time

from posedyn.dynamics import ToolTipDynamics
from posedyn.stability import Cut, Discretization, StabilityModel, floquet
from posedyn.table import Mode

TABLE = [
    ("x", 12.5909, 0.0300342, 2.11684e06), ("x", 13.1342, 0.0305178, 9.91928e09), ("x", 1443.92, 0.068509, 3.37558e07), ("x", 5438.87, 0.0109756, 2.89553e07),
    ("y", 12.6066, 0.0298721, 1.70046e07), ("y", 13.1265, 0.030316, 910188.0), ("y", 1479.59, 0.048235, 6.7942e07), ("y", 5418.99, 0.0109107, 2.75146e07),
]
CUT = Cut(teeth=3, kt_pa=796e6, kn_pa=169e6, radial_immersion=0.5, milling="down")
#: Independent time-domain simulation: (stable, unstable) depth in mm, dominant Hz.
SIMULATION = {1000.0: (1.862, 1.874, 5437), 2000.0: (1.5115, 1.5228, 5457), 5000.0: (1.288, 1.294, 5422), 12000.0: (4.607, 4.645, 5553)}


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--sdm", action="store_true", help="also the semi-discretization at 40 and 80 steps (minutes)")
    args = parser.parse_args()
    dyn = ToolTipDynamics.from_modes(x=[Mode(f, z, k) for d, f, z, k in TABLE if d == "x"], y=[Mode(f, z, k) for d, f, z, k in TABLE if d == "y"])
    floquet.critical_depth(dyn, CUT, 2000.0)  # warm-up
    for rpm, (lo, hi, hz) in SIMULATION.items():
        print(f"{rpm:.0f} rpm (independent simulation: {lo:.4g}-{hi:.4g} mm, {hz} Hz)")
        for level in (4.0, 8.0, 16.0, 32.0, 64.0):
            p = floquet.critical_depth(dyn, CUT, rpm, rel_tol=1.0, substeps_per_rad=level, verify=False)
            print(f"  floquet, {level:4.0f} sub-steps/rad (and twice that for the estimate): {p.depth_m * 1e3:.4f} mm, {p.chatter_hz:.1f} Hz, estimate {p.rel_error_estimate:.2%}")
        start = time.perf_counter()
        p = floquet.critical_depth(dyn, CUT, rpm)
        seconds = time.perf_counter() - start
        print(f"  floquet, chosen ({p.substeps_per_rad:g}/rad), verified: {p.depth_m * 1e3:.4f} mm, {p.chatter_hz:.1f} Hz, estimate {p.rel_error_estimate:.2%}, "
              f"converged {p.converged}, {seconds * 1e3:.0f} ms; vs simulation midpoint {p.depth_m * 1e3 / (0.5 * (lo + hi)) - 1:+.2%}")
        if args.sdm:
            for steps in (40, 80):
                start = time.perf_counter()
                r = StabilityModel(dyn, CUT, Discretization(steps)).critical_depths([rpm], rel_tol=1e-4)
                seconds = time.perf_counter() - start
                print(f"  semi-discretization, {steps} steps: {r.depth_m[0] * 1e3:.4f} mm, {r.dominant_chatter_hz[0]:.1f} Hz, {seconds:.1f} s")


if __name__ == "__main__":
    main()
