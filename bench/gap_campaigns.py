"""Issue 18's twin-level campaign kinds scored over 20 seeds (the tests run 2-3 seeds of each: an
analysis with the twin's candidates takes 3-15 s). The campaigns are tests/test_gap_statistics.py's
`twin_campaign`: the twin's own physics changed (its modes recomputed), not the library's effect
functions. Prints, per kind, how many seeds got the right verdict, the fitted parameters' range,
the RMS after and the time per analysis.

    .venv/bin/python bench/gap_campaigns.py [--seeds 20] [--workers 2]
"""

from __future__ import annotations

import argparse
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

KINDS = {
    "7 kg device on the flange": dict(mass_kg=7.0),
    "axis 2 x0.7, axis 3 x1.25": dict(joint_scale=(1.0, 0.7, 1.25, 1.0, 1.0, 1.0)),
    "joints softer under gravity, 0.1 per kN m": dict(gravity_per_knm=0.1),
    "0.2 kg sensor at the tool tip": dict(sensor_kg=0.2),
    "nothing hidden": dict(),
}


def right(kind: str, result) -> bool:
    names = sorted(e["name"] for e in result.effects)
    fitted = {e["name"]: next(iter(e["parameters"].values())) for e in result.effects}
    close = result.rmse_after <= 1.5 * max(result.noise_std, 1.0)
    if kind.startswith("7 kg"):
        return names == ["flange_device"] and abs(fitted["flange_device"] - 7.0) <= 0.7 and close
    if kind.startswith("axis"):
        return (names == ["joint_stiffness_a2", "joint_stiffness_a3"] and abs(2 ** fitted["joint_stiffness_a2"] / 0.7 - 1) <= 0.1
                and abs(2 ** fitted["joint_stiffness_a3"] / 1.25 - 1) <= 0.1 and close)
    if kind.startswith("0.2 kg sensor"):
        return names == ["sensor_mass"] and abs(fitted["sensor_mass"] / 0.2 - 1) <= 0.1 and close
    if kind.startswith("joints softer"):
        return names == ["gravity_softening"] and abs(fitted["gravity_softening"] / 0.1 - 1) <= 0.1 and close
    return not names and not result.ambiguous


def one(job):
    kind, seed = job
    from posedyn.gap import analyse
    from test_gap_statistics import twin_campaign

    nominal, m, y = twin_campaign(seed, **KINDS[kind])
    start = time.perf_counter()
    result = analyse(m, y, library=nominal.library())
    return kind, seed, right(kind, result), result, time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    jobs = [(kind, seed) for kind in KINDS for seed in range(args.seeds)]
    with ProcessPoolExecutor(args.workers) as pool:
        done = list(pool.map(one, jobs))
    for kind in KINDS:
        rows = [d for d in done if d[0] == kind]
        params = {}
        for _, _, _, r, _ in rows:
            for e in r.effects:
                params.setdefault(e["name"], []).append(next(iter(e["parameters"].values())))
        wrong = [f"seed {s}: {[e['name'] for e in r.effects] or 'none'}{' undecided ' + str(r.ambiguous[0]['candidates']) if r.ambiguous else ''}"
                 for _, s, ok, r, _ in rows if not ok]
        print(f"{kind}: right in {sum(d[2] for d in rows)} of {len(rows)} seeds; RMS after {min(d[3].rmse_after for d in rows):.2f}-"
              f"{max(d[3].rmse_after for d in rows):.2f}; {min(d[4] for d in rows):.1f}-{max(d[4] for d in rows):.1f} s an analysis")
        for name, values in sorted(params.items()):
            print(f"    {name}: {len(values)} x, {min(values):.4g} .. {max(values):.4g}")
        for w in wrong:
            print("    wrong: " + w)


if __name__ == "__main__":
    main()
