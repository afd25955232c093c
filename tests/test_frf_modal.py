"""FRF import (CSV, UFF) and modal identification against known modes."""

import json
import re

import numpy as np
import pytest

from posedyn.dynamics import ToolTipDynamics
from posedyn.errors import InputError
from posedyn.io import read_modal_table
from posedyn.io.frf import FRFSet, read_frf, read_frf_csv, write_frf_csv, write_frf_uff
from posedyn.identify import direct_modal_parameters, matrix_modal_fit
from posedyn.stability import Cut, Discretization, StabilityModel
from posedyn.table import Mode
from tests.cli_helpers import run_cli

TRUE = [(6.5, 0.04, 6e5), (18.0, 0.03, 2.5e6), (34.0, 0.05, 4e6), (700.0, 0.03, 4e7), (2600.0, 0.02, 6e7)]


def receptance(f, modes):
    w = 2 * np.pi * f
    return sum(1 / (k * (1 - (w / (2 * np.pi * fn)) ** 2 + 2j * z * w / (2 * np.pi * fn))) for fn, z, k in modes)


def noisy(h, rng, level=0.02):
    return h + level * np.abs(h) * (rng.standard_normal(len(h)) + 1j * rng.standard_normal(len(h))) / np.sqrt(2)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_direct_frf_identification_recovers_robot_and_spindle_modes(seed):
    """Robot modes at 5-40 Hz and spindle modes at 500-3000 Hz in one FRF, 2 % complex noise:
    fn within 0.5 %, zeta within 10 %, modal stiffness within 5 %, and honest uncertainties."""
    rng = np.random.default_rng(seed)
    f = np.arange(0.5, 4000.0, 0.25)
    found = direct_modal_parameters(f, noisy(receptance(f, TRUE), rng))
    assert len(found) == len(TRUE)
    for (fn, zeta, k), got in zip(TRUE, found):
        assert got["fn_hz"] == pytest.approx(fn, rel=0.005)
        assert got["zeta"] == pytest.approx(zeta, rel=0.10)
        assert got["k_n_per_m"] == pytest.approx(k, rel=0.05)
        assert 0 < got["std_k_n_per_m"] < 0.05 * k


def coupled_matrix(f, rng):
    """Two coupled robot modes (different left and right shapes: non-symmetric coupling) and two
    uncoupled spindle modes; mass-normalised shapes in 1/sqrt(kg)."""
    modes = [(9.0, 0.04, [0.12, 0.08], [0.12, 0.05]), (21.0, 0.03, [0.05, -0.10], [0.05, -0.09]), (1500.0, 0.03, [0.02, 0.0], [0.02, 0.0]), (2200.0, 0.02, [0.0, 0.018], [0.0, 0.018])]
    w = 2 * np.pi * f
    clean, H = {}, {}
    for a, ia in (("x", 0), ("y", 1)):
        for b, ib in (("x", 0), ("y", 1)):
            h = sum(L[ia] * R[ib] / ((2 * np.pi * fn) ** 2 - w**2 + 2j * z * 2 * np.pi * fn * w) for fn, z, L, R in modes)
            clean[f"h_{a}{b}"] = h
            H[f"h_{a}{b}"] = noisy(h, rng)
    return modes, clean, H


def test_frf_matrix_fit_recovers_the_cross_coupling():
    rng = np.random.default_rng(3)
    f = np.arange(0.5, 4000.0, 0.25)
    modes, clean, H = coupled_matrix(f, rng)
    found, rebuilt = matrix_modal_fit(f, H)
    assert len(found) == 4
    for (fn, zeta, L, R), got in zip(modes[:2], found[:2]):
        assert got["fn_hz"] == pytest.approx(fn, rel=0.005)
        product = np.outer(got["shape_left"], got["shape_right"])
        assert np.allclose(product, np.outer(L, R), rtol=0.03, atol=0.002 * np.abs(np.outer(L, R)).max())
    for name in H:  # the fitted matrix is within the 2 % noise of the true one
        error = np.abs(rebuilt[name] - clean[name]) / np.abs(clean[name]).max()
        assert np.percentile(error, 95) < 0.02


