"""Twin benchmarks: modes at one pose and at 10,000 poses (inverse kinematics + CRBA + the
generalized eigenproblem + the tool-tip Jacobian per pose). Prints figures only."""

from __future__ import annotations

import math
import time

import numpy as np

from posedyn.robot.campaign import GridPose, pose_modes
from posedyn.io.twin_file import load_twin
from posedyn.robot import ToolPose


def main() -> None:
    robot, params = load_twin()
    data = robot.model.createData()
    rng = np.random.default_rng(0)
    poses = [
        GridPose("p", ToolPose.from_beta(x, y, 0.6, math.radians(b)))
        for x, y, b in zip(rng.uniform(1.3, 1.9, 10_000), rng.uniform(-0.3, 0.3, 10_000), rng.uniform(-60, 60, 10_000))
    ]
    pose_modes(robot, poses[0], params, data=data)  # warm-up
    times = []
    for _ in range(200):
        start = time.perf_counter()
        pose_modes(robot, poses[1], params, data=data)
        times.append(time.perf_counter() - start)
    print(f"modes at one pose (IK + M(q) + eigenproblem + Jacobian): {np.median(times) * 1e6:.0f} us median of 200")
    start = time.perf_counter()
    lowest = [pose_modes(robot, p, params, data=data)[1].fn_hz[0] for p in poses]
    elapsed = time.perf_counter() - start
    print(f"modes at 10,000 poses: {elapsed:.2f} s ({elapsed / len(poses) * 1e6:.0f} us per pose), lowest mode {min(lowest):.1f}-{max(lowest):.1f} Hz")


if __name__ == "__main__":
    main()
