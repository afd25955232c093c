"""Pose -> modal-parameter GPs: the GP core against independent formulas and scikit-learn,
seed 004's reproduction, MTGP vs STGP, the physics prior, calibration, persistence, CLI."""

import json
import re
import math

import numpy as np
import pytest
from sklearn.gaussian_process import GaussianProcessRegressor
from sklearn.gaussian_process.kernels import RBF, ConstantKernel, WhiteKernel

from posedyn.posemodel import _gp as gp  # the GP core's likelihoods and gradients, tested directly
from posedyn.robot.campaign import Noise, generate_campaign
from posedyn.robot.twin_effects import DeviceMass
from posedyn.errors import InputError
from posedyn.posemodel import PoseModel, cross_validate, r2_score, table_targets
from posedyn.io import read_modal_table
from posedyn.io.grid import read_grid
from posedyn.io.twin_file import read_twin
from posedyn.io.model_dir import load_model, save_model
from posedyn.robot import Robot
from tests.cli_helpers import run_cli


# --- GP core ------------------------------------------------------------------------------


def test_kronecker_likelihood_gradient_and_prediction_match_dense_formulas():
    rng = np.random.default_rng(0)
    X = rng.uniform(-2, 2, (30, 3))
    Y = np.column_stack([np.sin(X[:, 0]), np.sin(X[:, 0]) + 0.3 * X[:, 1], X[:, 2] ** 2]) + 0.05 * rng.standard_normal((30, 3))
    theta = rng.normal(0, 0.5, 3 + 6 + 3)
    value, grad = gp.nll_kron(theta, X, Y)
    assert value == pytest.approx(gp.nll_dense(theta, X, Y), rel=1e-12)
    numeric = [(gp.nll_kron(theta + h, X, Y)[0] - gp.nll_kron(theta - h, X, Y)[0]) / 2e-6 for h in np.eye(len(theta)) * 1e-6]
    assert np.allclose(grad, numeric, atol=1e-5 * np.abs(grad).max())
    model = gp.GP(theta=theta, X=X, Y=Y)
    Xs = rng.uniform(-2, 2, (4, 3))
    mean, std = model.predict(Xs, return_std=True)
    L = gp.cholesky_factor(theta, 3, 3)
    B = L @ L.T
    K = np.kron(B, gp.rbf(theta, X, X)) + np.kron(np.diag(np.exp(theta[-3:])), np.eye(30))
    Ks = np.kron(B, gp.rbf(theta, Xs, X))
    dense_mean = Ks @ np.linalg.solve(K, Y.T.ravel())
    dense_var = np.kron(np.diag(B), np.ones(4)) - np.sum(Ks * np.linalg.solve(K, Ks.T).T, axis=1)
    assert np.allclose(mean, dense_mean.reshape(3, 4).T, atol=1e-9)
    assert np.allclose(std, np.sqrt(dense_var).reshape(3, 4).T, atol=1e-9)


def _dense_posterior(model, Xs):
    """GP posterior mean and latent std from the dense (nT) x (nT) covariance, built here from the
    fitted GP's public hyperparameters (length scales, task covariance, noise variances) with
    scipy's cdist: no code shared with the predictor."""
    from scipy.spatial.distance import cdist

    l, B, noise = model.length_scales, model.task_covariance, model.noise_variances
    n, T = model.Y.shape
    kx = np.exp(-0.5 * cdist(model.X / l, model.X / l, "sqeuclidean"))
    ks = np.exp(-0.5 * cdist(Xs / l, model.X / l, "sqeuclidean"))
    K = np.kron(B, kx) + np.kron(np.diag(noise), np.eye(n))
    chol = np.linalg.cholesky(K)
    alpha = np.linalg.solve(chol.T, np.linalg.solve(chol, model.Y.T.ravel()))
    mean, std = np.empty((len(Xs), T)), np.empty((len(Xs), T))
    for t in range(T):
        cross = np.kron(B[t][None, :], ks)  # (m, n T): cov(f_t(x*), y)
        mean[:, t] = cross @ alpha
        v = np.linalg.solve(chol, cross.T)
        std[:, t] = np.sqrt(B[t, t] - np.sum(v * v, axis=0))
    return mean, std