def test_a_pole_shared_by_an_x_and_a_y_mode_gives_both_modes():
    """An uncoupled x and y spindle mode at one frequency (a symmetric spindle) share a pole: its
    residue matrix has rank two, and the first rank-one factor alone had dropped the y mode, h_yy's
    largest peak, without a warning (the table then read 3.68 mm where the true one gives 1.70)."""
    rng = np.random.default_rng(4)
    f = np.arange(1.0, 3000.0, 1.0)
    robot = receptance(f, [(15.0, 0.03, 1e7)])
    spindle = receptance(f, [(1500.0, 0.05, 3e6)])
    clean = {"h_xx": robot + spindle, "h_xy": 0.5 * robot, "h_yx": 0.5 * robot, "h_yy": 0.25 * robot + spindle}
    found, rebuilt = matrix_modal_fit(f, {n: noisy(h, rng, 0.01) for n, h in clean.items()})
    at_1500 = [m for m in found if abs(m["fn_hz"] - 1500.0) < 5.0]
    assert len(found) == 3 and len(at_1500) == 2
    directions = sorted(int(np.argmax(np.abs(m["shape_right"]))) for m in at_1500)
    assert directions == [0, 1]  # one along x, one along y
    for m in at_1500:  # mass-normalised: phi_L . phi_R = 1 / m = w^2 / k, k = 3e6 N/m
        assert np.dot(m["shape_left"], m["shape_right"]) / (2 * np.pi * m["fn_hz"]) ** 2 == pytest.approx(1 / 3e6, rel=0.03)
    for name in clean:
        error = np.abs(rebuilt[name] - clean[name]) / np.abs(clean[name]).max()
        assert np.percentile(error, 95) < 0.02


def test_fit_cli_writes_a_coupled_table_that_the_stability_engine_uses(tmp_path):
    rng = np.random.default_rng(4)
    f = np.arange(0.5, 4000.0, 0.25)
    modes, clean, H = coupled_matrix(f, rng)
    frf = FRFSet(f, H, pose_id="C1", pose={"x_mm": 1500.0, "y_mm": 0.0, "z_mm": 600.0, "beta_deg": 10.0})
    write_frf_csv(frf, tmp_path / "c1.csv")
    result = run_cli("fit", tmp_path / "c1.csv", "--out", tmp_path / "modes.csv", "--modes", "2", "--plot", tmp_path / "plots", "--json")
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout)["coupled"] is True
    assert (tmp_path / "plots/C1.png").read_bytes()[:4] == b"\x89PNG"
    table = read_modal_table(tmp_path / "modes.csv")
    assert set(table.cross) == {"k_xy_n_per_m", "k_yx_n_per_m"}
    # every row has its stds (the matrix path too): fn's and zeta's of the pole, k's of its direct residue
    assert set(table.std) == {"std_fn_hz", "std_zeta", "std_k_n_per_m"}
    for name in table.std:
        assert np.all(np.isfinite(table.std[name]) & (table.std[name] >= 0)), name
    assert np.all(table.std["std_k_n_per_m"] > 0) and np.all(table.std["std_k_n_per_m"] < 0.05 * table.k_n_per_m)
    assert np.all(table.std["std_fn_hz"] < 0.01 * table.fn_hz)
    dyn = ToolTipDynamics.from_table(table, "C1")
    truth = ToolTipDynamics(fn_hz=[m[0] for m in modes[:2]], zeta=[m[1] for m in modes[:2]], shapes=np.array([m[2] for m in modes[:2]]).T, shapes_force=np.array([m[3] for m in modes[:2]]).T)
    omega = 2 * np.pi * np.linspace(5, 30, 200)
    assert np.allclose(dyn.frf(omega), truth.frf(omega), rtol=0.05, atol=0.03 * np.abs(truth.frf(omega)).max())
    cut = Cut(teeth=3, kt_pa=796e6, kn_pa=169e6, radial_immersion=0.5)
    a = StabilityModel(dyn, cut, Discretization(40)).critical_depths([2000.0]).depth_m[0]
    b = StabilityModel(truth, cut, Discretization(40)).critical_depths([2000.0]).depth_m[0]
    assert a == pytest.approx(b, rel=0.03)


