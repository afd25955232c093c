"""GP benchmarks (issues: pose -> modal-parameter GPs; 22, pose model speed). Prints figures and
ratios measured in this run; asserts nothing.

  - training time on the shipped 112-pose campaign for stgp, mtgp and physics, beside
    scikit-learn's plain GaussianProcessRegressor (anisotropic RBF + white noise, one per
    target) on the same data, and the time of one 3-task MTGP group (seed 003: 3.36 s in MATLAB).
    Targets (issue 22): one group < 1 s; the whole mtgp model <= 2 x stgp
  - prediction time for 10,000 poses with std beside scikit-learn's per-target GPRs (target:
    ratio >= 1, ours no slower), and for one pose (the service's case; target < 2 ms)
  - the learning curve: mean relative error on the lowest mode's fn (x1.fn_hz) against the
    number of training poses, for an as-built robot that differs from the nominal twin
    (joint stiffnesses +-30 %, 65 kg payload, an 8 kg device on the spindle housing)

Usage: python bench/gpr.py [--quick]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from sklearn.gaussian_process import GaussianProcessRegressor
from sklearn.gaussian_process.kernels import RBF, ConstantKernel, WhiteKernel

from posedyn.io.shipped import DATASETS
from posedyn.robot.campaign import Noise, generate_campaign
from posedyn.robot.twin_effects import DeviceMass
from posedyn.posemodel import fit_gps
from posedyn.posemodel import PoseModel, feature_matrix, select_features, table_targets
from posedyn.io import read_modal_table
from posedyn.io.grid import read_grid
from posedyn.io.twin_file import load_twin
from posedyn.table import PoseSet


def timed(fn):
    start = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--quick", action="store_true", help="fewer learning-curve points")
    args = parser.parse_args()
    robot, params = load_twin()
    table = read_modal_table(DATASETS / "campaigns/seed003_twin_s1.csv")
    names, Y = table_targets(table)
    print(f"training on {len(table.poses)} poses, {len(names)} targets")
    models, seconds_fit = {}, {}
    for method in ("stgp", "mtgp", "physics"):
        models[method], seconds_fit[method] = timed(lambda: PoseModel(method, twin=(robot, params)).fit(table))
        print(f"  {method:8s} {seconds_fit[method]:6.2f} s  ({len(models[method].groups_)} GPs)")
    features = select_features(table.poses, None)
    X = feature_matrix(table.poses, features)
    X = (X - X.mean(0)) / X.std(0)
    Z = np.log(Y)
    Z = (Z - Z.mean(0)) / np.where(Z.std(0) > 0, Z.std(0), 1)

    def sklearn_all():
        fitted = []
        for j in range(Z.shape[1]):
            kernel = ConstantKernel(1.0, (1e-6, 1e6)) * RBF(np.ones(X.shape[1]), (0.05, 50.0)) + WhiteKernel(0.01, (1e-6, 10.0))
            fitted.append(GaussianProcessRegressor(kernel, n_restarts_optimizer=1, random_state=0).fit(X, Z[:, j]))
        return fitted

    sklearn_models, seconds_sklearn = timed(sklearn_all)
    print(f"  sklearn GaussianProcessRegressor, one per target, 1 restart: {seconds_sklearn:6.2f} s  (sklearn / stgp = {seconds_sklearn / seconds_fit['stgp']:.1f}x)")
    group = [names.index(t) for t in ("x1.fn_hz", "y1.fn_hz", "z1.fn_hz")]
    _, seconds_group = timed(lambda: fit_gps(X, [Z[:, group]], restarts=0))
    print(f"  one 3-task MTGP group (x1/y1/z1 fn), no restart: {seconds_group:.2f} s  target < 1 s (seed 003: 3.36 s in MATLAB)")
    print(f"  whole mtgp model / stgp: {seconds_fit['mtgp'] / seconds_fit['stgp']:.2f}x  target <= 2x")

    rng = np.random.default_rng(0)
    n = 10_000
    poses = PoseSet(
        pose_id=tuple(f"p{i}" for i in range(n)),
        position_mm=np.column_stack([rng.uniform(1300, 1900, n), rng.uniform(-300, 300, n), np.full(n, 600.0)]),
        orientation="beta",
        orientation_deg=rng.uniform(-60, 60, (n, 1)),
    )
    Xq = (feature_matrix(poses, features) - feature_matrix(table.poses, features).mean(0)) / feature_matrix(table.poses, features).std(0)
    _, seconds_sk = timed(lambda: [sk.predict(Xq, return_std=True) for sk in sklearn_models])
    print(f"  predict 10,000 poses with std, sklearn one GPR per target: {seconds_sk:.2f} s")
    for method in ("stgp", "mtgp"):
        models[method].predict(poses.subset([0]), return_std=True)  # builds the predictor
        _, seconds = timed(lambda: models[method].predict(poses, return_std=True))
        print(f"  predict 10,000 poses with std, {method}: {seconds:.2f} s  (sklearn / {method} = {seconds_sk / seconds:.2f}x, target >= 1)")
    for method in ("stgp", "mtgp", "physics"):
        one = poses.subset([1])
        models[method].predict(one, return_std=True)
        _, seconds = timed(lambda: [models[method].predict(one, return_std=True) for _ in range(200)])
        print(f"  predict one pose with std, {method}: {seconds / 200 * 1e3:.2f} ms  target < 2 ms")
    _, seconds = timed(lambda: models["physics"].predict(poses.__class__(poses.pose_id[:1000], poses.position_mm[:1000], "beta", poses.orientation_deg[:1000]), return_std=True))
    print(f"  predict 1,000 poses with std, physics (inverse kinematics + twin per pose): {seconds:.2f} s")

    print("learning curve: mean relative error on x1.fn_hz at the other poses (as-built robot, seeds 0-2)")
    grid = list(read_grid(DATASETS / "campaigns/seed003_grid.toml").poses)
    built, _ = load_twin(payload_kg=65.0)
    sizes = (5, 10, 20, 40, 80) if args.quick else (5, 10, 15, 20, 30, 40, 60, 80, 100)
    print("  poses   " + "   ".join(f"{m:>8s}" for m in ("stgp", "mtgp", "physics")))
    curves = {m: [] for m in ("stgp", "mtgp", "physics")}
    for size in sizes:
        errors = {m: [] for m in curves}
        for seed in range(3):
            as_built = params.scaled(np.random.default_rng(100 + seed).uniform(0.7, 1.3, 6))
            measured = generate_campaign(built, grid, as_built, Noise(), seed=seed, effects=(DeviceMass(mass_kg=8.0),))
            truth = generate_campaign(built, grid, as_built, Noise(0, 0, 0), seed=seed, effects=(DeviceMass(mass_kg=8.0),))
            order = np.random.default_rng(seed).permutation(len(grid))
            train, test = order[:size], order[size:]
            t_names, true_values = table_targets(truth.select_poses(test))
            for m in curves:
                model = PoseModel(m, twin=(robot, params), random_state=seed).fit(measured.select_poses(train))
                predicted = model.predict(measured.select_poses(test).poses)[:, model.targets_.index("x1.fn_hz")]
                errors[m].append(np.mean(np.abs(predicted / true_values[:, t_names.index("x1.fn_hz")] - 1)))
        print(f"  {size:5d}   " + "   ".join(f"{100 * np.mean(errors[m]):7.2f}%" for m in curves))


if __name__ == "__main__":
    main()