def test_fast_prediction_matches_the_dense_posterior_to_1e_9():
    """The stacked predictor (all of a model's GPs at once, issue 22) against the dense posterior,
    for single-task and 3-task GPs with their own length scales, output columns interleaved as a
    model's groups are, at random queries inside and far outside the training inputs."""
    rng = np.random.default_rng(7)
    X = rng.uniform(-2, 2, (40, 3))
    Y = np.column_stack([np.sin(X[:, 0]), np.cos(X[:, 1]) * X[:, 2], X[:, 0] * X[:, 1], np.sin(X[:, 2]) + 0.2 * X[:, 0]])
    Y = Y + 0.05 * rng.standard_normal(Y.shape)
    three = gp.GP(theta=np.concatenate([rng.normal(0, 0.4, 3), rng.normal(0, 0.6, 6), np.log([0.01, 0.02, 0.005])]), X=X, Y=Y[:, [0, 2, 3]])
    one = gp.GP(theta=np.concatenate([rng.normal(0.3, 0.3, 3), [0.2], [np.log(0.01)]]), X=X, Y=Y[:, [1]])
    Xs = np.vstack([rng.uniform(-2.5, 2.5, (300, 3)), rng.uniform(6, 9, (5, 3))])
    predictor = gp.Predictor.of([three, one], [[0, 2, 3], [1]])
    mean, std = predictor.predict(Xs, return_std=True)
    for model, cols in ((three, [0, 2, 3]), (one, [1])):
        dense_mean, dense_std = _dense_posterior(model, Xs)
        scale = np.sqrt(np.mean(dense_mean**2, axis=0))
        assert np.max(np.abs(mean[:, cols] - dense_mean) / scale) < 1e-9
        assert np.max(np.abs(std[:, cols] / dense_std - 1.0)) < 1e-9
        assert np.allclose(model.predict(Xs, return_std=True)[1], dense_std, rtol=1e-9, atol=0)
    assert np.array_equal(predictor.predict(Xs), mean)  # without the std, the same means


def test_predictive_covariance_between_tasks_matches_the_dense_posterior():
    """`Predictor.predict_cov` (issue 23: correlated samples of a pose's modes) against the dense
    posterior covariance cov(f_t(x), f_u(x)) = B_tu - k_t^T K^-1 k_u, built as in
    `_dense_posterior`; zero between GPs; its diagonal is `predict`'s variance."""
    from scipy.spatial.distance import cdist

    rng = np.random.default_rng(3)
    X = rng.uniform(-2, 2, (30, 2))
    Y = np.column_stack([np.sin(X[:, 0]), np.sin(X[:, 0]) + 0.3 * X[:, 1], np.cos(X[:, 1])]) + 0.05 * rng.standard_normal((30, 3))
    two = gp.GP(theta=np.concatenate([[0.1, -0.2], [0.8, 0.6, 0.3], np.log([0.01, 0.02])]), X=X, Y=Y[:, :2])
    one = gp.GP(theta=np.array([0.3, 0.1, 0.0, np.log(0.01)]), X=X, Y=Y[:, [2]])
    predictor = gp.Predictor.of([two, one], [[2, 0], [1]])
    Xs = np.vstack([rng.uniform(-2.5, 2.5, (20, 2)), [[7.0, 8.0]]])
    cov = predictor.predict_cov(Xs)
    _, std = predictor.predict(Xs, return_std=True)
    assert np.allclose(np.sqrt(np.einsum("mtt->mt", cov)), std, rtol=1e-9, atol=1e-12)
    assert np.all(cov[:, 1, [0, 2]] == 0) and np.all(cov[:, [0, 2], 1] == 0)
    l, B, noise = two.length_scales, two.task_covariance, two.noise_variances
    K = np.kron(B, np.exp(-0.5 * cdist(X / l, X / l, "sqeuclidean"))) + np.kron(np.diag(noise), np.eye(len(X)))
    ks = np.exp(-0.5 * cdist(Xs / l, X / l, "sqeuclidean"))
    for i in range(len(Xs)):
        cross = np.stack([np.kron(B[t], ks[i]) for t in range(2)])  # (2, 2 n)
        dense = B - cross @ np.linalg.solve(K, cross.T)
        assert np.allclose(cov[i][np.ix_([2, 0], [2, 0])], dense, rtol=1e-8, atol=1e-10 * B.max())
    assert abs(cov[0, 0, 2]) > 0.1 * np.sqrt(cov[0, 0, 0] * cov[0, 2, 2])  # correlated tasks: the test can fail


