"""`posedyn train` and `posedyn predict`: the pose -> modal-parameter model."""

from __future__ import annotations

from enum import Enum
from pathlib import Path
from typing import Optional

import numpy as np
import typer
from rich.table import Table

from posedyn.errors import InputError
from posedyn.io import concat_tables, read_modal_table, read_pose_table, write_modal_table
from posedyn.io.atomic import write_text_atomic
from posedyn.io.cut import read_cut
from posedyn.io.model_dir import check_model_target, load_model, save_model
from posedyn.io.twin_file import load_twin
from posedyn.posemodel import PoseModel, check_folds, cross_validate
from posedyn.posemodel import r2_score, suspect_measurements, table_targets
from posedyn.posemodel.model import MODE_MATCH_FN, MODE_MATCH_K
from service.cli.common import console, output_file, print_json
from service.cli.inputs import warn_outside_workspace


class Method(str, Enum):
    stgp = "stgp"
    mtgp = "mtgp"
    physics = "physics"


def train(
    files: list[Path] = typer.Argument(..., help="Modal-test tables (CSV)."),
    out: Path = typer.Option(..., "--out", help="Model directory to write."),
    method: Method = typer.Option(Method.stgp, "--method", help="stgp, mtgp (coregionalized groups) or physics (twin prior + GP residual)."),
    features: Optional[str] = typer.Option(None, "--features", help="Comma-separated pose columns (default: the ones that vary)."),
    cv: int = typer.Option(5, "--cv", help="k-fold cross-validation over poses (0: none)."),
    holdout: Optional[Path] = typer.Option(None, "--holdout", help="External hold-out table to score."),
    seed: int = typer.Option(0, "--seed", help="Random seed (restarts, folds)."),
    restarts: int = typer.Option(1, "--restarts", min=0, help="Seeded restarts of the hyperparameter optimisation (0: the default start only)."),
    twin: Optional[Path] = typer.Option(None, "--twin", help="Twin file for --method physics (default: the shipped KR R2700 twin)."),
    cut: Optional[Path] = typer.Option(None, "--cut", help="A cut file the model directory carries as its default cut (MODEL_DIR/cut.toml)."),
    as_json: bool = typer.Option(False, "--json", help="Print JSON."),
):
    """Train a pose -> modal-parameter model and cross-validate it."""
    check_model_target(out)  # before training: refused after it would waste the wait
    if cut is not None:
        read_cut(cut)  # validate before training
    table = concat_tables([read_modal_table(f) for f in files])
    test = read_modal_table(holdout) if holdout is not None else None  # before training: an error after it left the model written
    names = [c.strip() for c in features.split(",")] if features else None
    robot_twin = load_twin(twin) if method is Method.physics else None
    if cv:
        check_folds(cv, len(table.poses))  # before anything is written (a refused --cv had replaced the model)

    def make():
        return PoseModel(method.value, names, n_restarts=restarts, random_state=seed, twin=robot_twin)

    model = make().fit(table)
    report = {"method": method.value, "n_poses": len(table.poses), "cv": {}, "suspects": suspect_measurements(model, table)}
    if cv:
        report["cv"] = cross_validate(make, table, folds=cv, seed=seed)
    if test is not None:
        names_h, Y = table_targets(test)
        predicted = model.predict(test.poses)
        report["holdout"] = {
            t: {"r2": r2_score(predicted[:, model.targets_.index(t)], Y[:, j]), "rmse": float(((predicted[:, model.targets_.index(t)] - Y[:, j]) ** 2).mean() ** 0.5)}
            for j, t in enumerate(names_h)
            if t in model.targets_
        }
    save_model(model, out)  # once everything that can fail has run
    if cut is not None:
        write_text_atomic(out / "cut.toml", cut.read_text(encoding="utf-8"))
    if model.physics_ is not None:
        report["physics"] = {k: v for k, v in model.physics_.items() if k in ("used", "reason", "stiffness_scales", "fit_converged", "mode_map", "modes_without_prior",
                                                                           "targets_without_prior")}
    if as_json:
        print_json(report)
        return
    console.print(f"trained {method.value} on {len(table.poses)} poses ({len(model.targets_)} targets, features {', '.join(model.features_)}); wrote {out}")
    if model.physics_ is not None:
        console.print(f"physics prior: {report['physics']}")
        if model.physics_.get("modes_without_prior"):
            console.print(f"note: the twin has no mode within {MODE_MATCH_FN:g}x in frequency and {MODE_MATCH_K:g}x in stiffness of "
                          f"{', '.join(model.physics_['modes_without_prior'])}: "
                          "those modes are learned without the prior (as stgp)")
        if model.physics_.get("targets_without_prior"):
            console.print(f"note: the twin's values of {', '.join(model.physics_['targets_without_prior'])} vary more over the training poses than the "
                          "measurements (a mode shape turning away from the direction): learned without the prior")
    if report["cv"]:
        t = Table(title=f"{cv}-fold cross-validation over poses", title_justify="left")
        for c in ("target", "R2 mean", "R2 std", "R2 pooled", "RMSE", "errors in stds (rms)"):
            t.add_column(c, justify="right")
        notes = set()
        for name, v in report["cv"].items():
            t.add_row(name, *("-" if v[k] is None else f"{v[k]:.4f}" for k in ("r2_mean", "r2_std", "r2_pooled")), f"{v['rmse']:.4g}",
                      "-" if v["z_rms"] is None else f"{v['z_rms']:.3g}")
            notes.update([v["note"].split(":")[0]] if "note" in v else [])
        console.print(t)
        over = [name for name, v in report["cv"].items() if v["z_rms"] is not None and v["z_rms"] > 2.0]
        if over:
            console.print(f"note: the predictive distribution of {', '.join(over[:6])}{' ...' if len(over) > 6 else ''} was too narrow on the held-out poses "
                          "(their errors more than 2 stds rms, the fitted measurement noise included): read those stds, and what --robust draws from them, as a lower bound")
        for note in sorted(notes):
            console.print(f"note: {note} (see --json)")
    if "holdout" in report:
        t = Table(title=f"hold-out table {holdout} ({len(test.poses)} poses)", title_justify="left")
        for c in ("target", "R2", "RMSE"):
            t.add_column(c, justify="right")
        for name, v in report["holdout"].items():
            t.add_row(name, "-" if v["r2"] is None or not np.isfinite(v["r2"]) else f"{v['r2']:.4f}", f"{v['rmse']:.4g}")
        console.print(t)
    if report["suspects"]:
        shown = report["suspects"][:10]
        t = Table(title=f"measurements far from what the other poses say (leave-one-pose-out; {len(report['suspects'])} beyond a 1 % familywise threshold)",
                  title_justify="left")
        for c in ("pose", "target", "measured", "from the others", "stds"):
            t.add_column(c, justify="right")
        for s in shown:
            t.add_row(s["pose_id"], s["target"], f"{s['measured']:.4g}", f"{s['loo_predicted']:.4g}", f"{s['z']:+.1f}")
        console.print(t)
        console.print("note: check these tests (a mode taken for another, a bad fit) before trusting the model there; a stiffness far above the "
                      "pose's others is a mode that hardly moves the tool that way, not a bad measurement" + (" (--json lists all)" if len(shown) < len(report["suspects"]) else ""))