def test_stability_from_fitted_modes_matches_the_true_modes_at_seed004_position5(datasets):
    """Seed 004 position 5 (19.06 Hz, 1.06 MN/m, 725 Ns/m) plus a spindle mode: FRFs with 2 %
    noise, fitted, then the critical depth at 2000 rpm (3 teeth, Kt 796, Kn 169 MPa, immersion
    0.5) from the fitted modes is within 3 % of the one from the true modes."""
    table = read_modal_table(datasets / "seeds/hou2023_positions.csv")
    p5 = table.modes("P5", "x")[0]
    true = [(p5.fn_hz, p5.zeta, p5.k_n_per_m), (1450.0, 0.04, 5e7)]
    rng = np.random.default_rng(5)
    f = np.arange(0.5, 3000.0, 0.25)
    fitted = {d: direct_modal_parameters(f, noisy(receptance(f, true), rng)) for d in "xy"}
    dyn_fit = ToolTipDynamics.from_modes(*(tuple(Mode(m["fn_hz"], m["zeta"], m["k_n_per_m"]) for m in fitted[d]) for d in "xy"))
    dyn_true = ToolTipDynamics.from_modes(*(tuple(Mode(*m) for m in true) for _ in "xy"))
    cut = Cut(teeth=3, kt_pa=796e6, kn_pa=169e6, radial_immersion=0.5)
    a = StabilityModel(dyn_fit, cut, Discretization(40)).critical_depths([2000.0]).depth_m[0]
    b = StabilityModel(dyn_true, cut, Discretization(40)).critical_depths([2000.0]).depth_m[0]
    assert a == pytest.approx(b, rel=0.03)


def test_uff_and_csv_round_trips(tmp_path):
    rng = np.random.default_rng(6)
    f = np.linspace(1.0, 500.0, 400)
    frf = FRFSet(f, {"h_xx": noisy(receptance(f, TRUE[:2]), rng), "h_yy": receptance(f, TRUE[1:3])}, pose_id="P9", pose={"x_mm": 1.5, "beta_deg": -20.0})
    write_frf_csv(frf, tmp_path / "a.csv")
    back = read_frf_csv(tmp_path / "a.csv")
    assert back.pose_id == "P9" and back.pose == frf.pose
    assert all(np.array_equal(back.frf[n], frf.frf[n]) for n in frf.frf) and np.array_equal(back.frequency_hz, f)
    write_frf_uff(frf, tmp_path / "a.uff")
    once = read_frf(tmp_path / "a.uff")
    assert once.pose_id == "P9" and once.pose == frf.pose
    for n in frf.frf:
        assert np.allclose(once.frf[n], frf.frf[n], rtol=1e-11, atol=1e-11 * np.abs(frf.frf[n]).max())
    write_frf_uff(once, tmp_path / "b.uff")
    twice = read_frf(tmp_path / "b.uff")
    assert all(np.array_equal(twice.frf[n], once.frf[n]) for n in once.frf) and np.array_equal(twice.frequency_hz, once.frequency_hz)
    # mobility and accelerance are converted to receptance
    for quantity in ("mobility", "accelerance"):
        write_frf_csv(frf, tmp_path / f"{quantity}.csv", quantity=quantity)
        assert np.allclose(read_frf_csv(tmp_path / f"{quantity}.csv").frf["h_xx"], frf.frf["h_xx"], rtol=1e-12)


@pytest.mark.parametrize(
    "text, words",
    [
        ("frequency_hz,h_xx_re,h_xx_im\n1,1e-6,0\n2,1e-6,0\n2,1e-6,0\n", "duplicated at 2 Hz"),
        ("frequency_hz,h_xx_re,h_xx_im\n1,1e-6,0\n3,1e-6,0\n2,1e-6,0\n", "decreasing at 2 Hz"),
        ("frequency_hz,h_xx_re\n1,1e-6\n2,1e-6\n3,1e-6\n", "both h_xx_re and h_xx_im"),
        ("# quantity = mobility\n# unit = m/N\nfrequency_hz,h_xx_re,h_xx_im\n1,1,0\n2,1,0\n3,1,0\n", "unit m/s/N for mobility"),
        ("frequency_hz,h_xx_re,h_xx_im\n1,1e-6,0\n2,abc,0\n3,1e-6,0\n", "row 2 (line 3), column 'h_xx_re': expected a number"),
        # a column twice (the second pair was another FRF: silently fitted as this one), an FRF name that is no direction pair
        # (silently left out), a pose key that is no number (a traceback), one given twice or misspelt, a pose that is not finite
        ("frequency_hz,h_xx_re,h_xx_im,h_xx_re,h_xx_im\n1,1,0,1,0\n2,1,0,1,0\n3,1,0,1,0\n", "line 1, column 'h_xx_re': expected each column once"),
        ("frequency_hz,h_xx_re,h_xx_im,h_qq_re,h_qq_im\n1,1,0,1,0\n2,1,0,1,0\n3,1,0,1,0\n", "column 'h_qq_re': expected FRF names h_<response><reference>"),
        ("# x_mm = abc\nfrequency_hz,h_xx_re,h_xx_im\n1,1,0\n2,1,0\n3,1,0\n", "line 1, column 'x_mm': expected a number, got 'abc'"),
        ("# x_mm = 1500\n# x_mm = 1600\nfrequency_hz,h_xx_re,h_xx_im\n1,1,0\n2,1,0\n3,1,0\n", "line 2, column 'x_mm': expected each header key once (already on line 1)"),
        ("# colour = blue\nfrequency_hz,h_xx_re,h_xx_im\n1,1,0\n2,1,0\n3,1,0\n", "line 1, column 'colour': expected a header key among"),
        ("# y_mm = nan\nfrequency_hz,h_xx_re,h_xx_im\n1,1,0\n2,1,0\n3,1,0\n", "line 1, column 'y_mm': expected a finite number"),
        ("frequency_hz,h_xx_re,h_xx_im\n-1,1,0\n2,1,0\n3,1,0\n", "row 1 (line 2), column 'frequency_hz': expected finite frequencies >= 0 Hz, got -1.0"),
    ],
)
def test_bad_frf_files_get_clear_errors(tmp_path, text, words):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(InputError) as info:
        read_frf_csv(path)
    assert words in str(info.value) and "bad.csv" in str(info.value)


