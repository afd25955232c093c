"""Milling stability: the cut and its force matrices (`cutting`), semi-discretization (`sdm`),
zeroth-order approximation (`zoa`), critical depths, lobes and chatter frequencies of one
structure (`model`) and of many at one speed (`batch`), the converged engine on the exact
Floquet characteristic equation (`floquet`), the one entry point for user-facing numbers
(`critical`), the no-growth depth where only the surface remembers the last pass (`surface`),
time-domain check (`timesim`) and the published reference cases (`reference`)."""

from posedyn.stability.batch import BatchStability
from posedyn.stability.critical import (
    REL_TOL, SURFACE_MEMORY_EFOLDS, AbsoluteLimit, StabilityResult, absolute_limit, critical_lobes, critical_points, free_flight_decay,
    modes_carrying_over,
)
from posedyn.stability.cutting import Cut, force_matrix, interval_force_matrices, mean_force_matrix
from posedyn.stability.model import CriticalDepths, Discretization, StabilityModel, chatter_frequencies

__all__ = [
    "REL_TOL",
    "AbsoluteLimit",
    "StabilityResult",
    "absolute_limit",
    "critical_lobes",
    "critical_points",
    "free_flight_decay",
    "modes_carrying_over",
    "SURFACE_MEMORY_EFOLDS",
    "BatchStability",
    "Cut",
    "CriticalDepths",
    "Discretization",
    "StabilityModel",
    "chatter_frequencies",
    "force_matrix",
    "interval_force_matrices",
    "mean_force_matrix",
]