def test_leave_one_out_residuals_match_refitting_without_the_pose():
    """`loo_residuals` (closed form from the Kronecker factors) against its definition: the dense
    posterior of a pose's tasks from the other poses (same hyperparameters, np.linalg.solve on the
    dense covariance), residual and predictive std of a measurement, for a 3-task and a 1-task GP."""
    from scipy.spatial.distance import cdist

    rng = np.random.default_rng(5)
    X = rng.uniform(-2, 2, (25, 2))
    Y = np.column_stack([np.sin(X[:, 0]), np.sin(X[:, 0]) + 0.3 * X[:, 1], np.cos(X[:, 1])]) + 0.05 * rng.standard_normal((25, 3))
    for model in (gp.GP(theta=np.concatenate([[0.1, -0.2], [0.8, 0.6, 0.3, -0.4, 0.2, 0.1], np.log([0.01, 0.02, 0.005])]), X=X, Y=Y),
                  gp.GP(theta=np.array([0.3, 0.1, 0.0, np.log(0.01)]), X=X, Y=Y[:, [2]])):
        n, T = model.Y.shape
        l, B, noise = model.length_scales, model.task_covariance, model.noise_variances
        K = np.kron(B, np.exp(-0.5 * cdist(X / l, X / l, "sqeuclidean"))) + np.kron(np.diag(noise), np.eye(n))
        y = model.Y.T.ravel()  # task-major, as K
        residual, std = gp.loo_residuals(model)
        for i in range(n):
            own = np.arange(T) * n + i
            rest = np.setdiff1d(np.arange(n * T), own)
            solved = np.linalg.solve(K[np.ix_(rest, rest)], np.column_stack([y[rest], K[np.ix_(rest, own)]]))
            assert np.allclose(residual[i], y[own] - K[np.ix_(own, rest)] @ solved[:, 0], rtol=1e-8, atol=1e-10)
            assert np.allclose(std[i], np.sqrt(np.diag(K[np.ix_(own, own)] - K[np.ix_(own, rest)] @ solved[:, 1:])), rtol=1e-8)


def test_a_misidentified_mode_is_named_and_a_clean_table_has_no_suspects(datasets, tmp_path):
    """`suspect_measurements`: seed 004's seven published positions give none; the shipped 112-pose
    campaign with one pose's y1 frequency 30 % low (a mode taken for another) names that pose and
    target first, with the true value from the other poses, and `posedyn train` reports it."""
    import dataclasses

    from posedyn.io import write_modal_table
    from posedyn.posemodel import suspect_measurements

    seed004 = read_modal_table(datasets / "seeds/hou2023_positions.csv")
    assert suspect_measurements(PoseModel().fit(seed004), seed004) == []
    table = read_modal_table(datasets / "campaigns/seed003_twin_s1.csv")
    bad_pose = 57
    rows = np.flatnonzero((table.pose_index == bad_pose) & (table.direction == "y") & (table.mode == 1))
    fn = table.fn_hz.copy()
    fn[rows] *= 0.7
    bad = dataclasses.replace(table, fn_hz=fn)
    write_modal_table(bad, tmp_path / "bad.csv")
    result = posedyn("train", tmp_path / "bad.csv", "--cv", 0, "--out", tmp_path / "m", "--json")
    assert result.returncode == 0, result.stderr
    first = json.loads(result.stdout)["suspects"][0]
    assert (first["pose_id"], first["target"]) == (table.poses.pose_id[bad_pose], "y1.fn_hz")
    assert first["z"] < -6 and first["measured"] == pytest.approx(fn[rows[0]])
    assert first["loo_predicted"] == pytest.approx(table.fn_hz[rows[0]], rel=0.02)  # what the other poses say: the true value
    model = load_model(tmp_path / "m")
    assert suspect_measurements(model, read_modal_table(tmp_path / "bad.csv"))[0] == pytest.approx(first)
    with pytest.raises(ValueError):
        suspect_measurements(model, table)  # not the table it was fitted on


def test_fits_on_one_blas_thread_reach_the_same_optimum():
    """`fit_gps` (a thread pool, one BLAS thread per fit) finds the optimum `fit_gp` finds with
    the default BLAS threads, to 1e-6 in the log likelihood."""
    rng = np.random.default_rng(3)
    X = rng.uniform(-2, 2, (60, 3))
    Y = np.column_stack([np.sin(X[:, 0]) + 0.4 * X[:, 1], np.sin(X[:, 0]) - 0.3 * X[:, 2], np.cos(X[:, 1])]) + 0.05 * rng.standard_normal((60, 3))
    Y = (Y - Y.mean(0)) / Y.std(0)
    groups = [Y[:, [0, 1]], Y[:, [2]]]
    pooled = gp.fit_gps(X, groups, restarts=1, seed=4)
    for k, (fitted, targets) in enumerate(zip(pooled, groups)):
        alone = gp.fit_gp(X, targets, restarts=1, seed=4 + k)
        assert fitted.log_marginal_likelihood() == pytest.approx(alone.log_marginal_likelihood(), rel=1e-6)