def _uff(path, sets):
    """A UFF file of (data, rsp_dir, ref_dir, id2) datasets at 1-400 Hz (receptance)."""
    import pyuff

    f = np.linspace(1.0, 400.0, 200)
    pyuff.UFF(str(path)).write_sets([pyuff.prepare_58(binary=0, func_type=4, id1="t", id2=id2, rsp_node=1, rsp_dir=r, ref_node=1, ref_dir=c, data=d(f), x=f,
                                                      abscissa_spec_data_type=18, ordinate_spec_data_type=8, orddenom_spec_data_type=13)
                                     for d, r, c, id2 in sets], mode="overwrite")
    return path


POSE_ID2 = "pose_id=U;x_mm=1400;y_mm=0;z_mm=800;beta_deg=0"


def test_uff_negative_directions_flip_the_sign_and_bad_directions_or_pose_keys_are_refused(tmp_path):
    """UFF direction -2 is measured along -y: the FRF along +y is the measured one times the signs
    of both directions (a cross term read with the wrong sign made a 0.72 mm cut read 12.65 mm)."""
    hxy = lambda f: receptance(f, TRUE[:1]) * 0.5
    plus = read_frf(_uff(tmp_path / "plus.uff", [(hxy, 1, 2, POSE_ID2), (hxy, 2, 2, POSE_ID2)]))
    minus = read_frf(_uff(tmp_path / "minus.uff", [(lambda f: -hxy(f), 1, -2, POSE_ID2), (hxy, -2, -2, POSE_ID2)]))
    for n in ("h_xy", "h_yy"):
        assert np.array_equal(minus.frf[n], plus.frf[n])
    refused = {
        "dir0": ([(hxy, 1, 1, POSE_ID2), (hxy, 0, 0, POSE_ID2)], "row 2, column 'rsp_dir'"),
        "dir4": ([(hxy, 1, 4, POSE_ID2)], "row 1, column 'ref_dir'"),
        "twice": ([(hxy, 1, 1, POSE_ID2 + ";x_mm=1500")], "x_mm twice"),
        "unknown": ([(hxy, 1, 1, POSE_ID2 + ";colour=red")], "colour"),
        "two poses": ([(hxy, 1, 1, POSE_ID2), (hxy, 2, 2, POSE_ID2.replace("1400", "1500"))], "row 2, column 'id2 x_mm'"),
    }
    for name, (sets, words) in refused.items():
        with pytest.raises(InputError, match=re.escape(words)):
            read_frf(_uff(tmp_path / f"{name}.uff", sets))