def predict(
    model_dir: Path = typer.Argument(..., help="Model directory from posedyn train."),
    poses: Path = typer.Option(..., "--poses", help="CSV with the pose columns of the modal-table format."),
    out: Optional[Path] = typer.Option(None, "--out", help="Write the predictions as a modal table (with std_* columns)."),
    as_json: bool = typer.Option(False, "--json", help="Print JSON."),
):
    """Predict tool-tip modes (with std) at poses."""
    output_file(out, "--out")
    model = load_model(model_dir)
    pose_set = read_pose_table(poses)
    warn_outside_workspace(model, pose_set)
    try:
        table = model.predict_table(pose_set)
    except InputError as exc:
        raise exc.located(file=str(poses)) from None
    if out is not None:
        write_modal_table(table, out)
    if as_json:
        result = []
        for p, pose_id in enumerate(pose_set.pose_id):
            rows = [i for i in range(len(table)) if table.pose_index[i] == p]
            result.append(
                {
                    "pose_id": pose_id,
                    "modes": [
                        {
                            "direction": str(table.direction[i]),
                            "mode": int(table.mode[i]),
                            "fn_hz": float(table.fn_hz[i]),
                            "std_fn_hz": float(table.std["std_fn_hz"][i]),
                            "zeta": float(table.zeta[i]),
                            "std_zeta": float(table.std["std_zeta"][i]),
                            "k_n_per_m": float(table.k_n_per_m[i]),
                            "std_k_n_per_m": float(table.std["std_k_n_per_m"][i]),
                        }
                        for i in rows
                    ],
                }
            )
        print_json(result)
        return
    t = Table(title=f"predicted modes ({model.method})", title_justify="left")
    for c in ("pose_id", "mode", "fn_hz", "zeta", "k_n_per_m"):
        t.add_column(c, justify="right")
    for i in range(len(table)):
        s = table.std
        t.add_row(
            pose_set.pose_id[table.pose_index[i]],
            f"{table.direction[i]}{table.mode[i]}",
            f"{table.fn_hz[i]:.4g} +- {s['std_fn_hz'][i]:.2g}",
            f"{table.zeta[i]:.3g} +- {s['std_zeta'][i]:.2g}",
            f"{table.k_n_per_m[i]:.4g} +- {s['std_k_n_per_m'][i]:.2g}",
        )
    console.print(t)
    if out is not None:
        console.print(f"wrote {out}")
