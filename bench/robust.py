"""Monte Carlo of the stability limit under host uncertainty (issue 23, seed 002 section 4).

Prints the time of 500 Latin-hypercube samples at one spindle speed for seed 002's host with a
TMD (a 2-mode structure) and with IDVA-C6 (3 modes), vectorised over the samples, beside the
same samples computed one at a time through the same zeroth-order functions (the baseline,
measured in this run), and the coefficients of variation against the seed's. Target: <= 0.5 s
per 500 samples.

    .venv/bin/python bench/robust.py
"""

from __future__ import annotations

import time

import numpy as np

from absorber.files import read_host
from absorber.robust import HostUncertainty, monte_carlo_limits
from absorber.tuning import tune_sims
from posedyn.io.shipped import DATASETS


def best_of(runs: int, function) -> tuple[float, object]:
    times, result = [], None
    for _ in range(runs):
        start = time.perf_counter()
        result = function()
        times.append(time.perf_counter() - start)
    return min(times), result


def main() -> None:
    case = read_host(DATASETS / "seeds/dogan2024_host_milling.toml")
    uncertainty, cut, mu = case.uncertainty, case.cut, case.mass_ratio
    print(f"seed 002 host, mu = {mu}, 2700 rpm, 500 samples (best of 3):")
    for layout, seed_cv in (("tmd", 13.8), ("idva-c6", 10.2)):
        tuned = tune_sims(layout, mu, uncertainty.nominal.zeta)
        fast, stats = best_of(3, lambda: monte_carlo_limits(uncertainty, tuned, cut, [2700.0], samples=500, seed=0))
        k, fn, zeta = uncertainty.sample(500, 0)

        def one_by_one():
            out = []
            for i in range(500):
                single = HostUncertainty(type(uncertainty.nominal)(fn[i], k[i], zeta[i]), 0.0, 0.0, 0.0)
                out.append(monte_carlo_limits(single, tuned, cut, [2700.0], samples=2, method="zoa").mean_m[0])
            return np.array(out)

        slow, _ = best_of(1, one_by_one)
        print(f"  {layout:8s} vectorised {fast:.3f} s (target <= 0.5 s), one sample at a time {slow:.3f} s, ratio {slow / fast:.1f}x; "
              f"cv {100 * stats.cv[0]:.2f} % (seed {seed_cv} %), 95 % lower bound {stats.lower95_m[0] * 1e3:.3f} mm, method {stats.method[0]}"
              + (" (checked against the engine on the nominal host, in the time)" if layout == "tmd" else " (no engine model: unchecked)"))


if __name__ == "__main__":
    main()
