"""Exact Gaussian processes with an intrinsic-coregionalization (ICM) kernel.

For T tasks observed at the same n inputs x (standardised pose features) the covariance is

    K = B (x) Kx + S (x) I,   Kx[i, j] = exp(-sum_d (x_id - x_jd)^2 / (2 l_d^2)),   B = L L^T,

with S = diag(sigma_t^2) the task noise variances (seed 003 eq. 28: task covariance Kronecker
pose covariance, the task covariance through its Cholesky factor L). One task is the ordinary
single-task GP with an anisotropic RBF (amplitude L_00^2) and white noise.

Every task is observed at every pose (a modal test identifies all modes at a pose), so the
Kronecker structure is exact and K is never formed: with S^-1/2 B S^-1/2 = Q diag(lam) Q^T,
Kx = V diag(e) V^T and P = S^-1/2 Q,

    K^-1 = (P (x) V) diag(1 / (lam_i e_j + 1)) (P (x) V)^T,   log|K| = sum log(lam_i e_j + 1) + n sum log sigma_t^2,

so the likelihood costs one n x n eigendecomposition instead of an (nT) x (nT) Cholesky.

Hyperparameters are unconstrained reals (log length scales, the Cholesky factor with its
diagonal in log, log noise variances), fitted by maximising the log marginal likelihood with its
analytic gradient (L-BFGS-B) from several seeded starting points. Written here rather than on
scikit-learn's kernel API because scikit-learn optimises every hyperparameter in log space
(positive only), which cannot hold the signed off-diagonal Cholesky entries the ICM needs; the
single-task case is checked against scikit-learn's GaussianProcessRegressor in the tests, and the
Kronecker likelihood and gradient against the dense formulas.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.optimize
from threadpoolctl import threadpool_limits

LOG_2PI = np.log(2.0 * np.pi)
#: Kernel values are floored at exp(-LOG_K_FLOOR) (5e-131) in predictions (no subnormals).
LOG_K_FLOOR = 300.0


@dataclass(frozen=True, eq=False)
class GP:
    """A fitted GP: hyperparameters `theta`, training inputs X (n, D), targets Y (n, T)."""

    theta: np.ndarray
    X: np.ndarray
    Y: np.ndarray

    @property
    def n_tasks(self) -> int:
        return self.Y.shape[1]

    @property
    def length_scales(self) -> np.ndarray:
        return np.exp(self.theta[: self.X.shape[1]])

    @property
    def task_covariance(self) -> np.ndarray:
        L = cholesky_factor(self.theta, self.X.shape[1], self.n_tasks)
        return L @ L.T

    @property
    def noise_variances(self) -> np.ndarray:
        return np.exp(self.theta[-self.n_tasks :])

    def predict(self, X: np.ndarray, return_std: bool = False):
        """Latent mean (m, T), and std without the observation noise, at inputs X (m, D)
        (a `Predictor` kept with the GP)."""
        cached = self.__dict__.get("_predictor")
        if cached is None:
            cached = Predictor.of([self])
            object.__setattr__(self, "_predictor", cached)
        return cached.predict(X, return_std)

    def log_marginal_likelihood(self) -> float:
        return -nll_kron(self.theta, self.X, self.Y)[0]


@dataclass(frozen=True)
class Predictor:
    """Posterior of several fitted GPs on the same training inputs (a model's groups), with
    everything that does not depend on the query precomputed. For one GP (B, P, V, Dinv of the
    Kronecker solve in the module docstring, b_t the t-th column of B, alpha = K^-1 y):

        mean_t(x) = sum_s B_ts kx(x)^T alpha_s,
        var_t(x)  = B_tt - sum_ij (P^T b_t)_i^2 Dinv_ij ((V^T kx(x))_j)^2.

    Per block of queries: the kernels of all g GPs by one stacked product with the scaled
    training inputs and one exp, one stacked (g, m, n) @ (g, n, n) product for V^T kx, and thin
    contractions for the means and variances (t: the largest group's tasks)."""

    scaled_train: np.ndarray  # (g, D, n): x_i / l^2 per GP
    half_norm_train: np.ndarray  # (g, 1, n): |x_i / l|^2 / 2
    half_inv_l2: np.ndarray  # (D, g): 1 / (2 l^2)
    eigvecs: np.ndarray  # (g, n, n): V
    mean_weights: np.ndarray  # (g, n, t): alpha^T B, zero-padded to t tasks
    reduction: np.ndarray  # (g, n, t): sum_i (P^T b_t)_i^2 Dinv_ij, zero-padded
    slots: np.ndarray  # (T,): position in the (g t) flattened outputs of every output column
    prior_var: np.ndarray  # (T,) diag B
    task_factor: np.ndarray  # (g, t, t): P^T B, zero-padded (for covariances between tasks)
    dinv: np.ndarray  # (g, t, n): Dinv, zero-padded
    task_cov: np.ndarray  # (g, t, t): B, zero-padded

    #: Query rows per block: about this many kernel entries (g x rows x n) at a time.
    BLOCK_ENTRIES = 1_000_000

    @classmethod
    def of(cls, gps: list["GP"], columns: list[list[int]] | None = None) -> "Predictor":
        """`columns[k]`: the output columns of GP k's tasks (default: one after another)."""
        if columns is None:
            starts = np.cumsum([0] + [gp.n_tasks for gp in gps])
            columns = [list(range(starts[k], starts[k + 1])) for k in range(len(gps))]
        X = gps[0].X
        (n, D), g, t = X.shape, len(gps), max(gp.n_tasks for gp in gps)
        T = 1 + max(max(c) for c in columns)
        scaled, half, inv_l2 = np.empty((g, D, n)), np.empty((g, 1, n)), np.empty((D, g))
        V_all, mean_w, red = np.empty((g, n, n)), np.zeros((g, n, t)), np.zeros((g, n, t))
        factor, dinv, task_cov = np.zeros((g, t, t)), np.zeros((g, t, n)), np.zeros((g, t, t))
        slots, prior_var = np.full(T, -1), np.zeros(T)
        for k, (gp, cols) in enumerate(zip(gps, columns)):
            if gp.X is not X and not np.array_equal(gp.X, X):
                raise ValueError("stacked GPs must share their training inputs")
            tk = gp.n_tasks
            P, _, V, _, Dinv, B, _ = _factor(gp.theta, X, tk)
            alpha = P @ (Dinv * (P.T @ gp.Y.T @ V)) @ V.T  # (tk, n)
            il2 = np.exp(-2.0 * gp.theta[:D])
            scaled[k], half[k, 0], inv_l2[:, k] = (X * il2).T, 0.5 * np.sum(X * X * il2, axis=1), il2
            V_all[k], mean_w[k, :, :tk] = V, alpha.T @ B
            red[k, :, :tk] = (((P.T @ B) ** 2).T @ Dinv).T
            factor[k, :tk, :tk], dinv[k, :tk], task_cov[k, :tk, :tk] = P.T @ B, Dinv, B
            slots[cols] = k * t + np.arange(tk)
            prior_var[cols] = np.diag(B)
        if np.any(slots < 0):
            raise ValueError("every output column needs a GP")
        return cls(scaled, half, 0.5 * inv_l2, V_all, mean_w, red, slots, prior_var, factor, dinv, task_cov)

    def _kernels(self, x: np.ndarray) -> np.ndarray:
        """k(x, X_train) of every GP, (g, rows, n)."""
        # -|x - y|^2 / (2 l^2) = x.(y / l^2) - |x / l|^2 / 2 - |y / l|^2 / 2, at most 0
        log_k = np.matmul(x, self.scaled_train)  # (g, rows, n)
        log_k -= ((x * x) @ self.half_inv_l2).T[:, :, None]
        log_k -= self.half_norm_train
        # floored at exp(-LOG_K_FLOOR): subnormal numbers (a query far from the data in some
        # GP's length scales) slow every product that follows ~5x
        return np.exp(np.clip(log_k, -LOG_K_FLOOR, 0.0, out=log_k), out=log_k)

    def predict_cov(self, X: np.ndarray) -> np.ndarray:
        """Latent covariance between the outputs at each input, (m, T, T), without the
        observation noise: zero between GPs; within a GP of several tasks (b_t: column t of B)

            cov_tu(x) = B_tu - sum_i (P^T b_t)_i (P^T b_u)_i sum_j Dinv_ij ((V^T kx(x))_j)^2,

        whose diagonal is `predict`'s variance."""
        X = np.asarray(X, dtype=float)
        g, t, _ = self.task_factor.shape
        w = np.matmul(self._kernels(X), self.eigvecs)  # (g, m, n)
        d = np.einsum("gmn,gin->gmi", w * w, self.dinv)  # (g, m, t)
        cov = self.task_cov[:, None] - np.einsum("git,gmi,giu->gmtu", self.task_factor, d, self.task_factor)
        full = np.zeros((len(X), g * t, g * t))
        for k in range(g):
            full[:, k * t : (k + 1) * t, k * t : (k + 1) * t] = cov[k]
        return full[:, self.slots][:, :, self.slots]

    def predict(self, X: np.ndarray, return_std: bool = False):
        """Latent mean (m, T), and std without the observation noise, at inputs X (m, D)."""
        X = np.asarray(X, dtype=float)
        g, n, t = self.reduction.shape
        m, T = len(X), len(self.slots)
        mean = np.empty((m, T))
        std = np.empty((m, T)) if return_std else None
        block = max(1, self.BLOCK_ENTRIES // (g * n))
        for lo in range(0, m, block):
            x = X[lo : lo + block]
            rows = len(x)
            kx = self._kernels(x)
            # thin products by einsum: numpy's stacked matmul with a few columns is ~4x slower
            means = np.einsum("grn,gnt->rgt", kx, self.mean_weights, optimize=True).reshape(rows, g * t)
            mean[lo : lo + rows] = means[:, self.slots]
            if return_std:
                v = np.matmul(kx, self.eigvecs)  # (g, rows, n), contiguous
                v *= v
                var = np.einsum("grn,gnt->rgt", v, self.reduction, optimize=True).reshape(rows, g * t)[:, self.slots]
                std[lo : lo + rows] = np.sqrt(np.maximum(self.prior_var[None, :] - var, 0.0))
        return (mean, std) if return_std else mean


def loo_residuals(gp: GP) -> tuple[np.ndarray, np.ndarray]:
    """Leave-one-pose-out residuals of a fitted GP and the std of the measurement each was
    predicted with (latent plus noise), (n, T) each, at the fitted hyperparameters, in closed form
    (no refit): with I the T entries of pose i, alpha = K^-1 y and C_i = (K^-1)_II,

        y_I - mean_-i(I) = C_i^-1 alpha_I,    cov_-i(I) = C_i^-1

    (Sundararajan and Keerthi 2001, Neural Computation 13(5), eq. 9-10, for blocks; one task:
    alpha_i / [K^-1]_ii and 1 / [K^-1]_ii). From the Kronecker factors of the module docstring,
    (C_i)_tu = sum_a P_ta P_ua sum_j V_ij^2 Dinv_aj: no (nT) x (nT) matrix."""
    P, _, V, _, Dinv, _, _ = _factor(gp.theta, gp.X, gp.n_tasks)
    alpha = P @ (Dinv * (P.T @ gp.Y.T @ V)) @ V.T  # (T, n)
    C = np.einsum("ta,ia,ua->itu", P, (V * V) @ Dinv.T, P)  # (n, T, T)
    cov = np.linalg.inv(C)
    return np.einsum("itu,ui->it", cov, alpha), np.sqrt(np.diagonal(cov, axis1=1, axis2=2))


def fit_gps(X: np.ndarray, targets: list[np.ndarray], restarts: int = 2, seed: int = 0, workers: int | None = None) -> list["GP"]:
    """`fit_gp` for several target groups (one GP each, seed + k for the k-th), on a thread pool
    with one BLAS thread per fit. The matrices here are small (n x n, n ~ 100): a multi-threaded
    BLAS spends more on waking its threads than on the work (measured: one 3-task group on 112
    poses 1.1 s with two OpenBLAS threads, 0.35 s with one), so the fits run side by side instead
    (LAPACK releases the GIL). The limit is process-wide, hence set here once, around the pool."""
    with threadpool_limits(limits=1, user_api="blas"), ThreadPoolExecutor(workers or os.cpu_count() or 1) as pool:
        return list(pool.map(lambda k: fit_gp(X, targets[k], restarts=restarts, seed=seed + k), range(len(targets))))


def fit_gp(X: np.ndarray, Y: np.ndarray, restarts: int = 2, seed: int = 0, noise_floor: float = 1e-6) -> GP:
    """Maximum-marginal-likelihood fit from a default start and `restarts` seeded random ones."""
    X = np.asarray(X, dtype=float)
    Y = np.asarray(Y, dtype=float).reshape(len(X), -1)
    D, T = X.shape[1], Y.shape[1]
    n_chol = T * (T + 1) // 2
    bounds = [(np.log(0.05), np.log(50.0))] * D + [(-8.0, 8.0)] * n_chol + [(np.log(noise_floor), np.log(10.0))] * T
    rng = np.random.default_rng(seed)
    first = default_theta(D, T)
    if T > 1:  # start the task covariance at the data's: B = 0.95 cov(Y), noise 5 % of the variance
        cov = np.cov(Y, rowvar=False) + 1e-6 * np.eye(T)
        L0 = np.linalg.cholesky(0.95 * cov)
        first[D : D + n_chol] = [np.log(L0[a, b]) if a == b else L0[a, b] for a in range(T) for b in range(a + 1)]
        first[-T:] = np.log(0.05 * np.diag(cov))
    starts = [first]
    for _ in range(restarts):
        theta = default_theta(D, T)
        theta[:D] = rng.uniform(np.log(0.2), np.log(5.0), D)
        theta[D : D + n_chol] = _random_cholesky(rng, T)
        theta[-T:] = rng.uniform(np.log(1e-3), np.log(0.3), T)
        starts.append(theta)
    best = None
    for theta0 in starts:
        with np.errstate(all="ignore"):
            result = scipy.optimize.minimize(nll_kron, theta0, args=(X, Y), jac=True, method="L-BFGS-B", bounds=bounds, options={"maxiter": 300, "ftol": 1e-7, "gtol": 1e-4})
        if np.isfinite(result.fun) and (best is None or result.fun < best.fun):
            best = result
    if best is None or best.fun >= 1e25:
        raise np.linalg.LinAlgError("no starting point gave a valid covariance")
    return GP(theta=best.x, X=X, Y=Y)


def default_theta(D: int, T: int) -> np.ndarray:
    chol = [0.0 if a == b else 0.5 for a in range(T) for b in range(a + 1)]
    return np.concatenate([np.zeros(D), chol, np.full(T, np.log(0.01))])


def _random_cholesky(rng, T: int) -> np.ndarray:
    return np.array([rng.normal(0.0, 0.3) if a == b else rng.normal(0.0, 1.0) for a in range(T) for b in range(a + 1)])


def cholesky_factor(theta, D: int, T: int) -> np.ndarray:
    L = np.zeros((T, T))
    i = D
    for a in range(T):
        for b in range(a + 1):
            L[a, b] = np.exp(theta[i]) if a == b else theta[i]
            i += 1
    return L


def rbf(theta, X1, X2) -> np.ndarray:
    D = X1.shape[1]
    diff = (X1[:, None, :] - X2[None, :, :]) / np.exp(theta[:D])
    return np.exp(-0.5 * np.sum(diff**2, axis=2))


def _factor(theta, X, T):
    """P, S^-1/2 diagonal, V, e, 1 / (lam e + 1), B for the Kronecker solve."""
    D = X.shape[1]
    L = cholesky_factor(theta, D, T)
    B = L @ L.T
    noise = np.exp(theta[-T:])
    root = 1.0 / np.sqrt(noise)
    lam, Q = np.linalg.eigh(root[:, None] * B * root[None, :])
    lam = np.maximum(lam, 0.0)
    Kx = rbf(theta, X, X)
    e, V = np.linalg.eigh(Kx)
    e = np.maximum(e, 0.0)
    P = root[:, None] * Q
    Dinv = 1.0 / (np.outer(lam, e) + 1.0)
    return P, root, V, e, Dinv, B, Kx


def nll_single(theta, X, Y):
    """Single task: the same likelihood from a Cholesky factor of K = b Kx + sigma^2 I (cheaper than
    an eigendecomposition when there is no Kronecker structure to exploit)."""
    n, D = X.shape
    y = Y[:, 0]
    b, noise = np.exp(2.0 * theta[D]), np.exp(theta[D + 1])
    diff2 = (X[:, None, :] - X[None, :, :]) ** 2 / np.exp(2 * theta[:D])
    Kx = np.exp(-0.5 * diff2.sum(axis=2))
    K = b * Kx
    K[np.diag_indices_from(K)] += noise
    try:
        c = np.linalg.cholesky(K)
    except np.linalg.LinAlgError:
        return 1e25, np.zeros_like(theta)
    alpha = scipy.linalg.cho_solve((c, True), y)
    nll = 0.5 * y @ alpha + np.sum(np.log(np.diag(c))) + 0.5 * n * LOG_2PI
    W = np.outer(alpha, alpha) - scipy.linalg.cho_solve((c, True), np.eye(n))
    grad = np.empty_like(theta)
    bK = b * Kx
    for d in range(D):
        grad[d] = -0.5 * np.sum(W * bK * diff2[:, :, d])
    grad[D] = -np.sum(W * bK)
    grad[D + 1] = -0.5 * np.trace(W) * noise
    return nll, grad


def nll_kron(theta, X, Y):
    """Negative log marginal likelihood and its gradient, Kronecker form. Y is (n, T)."""
    n, T = Y.shape
    if T == 1:
        return nll_single(theta, X, Y)
    D = X.shape[1]
    try:
        P, root, V, e, Dinv, B, Kx = _factor(theta, X, T)
    except np.linalg.LinAlgError:
        return 1e25, np.zeros_like(theta)
    lam_e = 1.0 / Dinv - 1.0
    noise = 1.0 / root**2
    Yt = Y.T  # (T, n)
    Ytil = P.T @ Yt @ V  # (T, n) in the eigenbasis
    A = P @ (Dinv * Ytil) @ V.T  # alpha, (T, n)
    nll = 0.5 * np.sum(Yt * A) + 0.5 * np.sum(np.log(lam_e + 1.0)) + 0.5 * n * np.sum(np.log(noise)) + 0.5 * n * T * LOG_2PI
    grad = np.empty_like(theta)
    # tr(K^-1 (M (x) N)) = sum_ij Dinv_ij (P^T M P)_ii (V^T N V)_jj ; alpha^T (M (x) N) alpha = sum(M * (A N A^T))
    PBP = np.einsum("ti,ts,si->i", P, B, P)
    diff2 = (X[:, None, :] - X[None, :, :]) ** 2 / np.exp(2 * theta[:D])
    G = A.T @ B @ A  # (n, n)
    # sum_j (PBP Dinv)_j (V^T dKx V)_jj = sum(dKx * V diag(PBP Dinv) V^T): one n^3 product for all d
    Q = (V * (PBP @ Dinv)) @ V.T
    QG = (Q - G) * Kx
    for d in range(D):
        grad[d] = 0.5 * np.sum(QG * diff2[:, :, d])
    L = cholesky_factor(theta, D, T)
    AKA = A @ Kx @ A.T
    i = D
    for a in range(T):
        for b in range(a + 1):
            dL = np.zeros((T, T))
            dL[a, b] = L[a, b] if a == b else 1.0
            dB = dL @ L.T + L @ dL.T
            pdp = np.einsum("ti,ts,si->i", P, dB, P)
            grad[i] = 0.5 * (pdp @ Dinv @ e) - 0.5 * np.sum(dB * AKA)
            i += 1
    for t in range(T):
        grad[D + T * (T + 1) // 2 + t] = 0.5 * noise[t] * (np.sum(P[t] ** 2 @ Dinv) - np.sum(A[t] ** 2))
    return nll, grad


def nll_dense(theta, X, Y):
    """The same likelihood from the dense (nT) x (nT) covariance (task-major order); for checks."""
    n, T = Y.shape
    D = X.shape[1]
    L = cholesky_factor(theta, D, T)
    K = np.kron(L @ L.T, rbf(theta, X, X)) + np.kron(np.diag(np.exp(theta[-T:])), np.eye(n))
    y = Y.T.ravel()
    c = np.linalg.cholesky(K)
    alpha = np.linalg.solve(K, y)
    return 0.5 * y @ alpha + np.sum(np.log(np.diag(c))) + 0.5 * n * T * LOG_2PI
