"""Milling stability: semi-discretization (`sdm`), zeroth-order approximation (`zoa`),
critical depths and chatter frequencies (`chatter`), time-domain check (`timesim`)."""

from posedyn.stability.chatter import CriticalDepths, Discretization, StabilityModel, chatter_frequencies
from posedyn.stability.cutting import Cut, force_matrix, interval_force_matrices, mean_force_matrix

__all__ = [
    "Cut",
    "CriticalDepths",
    "Discretization",
    "StabilityModel",
    "chatter_frequencies",
    "force_matrix",
    "interval_force_matrices",
    "mean_force_matrix",
]
