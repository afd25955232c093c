"""Writes datasets/campaigns/sle_walls.csv: a surface-location-error campaign cut by the
independent geometric simulation (tests/independent_sle_sim.py, written blind to posedyn.sle),
not by posedyn.sle, with two causes hidden that the twin does not know:

- the robot's path runs outside the commanded path by 4 um per m/min of feed (seed 001 Table 2:
  14 um at 4.0 m/min, 32-34 um at 8.0-8.2 m/min): the tool centre is offset away from the wall,
  which also takes that much off the radial depth it really cuts;
- the tool is 6 um smaller in radius than its nominal diameter says (a reground tool): the wall
  stays 6 um further out, and the real radial depth is 6 um less.

Two poses of the seed 003 workspace; at each, 16 down-milled walls (the simulation cuts down
milling) on the x or y face with their own tool (2-4 teeth, 10-16 mm, 40 deg helix), speed,
depths and feed. The structure is the twin's, as the gap baseline predicts it (x and y modes of
the modal table at the pose). The simulation's wall is its CMM-like number (mean of the envelope
over the wall, geometric engagement, regenerative chip): physics the frequency-domain method
leaves out (up to ~9 % on a robot) is in it. CMM noise 1 um + 2 %, seeded.

    .venv/bin/python tests/make_sle_walls.py datasets/campaigns/sle_walls.csv
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent))

import independent_sle_sim as sim  # noqa: E402

from posedyn.gap import Measurements  # noqa: E402
from posedyn.io.measurements import format_measurements  # noqa: E402
from posedyn.io.shipped import SHIPPED_TWIN  # noqa: E402
from service.gap.baseline import Baseline  # noqa: E402

PATH_UM_PER_M_MIN = 4.0
RADIUS_ERROR_UM = -6.0
KT_MPA, KN_MPA, HELIX_DEG = 597.3, 59.8, 40.0  # seed 001 Table 3, section 3
POSES = [dict(pose_id="front", x_mm=1450.0, y_mm=-150.0, z_mm=600.0, beta_deg=-30.0),
         dict(pose_id="back", x_mm=1800.0, y_mm=200.0, z_mm=600.0, beta_deg=40.0)]


def walls(seed: int = 11) -> list[dict]:
    rng = np.random.default_rng(seed)
    rows = []
    for pose in POSES:
        for _ in range(16):
            rows.append(dict(pose, quantity="sle_um", direction=str(rng.choice(["x", "y"])), rpm=float(rng.choice([3000, 4500, 6000, 8000, 10000, 12000])),
                             teeth=float(rng.choice([2, 3, 4])), tool_diameter_mm=float(rng.choice([10.0, 12.7, 16.0])),
                             radial_depth_mm=float(rng.choice([0.5, 1.0, 2.0])), axial_depth_mm=float(rng.choice([1.0, 2.0, 3.0])),
                             feed_per_tooth_mm=float(rng.choice([0.05, 0.1, 0.15, 0.2])), helix_deg=HELIX_DEG, kt_mpa=KT_MPA, kn_mpa=KN_MPA,
                             up_milling=0.0))
    return rows


def measurements(rows: list[dict]) -> Measurements:
    n = len(rows)
    names = [k for k in rows[0] if k not in ("pose_id", "quantity", "direction")]
    return Measurements(np.array([r["quantity"] for r in rows]), np.zeros(n), np.ones(n), np.array([r["pose_id"] for r in rows]),
                        np.array([r["direction"] for r in rows]), np.full(n, np.nan), {k: np.array([r[k] for r in rows], dtype=float) for k in names})


def cut_wall_um(modes: dict, row: dict) -> float:
    """The wall of one row from the geometric simulation, the hidden causes in its geometry."""
    speed_m_min = row["feed_per_tooth_mm"] * row["teeth"] * row["rpm"] / 1000.0
    path_m = PATH_UM_PER_M_MIN * speed_m_min * 1e-6
    radius_m = (row["tool_diameter_mm"] / 2) * 1e-3 + RADIUS_ERROR_UM * 1e-6
    sim.NT, sim.HELIX, sim.KT, sim.KN = int(row["teeth"]), math.radians(row["helix_deg"]), row["kt_mpa"] * 1e6, row["kn_mpa"] * 1e6
    sim.D, sim.R = 2 * radius_m, radius_m
    sim.AE = row["radial_depth_mm"] * 1e-3 + RADIUS_ERROR_UM * 1e-6 - path_m  # what the smaller tool on the offset path really cuts
    sim.machine_modes = lambda machine: modes
    feed_per_rev_m = row["feed_per_tooth_mm"] * 1e-3 * row["teeth"]
    window = math.ceil(2 * (radius_m * math.sin(0.12) + feed_per_rev_m) / feed_per_rev_m) + 6  # revolutions whose wall is read (its envelope needs the margins)
    result = sim.simulate("twin", row["direction"], row["rpm"], row["axial_depth_mm"] * 1e-3, row["feed_per_tooth_mm"] * 1e-3, M=720,
                          T_sim=max(0.8, (window + 20) * 60.0 / row["rpm"]), n_rev_win=window)
    # the simulation measures from the real tool's edge: the wall relative to the commanded one
    # moves out by the radius shortfall and the path offset
    return result["sle_mean_um"] - RADIUS_ERROR_UM + path_m * 1e6


def main(out: Path) -> None:
    rows = walls()
    m = measurements(rows)
    table = Baseline(twin_file=SHIPPED_TWIN).pose_rows(m)
    truth = []
    for i, row in enumerate(rows):
        pose = table[row["pose_id"]]
        modes = {d: [pose[k] for k in sorted(pose) if k[0] == d] for d in ("x", "y")}
        truth.append(cut_wall_um(modes, row))
        print(f"{i + 1}/{len(rows)} {row['pose_id']} {row['direction']} {row['rpm']:.0f} rpm: {truth[-1]:.2f} um", flush=True)
    truth = np.array(truth)
    std = 1.0 + 0.02 * np.abs(truth)
    value = truth + np.random.default_rng(12).standard_normal(len(truth)) * std
    m = Measurements(m.quantity, np.round(value, 3), np.round(std, 3), m.pose_id, m.direction, m.mode, m.conditions)
    out.write_text(format_measurements(m))


if __name__ == "__main__":
    main(Path(sys.argv[1]))