def test_single_task_gp_matches_scikit_learn():
    rng = np.random.default_rng(1)
    X = rng.uniform(-2, 2, (50, 2))
    y = np.sin(X[:, 0]) + 0.5 * X[:, 1] ** 2 + 0.05 * rng.standard_normal(50)
    y = (y - y.mean()) / y.std()
    ours = gp.fit_gp(X, y[:, None], restarts=3, seed=0)
    kernel = ConstantKernel(1.0, (1e-6, 1e6)) * RBF([1.0, 1.0], (0.05, 50.0)) + WhiteKernel(0.01, (1e-6, 10.0))
    reference = GaussianProcessRegressor(kernel, n_restarts_optimizer=3, random_state=0).fit(X, y)
    assert ours.log_marginal_likelihood() == pytest.approx(reference.log_marginal_likelihood_value_, abs=0.05)
    Xs = rng.uniform(-2, 2, (10, 2))
    assert np.allclose(ours.predict(Xs)[:, 0], reference.predict(Xs), atol=0.02)


# --- seed 004 -------------------------------------------------------------------------------


SEED004_TABLE2 = {"fn": (0.9864, 0.1173), "k": (0.9221, 0.3608), "c": (0.9887, 62.9154)}  # R2, RMSE (Hz, MN/m, Ns/m)


def test_seed004_reproduction_trained_on_positions_1_4_7(datasets):
    """Seed 004 section 2.1 / Table 2: a GP trained on positions 1, 4, 7 predicts all seven.
    R2 over the seven positions (the seed compares predicted and actual at every position,
    Fig. 5) reaches 0.9 for fn, k and c; RMSE over the four held-out positions is reported next
    to the seed's."""
    table = read_modal_table(datasets / "seeds/hou2023_positions.csv")
    train = table.select_poses([0, 3, 6])
    model = PoseModel("stgp").fit(train)
    mean = model.predict(table.poses)
    fn = mean[:, model.targets_.index("x1.fn_hz")]
    k = mean[:, model.targets_.index("x1.k_n_per_m")]
    zeta = mean[:, model.targets_.index("x1.zeta")]
    c = 2 * zeta * k / (2 * math.pi * fn)
    x = table.direction == "x"
    truth = {"fn": table.fn_hz[x], "k": table.k_n_per_m[x], "c": table.c_ns_per_m[x]}
    predicted = {"fn": fn, "k": k, "c": c}
    held_out = [1, 2, 4, 5]
    report = {}
    for name in ("fn", "k", "c"):
        scale = 1e-6 if name == "k" else 1.0
        r2 = r2_score(predicted[name], truth[name])
        rmse = float(np.sqrt(np.mean((predicted[name][held_out] - truth[name][held_out]) ** 2)) * scale)
        report[name] = (r2, rmse)
        assert r2 >= 0.9, (name, r2)
    # our RMSE beside the seed's (printed with -s): k and c come out below the seed's
    print("seed 004 reproduction (R2 all seven, RMSE held-out) ours vs seed:", report, SEED004_TABLE2)
    assert report["k"][1] < SEED004_TABLE2["k"][1] and report["c"][1] < SEED004_TABLE2["c"][1]
    assert report["fn"][1] < 1.2 * SEED004_TABLE2["fn"][1]


# --- twin campaigns -------------------------------------------------------------------------


@pytest.fixture(scope="module")
def twin(datasets):
    spec = read_twin(datasets / "robots/kr_r2700_twin.toml")
    return Robot.from_urdf(spec.urdf, payload_kg=spec.payload_kg), spec.params


@pytest.fixture(scope="module")
def campaign(datasets):
    return read_modal_table(datasets / "campaigns/seed003_twin_s1.csv")


def first_mode(table):
    """Only mode 1 in every direction: x1, y1, z1 (the lowest robot mode seen three ways)."""
    rows = np.flatnonzero(table.mode == 1)
    from posedyn.table import ModalTable

    return ModalTable(table.poses, table.pose_index[rows], table.direction[rows], table.mode[rows], table.fn_hz[rows], table.zeta[rows], table.k_n_per_m[rows], {k: v[rows] for k, v in table.std.items()}, None)


