"""Milling stability: the cut and its force matrices (`cutting`), semi-discretization (`sdm`),
zeroth-order approximation (`zoa`), critical depths, lobes and chatter frequencies of one
structure (`model`) and of many at one speed (`batch`), time-domain check (`timesim`) and the
published reference cases (`reference`)."""

from posedyn.stability.batch import BatchStability
from posedyn.stability.cutting import Cut, force_matrix, interval_force_matrices, mean_force_matrix
from posedyn.stability.model import CriticalDepths, Discretization, StabilityModel, chatter_frequencies

__all__ = [
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
