"""A pose's modal parameters as a probability distribution, and samples of its dynamics.

Every positive modal parameter is modelled in logs (the pose model's convention), so one pose's
modes are a joint normal of ln fn, ln zeta, ln k over its rows:

    y = (ln fn_1, ln zeta_1, ln k_1, ln fn_2, ...) ~ N(mu, S)

From a trained pose model, mu and S are its latent predictive mean and covariance (a multi-task
model's groups bring the correlations between their targets, seed 003 eq. 28; a physics prior
shifts mu only). From a modal table with std columns, the rows are independent log-normals with
the table's mean m and std s: ln-variance ln(1 + s^2 / m^2), ln-median ln m minus half of it.
Cross stiffnesses (k_xy, k_yx) stay at their means.

Samples are Latin-hypercube (scipy.stats.qmc) draws of independent standard normals (inverse
CDF on each stratum, clipped at 4.5 std), correlated by a square root of S (seed 002 section 4's
sampling, with the pose model's distribution in place of its Table 3).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.stats import norm, qmc

from posedyn.dynamics import ToolTipDynamics
from posedyn.errors import InputError, check_positive
from posedyn.table import MODAL_PARAMS as PARAMS, ModalTable

#: Variances below this (ln units^2, a 0.01 % spread) are treated as certain and not sampled.
CERTAIN_LOG_VAR = 1e-8


@dataclass(frozen=True, eq=False)
class ModalDistribution:
    """One pose's modes: `table` (one pose; its means and cross columns), the ln-medians
    (rows, 3) in PARAMS order and their covariance (3 rows, 3 rows), index 3 row + param."""

    table: ModalTable
    log_median: np.ndarray
    log_cov: np.ndarray

    def __post_init__(self):
        rows = len(self.table)
        if len(self.table.poses) != 1 or np.shape(self.log_median) != (rows, 3) or np.shape(self.log_cov) != (3 * rows, 3 * rows):
            raise InputError(f"one pose, ln-medians ({rows}, 3) and their covariance ({3 * rows}, {3 * rows})",
                             got=(len(self.table.poses), np.shape(self.log_median), np.shape(self.log_cov)))

    @property
    def pose_id(self) -> str:
        return self.table.poses.pose_id[0]

    @property
    def log_std(self) -> np.ndarray:
        """Standard deviations of the logs, (rows, 3): about the relative spreads."""
        return np.sqrt(np.maximum(np.diag(self.log_cov), 0.0)).reshape(-1, 3)

    def sample_values(self, n: int, seed: int = 0) -> np.ndarray:
        """(n, rows, 3) Latin-hypercube samples of (fn_hz, zeta, k_n_per_m), zeta below 0.999."""
        check_positive("samples", n)
        mean = self.log_median.reshape(-1)
        uncertain = np.flatnonzero(np.diag(self.log_cov) > CERTAIN_LOG_VAR)
        logs = np.tile(mean, (n, 1))
        if len(uncertain):
            cov = self.log_cov[np.ix_(uncertain, uncertain)]
            lam, vec = np.linalg.eigh(0.5 * (cov + cov.T))
            root = vec * np.sqrt(np.maximum(lam, 0.0))  # root @ root.T = cov (positive semi-definite safe)
            z = np.clip(norm.ppf(qmc.LatinHypercube(d=len(uncertain), seed=seed).random(n)), -4.5, 4.5)
            logs[:, uncertain] += z @ root.T
        values = np.exp(logs).reshape(n, -1, 3)
        values[:, :, 1] = np.minimum(values[:, :, 1], 0.999)
        return values

    def sample_dynamics(self, n: int, seed: int = 0) -> list[ToolTipDynamics]:
        """The tool-tip dynamics of n samples (`ToolTipDynamics.from_table` of each)."""
        return [ToolTipDynamics.from_table(replace(self.table, fn_hz=v[:, 0], zeta=v[:, 1], k_n_per_m=v[:, 2])) for v in self.sample_values(n, seed)]


def distributions_from_table(table: ModalTable) -> list[ModalDistribution]:
    """Independent log-normals from a table's std columns (no std: a certain parameter), one
    distribution per pose."""
    out = []
    for p in range(len(table.poses)):
        one = table.select_poses([p])
        mean = np.stack([getattr(one, name) for name in PARAMS], axis=1)
        std = np.stack([np.nan_to_num(one.std.get("std_" + name, np.zeros(len(one))), nan=0.0) for name in PARAMS], axis=1)
        log_var = np.log1p((std / mean) ** 2)
        out.append(ModalDistribution(one, np.log(mean) - 0.5 * log_var, np.diag(log_var.reshape(-1))))
    return out