def test_mtgp_beats_stgp_on_the_correlated_frequency_group(campaign):
    """Seed 003's finding on the shipped 112-pose campaign, 5-fold CV: the lowest mode's
    frequency measured in x, y and z (one physical quantity, three noisy measurements) forms a
    coregionalized group, and the MTGP has the higher mean R2 and the lower R2 spread."""
    table = first_mode(campaign)
    mtgp = PoseModel("mtgp").fit(table)
    fn = [mtgp.targets_.index(t) for t in ("x1.fn_hz", "y1.fn_hz", "z1.fn_hz")]
    assert sorted(fn) in [sorted(g) for g in mtgp.groups_]
    scores = {m: cross_validate(lambda m=m: PoseModel(m), table, folds=5, seed=0) for m in ("stgp", "mtgp")}
    names = ("x1.fn_hz", "y1.fn_hz", "z1.fn_hz")
    mean = {m: np.mean([scores[m][t]["r2_mean"] for t in names]) for m in scores}
    spread = {m: np.mean([scores[m][t]["r2_std"] for t in names]) for m in scores}
    print("fn group: R2 mean", mean, "R2 std", spread)
    assert mean["mtgp"] > mean["stgp"]
    assert spread["mtgp"] < spread["stgp"]


def as_built_campaign(robot, params, datasets, seed, noise=Noise()):
    """A robot that differs from the nominal twin: joint stiffnesses off by up to +-30 %, a 65 kg
    payload instead of 50, and an 8 kg device on the spindle housing."""
    rng = np.random.default_rng(100 + seed)
    built = Robot.from_urdf(datasets / "robots/kr_r2700_spindle.urdf", payload_kg=65.0)
    params_built = params.scaled(rng.uniform(0.7, 1.3, 6))
    poses = list(read_grid(datasets / "campaigns/seed003_grid.toml").poses)
    return generate_campaign(built, poses, params_built, noise, seed=seed, effects=(DeviceMass(mass_kg=8.0),))


def test_physics_prior_reaches_three_percent_on_the_lowest_mode_with_ten_poses(twin, datasets):
    robot, params = twin
    measured = as_built_campaign(robot, params, datasets, seed=3)
    truth = as_built_campaign(robot, params, datasets, seed=3, noise=Noise(0, 0, 0))
    order = np.random.default_rng(0).permutation(len(measured.poses))
    train, test = order[:10], order[10:]
    names, true_values = table_targets(truth.select_poses(test))
    j = names.index("x1.fn_hz")
    errors = {}
    for method in ("stgp", "mtgp", "physics"):
        model = PoseModel(method, twin=(robot, params)).fit(measured.select_poses(train))
        predicted = model.predict(measured.select_poses(test).poses)[:, model.targets_.index("x1.fn_hz")]
        errors[method] = float(np.mean(np.abs(predicted / true_values[:, j] - 1)))
    print("mean relative error on the lowest mode's fn with 10 poses:", errors)
    assert errors["physics"] <= 0.03
    assert errors["physics"] < errors["stgp"] and errors["physics"] < errors["mtgp"]


def test_physics_prior_pairs_table_modes_with_the_twins_by_frequency_and_stiffness(twin, datasets, tmp_path):
    """A table that numbers per direction the robot mode the tool sees and then the spindle (x: the
    twin's 12.5 Hz and 1443 Hz modes as 1 and 2; y: its 16.9 Hz and 1480 Hz modes as 1 and 2): by
    number the spindle took the twin's second robot mode as its prior and predicted 1e84 N/m. Now
    each mode gets the twin mode that matches its frequency and stiffness, and the predictions at
    the training poses follow the measurements."""
    keep = {("x", "1"): "1", ("x", "3"): "2", ("y", "2"): "1", ("y", "3"): "2"}
    lines = (datasets / "campaigns/seed003_twin_s1.csv").read_text().splitlines()
    header = lines[0].split(",")
    d_col, m_col = header.index("direction"), header.index("mode")
    out = [lines[0]]
    for line in lines[1:]:
        cells = line.split(",")
        if (cells[d_col], cells[m_col]) in keep:
            cells[m_col] = keep[(cells[d_col], cells[m_col])]
            out.append(",".join(cells))
    (tmp_path / "renumbered.csv").write_text("\n".join(out) + "\n")
    table = read_modal_table(tmp_path / "renumbered.csv")
    physics = PoseModel("physics", twin=twin).fit(table)
    assert physics.physics_["mode_map"] == {"x1": 1, "x2": 3, "y1": 2, "y2": 3}
    names, measured = table_targets(table)
    error = np.abs(np.log(physics.predict(table.poses)[:, [physics.targets_.index(t) for t in names]] / measured))
    assert np.all(np.median(error, axis=0) < 0.1) and error.max() < 1.0, error.max(axis=0)  # within the noise (zeta 10 %); by number: ln errors of 190