def test_pose_model_learns_cross_coupling_and_predicts_coupled_modes():
    """Cross stiffnesses (signed) are learned as compliances 1 / k_xy in linear space and come
    back as the k_xy / k_yx columns of the predicted table, which builds a coupled structure."""
    from posedyn.posemodel import PoseModel
    from posedyn.table import ModalTable, PoseSet

    n = 8
    x = np.linspace(1300, 1900, n)
    scale = 1 + 0.3 * (x - 1300) / 600
    poses = PoseSet(tuple(f"p{i}" for i in range(n)), np.column_stack([x, np.zeros(n), np.full(n, 600.0)]), "beta", np.zeros((n, 1)))
    rows = dict(pose_index=np.repeat(np.arange(n), 2), direction=["x", "y"] * n, mode=[1, 1] * n)
    fn = np.repeat(12.0 / np.sqrt(scale), 2)
    table = ModalTable(
        poses=poses, fn_hz=fn, zeta=np.full(2 * n, 0.03), k_n_per_m=np.ravel(np.column_stack([2e6 / scale, 3e6 / scale])),
        cross={"k_xy_n_per_m": np.ravel(np.column_stack([-4e6 / scale, np.full(n, np.nan)])), "k_yx_n_per_m": np.ravel(np.column_stack([np.full(n, np.nan), -5e6 / scale]))},
        **rows,
    )
    model = PoseModel("stgp").fit(table)
    assert "x1.k_xy_n_per_m" in model.targets_ and "y1.k_yx_n_per_m" in model.targets_
    predicted = model.predict_table(table.poses)
    assert np.allclose(predicted.cross["k_xy_n_per_m"][::2], -4e6 / scale, rtol=0.02)
    dyn = ToolTipDynamics.from_table(predicted, "p3")
    assert dyn.n_modes == 1 and dyn.frf(np.array([1.0]))[0, 0, 1].real < 0  # negative cross term


def test_a_predicted_coupled_mode_is_one_rank_one_mode_that_the_parser_reads_back():
    """The pose model predicts fn, zeta and k of a coupled mode's x and y rows independently; the
    predicted table makes them one rank-one mode (means, k_yy = k_xy k_yx / k_xx), as the engine
    reads it, so that the table written by `posedyn predict` passes the parser's consistency
    check, here far outside the training poses (independently, k_yy drifted 2.5x there)."""
    from posedyn.io import format_modal_table, parse_modal_table
    from posedyn.posemodel import PoseModel
    from posedyn.table import ModalTable, PoseSet

    n = 8
    x = np.linspace(1300, 1900, n)
    scale = 1 + 0.3 * (x - 1300) / 600
    poses = PoseSet(tuple(f"p{i}" for i in range(n)), np.column_stack([x, np.zeros(n), np.full(n, 600.0)]), "beta", np.zeros((n, 1)))
    rows = dict(pose_index=np.repeat(np.arange(n), 2), direction=["x", "y"] * n, mode=[1, 1] * n)
    table = ModalTable(
        poses=poses, fn_hz=np.ravel(np.column_stack([12.0 / np.sqrt(scale), 12.2 / np.sqrt(scale)])), zeta=np.tile([0.03, 0.035], n),
        k_n_per_m=np.full(2 * n, 2e6) * np.repeat(scale, 2),
        cross={"k_xy_n_per_m": np.ravel(np.column_stack([-4e6 * scale, np.full(n, np.nan)])), "k_yx_n_per_m": np.ravel(np.column_stack([np.full(n, np.nan), -1e6 / scale]))},
        **rows,
    )
    far = np.linspace(400, 2800, 7)
    model = PoseModel("stgp").fit(table)
    predicted = model.predict_table(PoseSet(tuple(f"q{i}" for i in range(len(far))), np.column_stack([far, np.zeros(len(far)), np.full(len(far), 600.0)]),
                                            "beta", np.zeros((len(far), 1))))
    xr, yr = predicted.direction == "x", predicted.direction == "y"
    assert np.allclose(predicted.fn_hz[xr], predicted.fn_hz[yr]) and np.allclose(predicted.zeta[xr], predicted.zeta[yr])
    assert np.allclose(predicted.k_n_per_m[yr], predicted.cross["k_xy_n_per_m"][xr] * predicted.cross["k_yx_n_per_m"][yr] / predicted.k_n_per_m[xr])
    back = parse_modal_table(format_modal_table(predicted), "predicted.csv")
    assert np.array_equal(back.k_n_per_m, predicted.k_n_per_m)


