"""Where the residual that no named effect explains lives (issue 18 item 4): a smooth map of the
normalised residual over the pose and the conditions, with its uncertainty.

A Gaussian process with one length scale per variable (ARD: constant x RBF + white noise) is
fitted to the normalised residual r = (value - prediction) / std of one quantity's rows over the
pose columns and conditions that vary there. A variable the residual does not follow gets a long
length scale; the map is drawn over the two with the shortest ones relative to their spread
(one when only one varies), the others held at their median. The white-noise level is the part
of r the map does not explain (1 for residual noise of the stated std)."""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from sklearn.exceptions import ConvergenceWarning
from sklearn.gaussian_process import GaussianProcessRegressor
from sklearn.gaussian_process.kernels import RBF, ConstantKernel, WhiteKernel

@dataclass(frozen=True)
class DiscrepancyMap:
    quantity: str
    variables: tuple[str, ...]  # every variable of the fit
    relevance: tuple[float, ...]  # spread / length scale per variable: large = the residual follows it
    axes: dict  # {variable: grid values} of the one or two mapped variables
    mean: np.ndarray  # normalised residual on the grid (stds), shape of the axes
    std: np.ndarray  # its posterior std
    signal_std: float  # the map's own scale (stds)
    noise_std: float  # what it leaves (stds)

    def to_json(self) -> dict:
        return {"quantity": self.quantity, "variables": list(self.variables), "relevance": list(self.relevance),
                "axes": {k: v.tolist() for k, v in self.axes.items()}, "mean": self.mean.tolist(), "std": self.std.tolist(),
                "signal_std": self.signal_std, "noise_std": self.noise_std}


def discrepancy_map(m, residual: np.ndarray, quantity: str, points: int = 15, seed: int = 0, restarts: int = 0) -> DiscrepancyMap | None:
    """The map of `residual` (normalised) over the rows of `quantity` (module docstring); None
    when fewer than 8 rows or nothing varies."""
    rows = np.flatnonzero(m.quantity == quantity)
    if len(rows) < 8:
        return None
    names, columns = [], []
    for name, values in m.conditions.items():
        if name.startswith("model_"):  # the model's own context, not a variable of the test
            continue
        v = values[rows]
        if np.all(np.isfinite(v)) and np.ptp(v) > 0:
            names.append(name)
            columns.append(v)
    if not names:
        return None
    X = np.column_stack(columns)
    centre, spread = X.mean(axis=0), X.std(axis=0)
    Z = (X - centre) / spread
    y = residual[rows]
    kernel = ConstantKernel(1.0, (1e-4, 1e4)) * RBF(np.ones(len(names)), (0.05, 100.0)) + WhiteKernel(1.0, (1e-3, 1e3))
    with warnings.catch_warnings():  # length scales of variables the residual ignores end on their upper bound, as they should
        warnings.simplefilter("ignore", ConvergenceWarning)
        gp = GaussianProcessRegressor(kernel, normalize_y=False, n_restarts_optimizer=restarts, random_state=seed).fit(Z, y)
    k = gp.kernel_
    lengths = np.atleast_1d(k.k1.k2.length_scale)
    relevance = 1.0 / lengths  # in units of each variable's spread
    mapped = [int(i) for i in np.argsort(-relevance)[: min(2, len(names))]]
    axes = {names[i]: np.linspace(X[:, i].min(), X[:, i].max(), points) for i in mapped}
    mesh = np.meshgrid(*axes.values(), indexing="ij")
    grid = np.tile(np.median(Z, axis=0), (mesh[0].size, 1))
    for j, i in enumerate(mapped):
        grid[:, i] = (mesh[j].ravel() - centre[i]) / spread[i]
    mean, std = gp.predict(grid, return_std=True)
    shape = mesh[0].shape
    return DiscrepancyMap(quantity, tuple(names), tuple(float(r) for r in relevance), axes, mean.reshape(shape), std.reshape(shape),
                          float(np.sqrt(k.k1.k1.constant_value)), float(np.sqrt(k.k2.noise_level)))