def test_predictive_std_is_calibrated_on_held_out_poses(twin, datasets):
    """About 95 % of the true (noise-free) values fall inside +-2 std on poses not trained on."""
    robot, params = twin
    measured = as_built_campaign(robot, params, datasets, seed=5)
    truth = as_built_campaign(robot, params, datasets, seed=5, noise=Noise(0, 0, 0))
    order = np.random.default_rng(1).permutation(len(measured.poses))
    train, test = order[:60], order[60:]
    model = PoseModel("physics", twin=(robot, params)).fit(measured.select_poses(train))
    assert model.physics_["fit_converged"]  # plain least squares: 600 evaluations, not converged (ln residuals of 1-3 on a few rows)
    mean, std = model.predict(measured.select_poses(test).poses, return_std=True)
    names, true_values = table_targets(truth.select_poses(test))
    cols = [model.targets_.index(t) for t in names if t.split(".")[0] in ("x1", "x2", "y1", "y2") and not t.endswith("zeta")]
    true_cols = [names.index(model.targets_[c]) for c in cols]
    inside = np.abs(mean[:, cols] - true_values[:, true_cols]) <= 2 * std[:, cols]
    print("coverage of +-2 std:", inside.mean())
    assert 0.85 <= inside.mean() <= 0.99


# --- persistence and CLI --------------------------------------------------------------------


def test_model_directory_round_trip_and_schema_check(twin, campaign, tmp_path):
    robot, params = twin
    table = first_mode(campaign).select_poses(range(40))
    for method in ("stgp", "mtgp", "physics"):
        model = PoseModel(method, twin=(robot, params)).fit(table)
        save_model(model, tmp_path / method)
        again = load_model(tmp_path / method)
        poses = first_mode(campaign).select_poses(range(40, 60)).poses
        a, sa = model.predict(poses, return_std=True)
        b, sb = again.predict(poses, return_std=True)
        assert np.allclose(a, b, rtol=1e-10) and np.allclose(sa, sb, rtol=1e-8)
        assert again.training_hash_ == model.training_hash_
    doc = json.loads((tmp_path / "stgp/model.json").read_text())
    doc["schema_version"] = 99
    (tmp_path / "stgp/model.json").write_text(json.dumps(doc))
    with pytest.raises(InputError, match=r"model\.json, column 'schema_version': expected schema_version 1.*got 99"):
        load_model(tmp_path / "stgp")
    # damaged files: an error that names the file, no traceback (a truncated arrays.npz was a BadZipFile)
    arrays = tmp_path / "mtgp/arrays.npz"
    arrays.write_bytes(arrays.read_bytes()[:100])
    with pytest.raises(InputError, match=r"arrays\.npz: expected arrays\.npz with X_train and Z_train, got 'BadZipFile"):
        load_model(tmp_path / "mtgp")
    for text, words in ((b"[1, 2]", "expected a JSON object, got 'list'"), (b"\xff\xfe{}", "expected UTF-8 text")):
        (tmp_path / "physics/model.json").write_bytes(text)
        with pytest.raises(InputError, match=re.escape(words)):
            load_model(tmp_path / "physics")


def test_physics_falls_back_without_reachable_poses(twin, datasets):
    robot, params = twin
    table = read_modal_table(datasets / "seeds/swan_fixture.csv")  # placeholder pose at the origin
    from posedyn.table import ModalTable, PoseSet

    two = ModalTable(
        PoseSet(("a", "b"), np.array([[0, 0, 0], [10, 0, 0]]), "beta", np.zeros((2, 1))),
        np.r_[np.zeros(len(table), int), np.ones(len(table), int)],
        np.r_[table.direction, table.direction], np.r_[table.mode, table.mode],
        np.r_[table.fn_hz, table.fn_hz * 1.01], np.r_[table.zeta, table.zeta], np.r_[table.k_n_per_m, table.k_n_per_m],
    )
    model = PoseModel("physics", twin=(robot, params)).fit(two)
    assert model.physics_["used"] is False and "tool tip at (0.0, 0.0, 0.0) mm" in model.physics_["reason"]
    assert np.isfinite(model.predict(two.poses)).all()  # a plain stgp underneath


def posedyn(*args):
    return run_cli(*args)