def test_a_matrix_fit_writes_a_mode_seen_in_one_direction_as_one_uncoupled_row(tmp_path):
    """A new user's x-y FRF matrix (1 % noise): a coupled 10 Hz mode (kxx 8e5, kxy = kyx 2e6,
    kyy 5e6 N/m) and uncoupled spindle modes at 5.2 kHz in x and 5.4 kHz in y. The fit wrote
    each spindle mode in both directions, the other one with a stiffness of noise (1e20 N/m) and
    cross terms of 1e14 of opposite signs, a table every command then refused. Now a mode
    living in one direction is one row there, and the table reads back."""
    from posedyn.modal_fit import fit_table
    from posedyn.io import write_modal_table

    rng = np.random.default_rng(1)
    f = np.concatenate([np.linspace(2, 200, 800), np.linspace(200.5, 8000, 3000)])
    coupled = receptance(f, [(10.0, 0.04, 1.0)])  # unit stiffness: scaled per entry below
    H = {"h_xx": coupled / 8e5 + receptance(f, [(5200.0, 0.015, 2.5e7)]), "h_yy": coupled / 5e6 + receptance(f, [(5400.0, 0.012, 2.8e7)]),
         "h_xy": coupled / 2e6, "h_yx": coupled / 2e6}
    H = {k: v * (1 + 0.01 * (rng.standard_normal(len(f)) + 1j * rng.standard_normal(len(f)))) for k, v in H.items()}
    table, _ = fit_table([FRFSet(f, H, pose_id="A", pose={"x_mm": 1500.0, "y_mm": 0.0, "z_mm": 700.0, "beta_deg": 0.0})])
    write_modal_table(table, tmp_path / "fit.csv")
    back = read_modal_table(tmp_path / "fit.csv")
    rows = sorted(zip(back.direction, np.round(back.fn_hz), back.k_n_per_m, back.cross["k_xy_n_per_m"], back.cross["k_yx_n_per_m"]))
    assert [(d, fn) for d, fn, *_ in rows] == [("x", 10.0), ("x", 5200.0), ("y", 10.0), ("y", 5400.0)]
    expected = {("x", 10.0): (8e5, 2e6, None), ("x", 5200.0): (2.5e7, None, None), ("y", 10.0): (5e6, None, 2e6), ("y", 5400.0): (2.8e7, None, None)}
    for d, fn, k, kxy, kyx in rows:
        k_true, kxy_true, kyx_true = expected[(d, fn)]
        assert k == pytest.approx(k_true, rel=0.03)
        for got, true in ((kxy, kxy_true), (kyx, kyx_true)):
            assert (np.isnan(got) and true is None) or got == pytest.approx(true, rel=0.03)


@pytest.mark.parametrize("seed", [3, 6])
def test_fit_finds_a_mode_on_a_decade_edge_and_warns_where_a_fit_misses_a_peak(tmp_path, seed, monkeypatch):
    """A new user's direct FRFs at 1 Hz resolution, 2 % noise (x: 10, 1450, 5200 Hz; y: 10.8,
    1480, 5400 Hz): in noise seed 6 the identification left out the 10 Hz x mode, the most
    flexible one, and the table was written without a word (the critical depth from it 3x too
    deep): 10 Hz is the edge between the decades 1-10 and 10-100 Hz, where no band's poles
    stabilize. It is found now (a decade centred on each edge), and where a fit does miss a peak
    by a quarter of it (the 10 Hz mode dropped on purpose here), fit says so."""
    import posedyn.modal_fit as modal_fit

    rng = np.random.default_rng(seed)
    f = np.linspace(1, 8000, 8000)
    hxx = receptance(f, [(10.0, 0.04, 8e5), (1450.0, 0.06, 3.3e7), (5200.0, 0.015, 2.5e7)])
    hyy = receptance(f, [(10.8, 0.035, 1.1e6), (1480.0, 0.05, 6e7), (5400.0, 0.012, 2.8e7)])
    H = {name: h * (1 + 0.02 * (rng.standard_normal(h.size) + 1j * rng.standard_normal(h.size))) for name, h in (("h_xx", hxx), ("h_yy", hyy))}
    write_frf_csv(FRFSet(f, H, pose_id="B", pose={"x_mm": 1500.0, "y_mm": 0.0, "z_mm": 700.0, "beta_deg": 0.0}), tmp_path / "b.csv")
    result = run_cli("fit", tmp_path / "b.csv", "--out", tmp_path / "modes.csv", "--json")
    assert result.returncode == 0, result.stderr
    table = read_modal_table(tmp_path / "modes.csv")
    x10 = (table.direction == "x") & (np.abs(table.fn_hz - 10.0) < 0.5)
    assert x10.sum() == 1 and abs(table.k_n_per_m[x10][0] / 8e5 - 1) < 0.05 and json.loads(result.stdout)["warnings"] == []
    found = modal_fit.direct_modal_parameters
    monkeypatch.setattr(modal_fit, "direct_modal_parameters", lambda *a, **k: [m for m in found(*a, **k) if abs(m["fn_hz"] - 10.0) > 0.5])
    warnings = json.loads(run_cli("fit", tmp_path / "b.csv", "--out", tmp_path / "missed.csv", "--json").stdout)["warnings"]
    assert len(warnings) == 1 and "h_xx" in warnings[0] and "at 10 Hz" in warnings[0]


