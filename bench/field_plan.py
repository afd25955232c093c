"""Coil-current planning (issue 21): a 1,000-point plan, and a warm-started re-plan of the
horizon shifted by 10 nodes beside a cold re-plan of the same horizon (the baseline, measured in
this run). Targets: <= 2 s for the plan, <= 0.2 s for the warm re-plan.

    .venv/bin/python bench/field_plan.py
"""

from __future__ import annotations

import time

import numpy as np

from absorber.field_plan import FieldPlanner


def main() -> None:
    n = 1000
    t = np.linspace(0.0, 100.0, n + 1)  # a node every 0.1 s: poses along a 100 s path
    target = 18.0 + 10.0 * np.sin(t / 5.0) ** 2 + 15.0 * (np.floor(t / 7.0) % 2)
    start = time.perf_counter()
    planner = FieldPlanner(n)
    plan = planner.solve(t, target)
    first = time.perf_counter() - start
    print(f"{n}-point plan (build + solve): {first:.2f} s (target <= 2 s), {plan.solver['iterations']} IPOPT iterations, {plan.solver['status']}")
    warm_times, cold_times = [], []
    for step in range(1, 4):
        shifted = np.r_[target[10 * step :], np.full(10 * step, target[-1])]
        state = (plan.field_t[10], plan.fluid_field_t[10], plan.temperature_c[10])
        start = time.perf_counter()
        nxt = planner.solve(t + step, shifted, initial_state=state, warm=plan.shifted(10))
        warm_times.append(time.perf_counter() - start)
        start = time.perf_counter()
        FieldPlanner(n).solve(t + step, shifted, initial_state=state)
        cold_times.append(time.perf_counter() - start)
        plan = nxt
    warm, cold = min(warm_times[1:]), min(cold_times)
    print(f"re-plan of the horizon shifted by 10 nodes: warm {warm:.3f} s (target <= 0.2 s; the first warm one {warm_times[0]:.3f} s switches IPOPT's options), "
          f"cold {cold:.3f} s, ratio {cold / warm:.1f}x")


if __name__ == "__main__":
    main()