def test_train_never_deletes_what_is_at_out_unless_it_is_a_model(datasets, tmp_path):
    """`--out` names a directory that is replaced as a whole: a folder holding anything but a
    model's files, or a file, is refused before training (it used to be deleted); a model
    directory is replaced; "." works from inside one."""
    data = datasets / "seeds/hou2023_positions.csv"
    folder = tmp_path / "mine"
    folder.mkdir()
    (folder / "notes.txt").write_text("precious")
    result = posedyn("train", data, "--out", folder, "--cv", "0")
    assert result.returncode == 2 and "notes.txt" in result.stderr and "Traceback" not in result.stderr
    assert (folder / "notes.txt").read_text() == "precious" and sorted(p.name for p in folder.iterdir()) == ["notes.txt"]
    (tmp_path / "file").write_text("hello")
    result = posedyn("train", data, "--out", tmp_path / "file", "--cv", "0")
    assert result.returncode == 2 and "an existing file" in result.stderr and (tmp_path / "file").read_text() == "hello"
    model = tmp_path / "model"
    model.mkdir()  # empty: taken
    assert posedyn("train", data, "--out", model, "--cv", "0").returncode == 0
    assert run_cli("train", data, "--out", ".", "--cv", "0", cwd=model).returncode == 0  # the model replaced from inside it
    assert sorted(p.name for p in model.iterdir()) == ["arrays.npz", "model.json"] and load_model(model).n_poses_ == 7
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # nothing left behind


def test_train_and_predict_cli_contract(datasets, tmp_path):
    result = posedyn("train", datasets / "seeds/hou2023_positions.csv", "--out", tmp_path / "m", "--cv", "3", "--json")
    assert result.returncode == 0, result.stderr
    out = json.loads(result.stdout)
    assert out["method"] == "stgp" and out["n_poses"] == 7
    assert set(out["cv"]) == {"x1.fn_hz", "x1.zeta", "x1.k_n_per_m", "y1.fn_hz", "y1.zeta", "y1.k_n_per_m"}
    assert {"r2_mean", "r2_std", "r2_pooled", "rmse", "z_rms"} <= set(out["cv"]["x1.fn_hz"]) <= {"r2_mean", "r2_std", "r2_pooled", "rmse", "z_rms", "note"}
    poses = tmp_path / "poses.csv"
    poses.write_text("pose_id,x_mm,y_mm,z_mm,beta_deg\nnew,1450,0,800,0\n")
    result = posedyn("predict", tmp_path / "m", "--poses", poses, "--out", tmp_path / "pred.csv", "--json")
    assert result.returncode == 0, result.stderr
    predicted = json.loads(result.stdout)
    assert predicted[0]["pose_id"] == "new"
    mode = predicted[0]["modes"][0]
    assert set(mode) == {"direction", "mode", "fn_hz", "std_fn_hz", "zeta", "std_zeta", "k_n_per_m", "std_k_n_per_m"}
    assert 18.1 < mode["fn_hz"] < 19.4
    table = read_modal_table(tmp_path / "pred.csv")  # feeds every other command
    assert set(table.std) == {"std_fn_hz", "std_zeta", "std_k_n_per_m"}
    chatter = posedyn("chatter", "--modes", tmp_path / "pred.csv", "--rpm", 2000, "--teeth", 3, "--kt-mpa", 796, "--kn-mpa", 169, "--radial-immersion", 0.5, "--json")
    assert chatter.returncode == 0, chatter.stderr
    bad = tmp_path / "bad.csv"
    bad.write_text("pose_id,x_mm,y_mm,z_mm,beta_deg\nnew,1450,zero,800,0\n")
    result = posedyn("predict", tmp_path / "m", "--poses", bad)
    assert result.returncode == 2 and "bad.csv, row 1 (line 2), column 'y_mm'" in result.stderr


def test_r2_is_undefined_where_the_values_vary_only_by_rounding():
    """A constant column (zeta 0.04 at every pose) whose copies differ in the last bit: the
    per-fold R2 was undefined and the pooled one -7e16."""
    actual = np.array([0.04, 0.04 + 7e-18, 0.04, 0.04 - 7e-18])
    assert math.isnan(r2_score(actual + 1e-6, actual))
    assert r2_score(np.array([1.0, 2.1, 2.9]), np.array([1.0, 2.0, 3.0])) == pytest.approx(0.99)


def test_the_workspace_the_service_serves_is_the_models_and_schedule_warns_beyond_it(datasets, tmp_path):
    """`posedyn serve` refused x = 1000 mm ('outside_workspace') while `posedyn schedule` on the
    same model answered it without a word. One rule (PoseModel.workspace_bounds) for both; the
    schedule now warns on stderr (its --json stays strict)."""
    from posedyn.table import PoseSet

    model = PoseModel("stgp").fit(read_modal_table(datasets / "seeds/hou2023_positions.csv"))
    assert model.workspace_bounds()["x_mm"] == pytest.approx((1050.0, 1950.0))
    poses = PoseSet.from_columns(("P5", "x1000"), {"x_mm": [1400.0, 1000.0], "y_mm": [0.0, 0.0], "z_mm": [800.0, 800.0], "beta_deg": [0.0, 0.0]})
    assert model.outside_workspace(poses) == ["pose x1000: x_mm = 1000 outside [1050, 1950]"]
    save_model(model, tmp_path / "m")
    (tmp_path / "poses.csv").write_text("pose_id,x_mm,y_mm,z_mm,beta_deg\nx1000,1000,0,800,0\n")
    result = run_cli("predict", tmp_path / "m", "--poses", tmp_path / "poses.csv", "--json")
    assert result.returncode == 0 and "outside_workspace" in result.stderr and "x1000" in result.stderr