def test_a_low_robot_mode_measured_from_1_hz_is_fitted_not_a_traceback(tmp_path):
    """A 5 Hz mode (k 2e6 N/m, zeta 0.01) measured 1-4000 Hz at 0.5 Hz with 1 % noise: the 1-10 Hz
    decade has 18 lines, fewer than the coefficients of its higher LSCF orders, whose singular
    normal equations were a LinAlgError traceback (a new user's noise seed 13)."""
    f = np.arange(1.0, 4000.0, 0.5)
    w, wn = 2 * np.pi * f, 2 * np.pi * 5.0
    h = (wn**2 / 2e6) / (wn**2 - w**2 + 2j * 0.01 * wn * w)
    rng = np.random.default_rng(13)
    h = h + 0.01 * np.abs(h) * (rng.standard_normal(len(f)) + 1j * rng.standard_normal(len(f))) / np.sqrt(2)
    write_frf_csv(FRFSet(f, {"h_xx": h}, pose_id="R13"), tmp_path / "r13.csv")
    result = run_cli("fit", tmp_path / "r13.csv", "--out", tmp_path / "modes.csv")
    assert result.returncode == 0, result.stderr
    table = read_modal_table(tmp_path / "modes.csv")
    assert len(table) == 1 and abs(table.fn_hz[0] / 5.0 - 1) < 1e-3 and abs(table.k_n_per_m[0] / 2e6 - 1) < 0.01


def test_fit_refuses_a_pose_given_in_part_or_two_ways(tmp_path):
    """Files of one pose_id are merged: the same FRF in two of them, or the same pose key with two
    values, is refused (the later file had silently won); a file that leaves out part of the pose
    the others give is refused (it was put at 0 there)."""
    f = np.linspace(10.0, 2000.0, 400)
    h = 1.0 / (1e7 * (1 - (f / 500.0) ** 2 + 0.04j * f / 500.0))
    pose = {"x_mm": 1500.0, "y_mm": 0.0, "z_mm": 800.0, "beta_deg": 0.0}
    write_frf_csv(FRFSet(f, {"h_xx": h}, pose_id="P1", pose=pose), tmp_path / "xx.csv")
    write_frf_csv(FRFSet(f, {"h_xx": h}, pose_id="P1", pose=pose), tmp_path / "xx_again.csv")
    write_frf_csv(FRFSet(f, {"h_yy": h}, pose_id="P1", pose=dict(pose, x_mm=1600.0)), tmp_path / "yy_moved.csv")
    write_frf_csv(FRFSet(f, {"h_xx": h}, pose_id="P2", pose={"x_mm": 1500.0}), tmp_path / "partial.csv")
    for files, words in (((tmp_path / "xx.csv", tmp_path / "xx_again.csv"), "xx_again.csv, column 'h_xx': expected each FRF of pose P1 in one file"),
                         ((tmp_path / "xx.csv", tmp_path / "yy_moved.csv"), "yy_moved.csv, column 'x_mm': expected the pose of P1 as in"),
                         ((tmp_path / "xx.csv", tmp_path / "partial.csv"), "partial.csv, column 'y_mm': expected the whole pose in every file")):
        result = run_cli("fit", *files, "--out", tmp_path / "modes.csv")
        assert result.returncode == 2 and words in result.stderr, result.stderr
        assert not (tmp_path / "modes.csv").exists()