def test_a_pose_column_the_training_poses_all_share_bounds_the_workspace(datasets, tmp_path):
    """Trained on seed 004's positions (x varies; y = 0, z = 800, beta = 0 throughout), a pose at
    y = 300 mm, beta = 45 deg got exactly P5's prediction and its tight std, and the service
    answered it: the model never saw y or beta change. Such a column bounds the workspace within
    50 mm or 15 deg of its value, saved with the model; the service refuses beyond, schedule
    warns; so for a pose in another orientation convention (a/b/c_deg to a beta_deg model)."""
    from posedyn.table import PoseSet
    from service.zenoh_service.engine import ScheduleEngine
    from service.zenoh_service.protocol import RequestError

    model = PoseModel("stgp").fit(read_modal_table(datasets / "seeds/hou2023_positions.csv"))
    assert model.features_ == ["x_mm"] and model.fixed_pose_ == {"y_mm": 0.0, "z_mm": 800.0, "beta_deg": 0.0}
    bounds = model.workspace_bounds()
    assert bounds["y_mm"] == (-50.0, 50.0) and bounds["beta_deg"] == (-15.0, 15.0) and bounds["z_mm"] == (750.0, 850.0)
    poses = PoseSet.from_columns(("P5", "Q"), {"x_mm": [1400.0, 1400.0], "y_mm": [0.0, 300.0], "z_mm": [800.0, 800.0], "beta_deg": [0.0, 45.0]})
    assert model.outside_workspace(poses) == ["pose Q: y_mm = 300 outside [-50, 50]", "pose Q: beta_deg = 45 outside [-15, 15]"]
    save_model(model, tmp_path / "m")
    assert load_model(tmp_path / "m").workspace_bounds() == bounds
    engine = ScheduleEngine(tmp_path / "m", datasets / "seeds/hou2023_cut.toml")
    with pytest.raises(RequestError) as refused:
        engine.pose_set({"pose_id": "Q", "x_mm": 1400.0, "y_mm": 300.0, "z_mm": 800.0, "beta_deg": 0.0})
    assert refused.value.code == "outside_workspace" and "y_mm = 300 outside [-50, 50]" in refused.value.message
    engine.pose_set({"pose_id": "P5", "x_mm": 1400.0, "y_mm": 20.0, "z_mm": 800.0, "beta_deg": 0.0})  # within 50 mm of y = 0
    with pytest.raises(RequestError) as refused:  # another orientation convention: the model knows beta only (it was answered as beta = 0)
        engine.pose_set({"pose_id": "P5", "x_mm": 1400.0, "y_mm": 20.0, "z_mm": 800.0, "a_deg": 0.0, "b_deg": 0.0, "c_deg": 0.0})
    assert refused.value.code == "outside_workspace" and "a_deg given, the model knows the orientation as beta_deg" in refused.value.message
    abc = PoseSet.from_columns(("R",), {"x_mm": [1400.0], "y_mm": [0.0], "z_mm": [800.0], "a_deg": [0.0], "b_deg": [90.0], "c_deg": [0.0]})
    assert model.outside_workspace(abc) == ["pose R: a_deg given, the model knows the orientation as beta_deg"]


def test_train_checks_its_options_and_the_holdout_before_training(datasets, tmp_path):
    """A missing hold-out file was found after the model was written; a feature constant over the
    training poses or given twice, and --restarts -1, were taken; the hold-out scores showed only
    with --json."""
    table = datasets / "seeds/hou2023_positions.csv"
    for args, words in ((("--holdout", tmp_path / "none.csv"), "none.csv"), (("--features", "z_mm"), "expected features that vary"),
                        (("--features", "x_mm,x_mm"), "expected each feature once"), (("--restarts", -1), "--restarts")):
        result = posedyn("train", table, "--cv", 0, "--out", tmp_path / "m", *args)
        assert result.returncode == 2 and words in result.stderr + result.stdout, (args, result.stderr)
        assert not (tmp_path / "m").exists()
    result = posedyn("train", table, "--cv", 0, "--out", tmp_path / "m", "--holdout", table)
    assert result.returncode == 0 and "hold-out table" in result.stdout and "x1.fn_hz" in result.stdout