def test_fit_options_out_of_range_are_refused_and_a_failed_fit_names_the_file_and_frf(tmp_path):
    """--modes 0 and --fmax-hz 0 were read as "not given", --modes -1 dropped each direction's
    highest mode; an FRF without a mode in the band read "column 'frf'" without the file."""
    f = np.linspace(10.0, 2000.0, 400)
    h = 1.0 / (1e7 * (1 - (f / 500.0) ** 2 + 0.04j * f / 500.0))
    write_frf_csv(FRFSet(f, {"h_xx": h}, pose_id="P1"), tmp_path / "xx.csv")
    for option in (("--modes", 0), ("--modes", -1), ("--fmax-hz", 0), ("--fmin-hz", -5), ("--max-order", 1)):
        result = run_cli("fit", tmp_path / "xx.csv", "--out", tmp_path / "modes.csv", *option)
        assert result.returncode == 2 and option[0] in result.stderr + result.stdout, (option, result.stderr)
    result = run_cli("fit", tmp_path / "xx.csv", "--out", tmp_path / "modes.csv", "--fmin-hz", 1000, "--fmax-hz", 1100)
    assert result.returncode == 2 and f"{tmp_path / 'xx.csv'}, column 'h_xx': expected an FRF with at least one identifiable mode" in result.stderr


def test_fit_warns_where_a_stiffness_is_no_tool_tips(tmp_path):
    """Accelerance data in a file that says receptance fit to k about w^2 too small (1 N/m for a
    1e7 N/m mode at 500 Hz): a warning asks about the quantity; the right label gives none."""
    f = np.linspace(10.0, 2000.0, 400)
    h = 1.0 / (1e7 * (1 - (f / 500.0) ** 2 + 0.04j * f / 500.0))
    write_frf_csv(FRFSet(f, {"h_xx": h}, pose_id="P1", pose={"x_mm": 1500.0, "y_mm": 0.0, "z_mm": 700.0, "beta_deg": 0.0}), tmp_path / "acc.csv", quantity="accelerance")
    text = (tmp_path / "acc.csv").read_text()
    (tmp_path / "mislabelled.csv").write_text(text.replace("accelerance", "receptance").replace("m/s^2/N", "m/N"))
    warned = json.loads(run_cli("fit", tmp_path / "mislabelled.csv", "--out", tmp_path / "a.csv", "--json").stdout)["warnings"]
    assert len(warned) == 1 and "softer than any milling tool tip" in warned[0] and "quantity" in warned[0]
    assert json.loads(run_cli("fit", tmp_path / "acc.csv", "--out", tmp_path / "b.csv", "--json").stdout)["warnings"] == []
    # without a pose in any file, the table's poses are all at the origin: fit says so (a new user's table came out so silently)
    (tmp_path / "nopose.csv").write_text("\n".join(line for line in text.splitlines() if not line.startswith(("# x_mm", "# y_mm", "# z_mm", "# beta_deg"))) + "\n")
    warned = json.loads(run_cli("fit", tmp_path / "nopose.csv", "--out", tmp_path / "c.csv", "--json").stdout)["warnings"]
    assert len(warned) == 1 and "no file gives its pose" in warned[0] and "# x_mm" in warned[0]


@pytest.mark.parametrize("top_hz, above", [(3000.0, (3600.0, 0.02, 3e7)), (3000.0, (5000.0, 0.02, 3e7)), (2000.0, (2200.0, 0.02, 6e7))])
def test_a_mode_just_above_the_measured_band_leaves_the_stiffnesses_alone(top_hz, above):
    """A spindle or tool mode above the measured band (1-3000 Hz and a mode at 3.6 or 5 kHz;
    1-2000 Hz and one at 2.2 kHz) is not constant over it and shifts the antiresonances, which
    the relative LSFD weights count up to 1000x. With a constant upper residual alone that misfit
    went into the residues: k 16 % low for both robot modes and 31 % high for the 2.2 kHz one
    (10 % and 11 % with the mode at 5 kHz). With the upper pseudo-mode (its frequency fitted),
    every k within 1.5 % (2 % noise)."""
    rng = np.random.default_rng(5)
    f = np.linspace(1.0, top_hz, 6000)
    true = [m for m in [(9.0, 0.04, 3e6), (21.0, 0.03, 8e6), (1500.0, 0.03, 4e7), (2200.0, 0.02, 6e7)] if m[0] < top_hz]
    found = direct_modal_parameters(f, noisy(receptance(f, true + [above]), rng), 1.0, top_hz)
    assert len(found) == len(true)
    for (fn, zeta, k), got in zip(true, found):
        assert got["fn_hz"] == pytest.approx(fn, rel=0.005)
        assert got["k_n_per_m"] == pytest.approx(k, rel=0.015)
