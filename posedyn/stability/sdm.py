"""Semi-discretization of the milling delay equation (Insperger and Stepan; seed 004 eqs. 8-12).

In modal coordinates q (tool tip U = Phi q) the cut gives

    z' = A(t) z + B(t) q(t - tau),   z = [q; q'],
    A = [[0, I], [-(W0 + a_p W(t)), -C]],   B = [[0], [a_p W(t)]],   W(t) = Phi^T H(t) Phi

with W0 = diag(w_r^2), C = diag(2 zeta_r w_r). One delay tau is cut into m steps dt = tau / m;
on step i, W is replaced by its average over the step (exact integrals of H) and the delayed
position by

    zeroth order:  (q_{i-m} + q_{i-m+1}) / 2           (weights w_a = w_b = 1/2, seed 004 eq. 8)
    first order:   linear in time from q_{i-m} to q_{i-m+1}

so that z_{i+1} = P_i z_i + Fb_i q_{i-m} + Fa_i q_{i-m+1} (seed 004 eq. 10) with
P_i = exp(A_i dt), F0_i = int_0^dt exp(A_i s) ds B_i, F1_i = int_0^dt exp(A_i s) (dt - s) / dt ds B_i,
Fa = Fb = F0 / 2 (zeroth order) or Fa = F1, Fb = F0 - F1 (first order).

The monodromy matrix Psi maps E_0 = [z_0; q_{-1}; ...; q_{-m}] to E_m (seed 004 eqs. 11-12),
N = 2n + m n. Only the z rows of each D_i are dense, so Psi is applied by running the step
recursion (8 n^2 m multiply-adds per vector instead of a dense N^2 product), batched over
(speed, depth) pairs with the batch as the last array axis.

Eigenvalues: a multiplier mu != 0 with eigenvector E_0 has q_{k-m} = q_k / mu over the period, so
the recursion closes on z alone,

    z_{i+1} = T_i(mu) z_i,  T_i = (mu I - Fa_i S)^-1 (mu P_i + Fb_i S),  S = [I 0],
    det(mu I - T_{m-1}(mu) ... T_0(mu)) = 0,

a 2n x 2n nonlinear eigenproblem with exactly the nonzero eigenvalues of Psi. The spectral
radius is found by a short Arnoldi run on Psi (candidates), refined on that 2n x 2n problem by
secant iteration to machine precision; elements whose refinement does not settle fall back to a
dense eigensolver on the formed Psi.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from posedyn.dynamics import ToolTipDynamics
from posedyn.stability.cutting import Cut, interval_force_matrices

ORDERS = (0, 1)


def modal_force_matrices(dyn: ToolTipDynamics, cut: Cut, steps: int) -> np.ndarray:
    """W_i = Phi_R^T H_i Phi_L for each step (steps, n, n), in the feed-aligned axes of the cut
    (Phi_L turns coordinates into tool-tip displacement, Phi_R^T tool-tip force into coordinates)."""
    turned = dyn.rotated(np.deg2rad(cut.feed_angle_deg))
    return np.einsum("ir,sij,jq->srq", turned.force_shapes, interval_force_matrices(cut, steps), turned.shapes)


@dataclass(frozen=True, eq=False)
class StepMatrices:
    """P (m, 2n, 2n, B), Fb and Fa (m, 2n, n, B) of a batch of B (speed, depth) pairs."""

    P: np.ndarray
    Fb: np.ndarray
    Fa: np.ndarray
    dt_s: np.ndarray

    @property
    def steps(self) -> int:
        return self.P.shape[0]

    @property
    def n(self) -> int:
        return self.Fa.shape[2]

    @property
    def size(self) -> int:
        """N = 2n + m n, the dimension of the monodromy matrix."""
        return 2 * self.n + self.steps * self.n

    @property
    def batch(self) -> int:
        return self.P.shape[-1]

    def take(self, index) -> "StepMatrices":
        return StepMatrices(self.P[..., index], self.Fb[..., index], self.Fa[..., index], self.dt_s[index])

    @cached_property
    def _batch_first(self):
        """P, Fb, Fa as (m, B, rows, cols) for matmul over many right-hand sides."""
        return tuple(np.ascontiguousarray(a.transpose(0, 3, 1, 2)) for a in (self.P, self.Fb, self.Fa))

    def apply_many(self, x: np.ndarray) -> np.ndarray:
        """Psi x for x of shape (B, N, K): the step recursion with matmul over the K columns."""
        n, m = self.n, self.steps
        P, Fb, Fa = self._batch_first
        two_n = 2 * n
        z = x[:, :two_n]
        hist = [None] * (2 * m + 1)
        for j in range(1, m + 1):
            hist[m - j] = x[:, two_n + (j - 1) * n : two_n + j * n]
        hist[m] = z[:, :n]
        for i in range(m):
            z = P[i] @ z + Fb[i] @ hist[i] + Fa[i] @ hist[i + 1]
            hist[m + i + 1] = z[:, :n]
        return np.concatenate([z] + [hist[2 * m - j] for j in range(1, m + 1)], axis=1)

    def apply(self, x: np.ndarray) -> np.ndarray:
        """Psi x for x of shape (N, B) or (N, B, K): the step recursion run once over the period."""
        n, m = self.n, self.steps
        two_n = 2 * n
        z = x[:two_n]
        hist = [None] * (2 * m + 1)  # hist[k] = q_{k-m}
        for j in range(1, m + 1):
            hist[m - j] = x[two_n + (j - 1) * n : two_n + j * n]
        hist[m] = z[:n]
        for i in range(m):
            z = (
                np.einsum("rcb,cb...->rb...", self.P[i], z)
                + np.einsum("rcb,cb...->rb...", self.Fb[i], hist[i])
                + np.einsum("rcb,cb...->rb...", self.Fa[i], hist[i + 1])
            )
            hist[m + i + 1] = z[:n]
        return np.concatenate([z] + [hist[2 * m - j] for j in range(1, m + 1)], axis=0)

    def used_slots(self) -> np.ndarray:
        """Indices of the state entries that some step reads: z and the history slots that a
        cutting step uses. The others are zero columns of the monodromy matrix."""
        n, m = self.n, self.steps
        fb = np.any(self.Fb != 0, axis=(1, 2, 3))  # step i reads q_{i-m}, slot j = m - i
        fa = np.any(self.Fa != 0, axis=(1, 2, 3))  # step i reads q_{i-m+1}, slot j = m - i - 1 (z for i = m-1)
        read = np.zeros(m + 1, dtype=bool)  # read[j]: slot of q_{-j}
        read[m - np.flatnonzero(fb)] = True
        read[m - 1 - np.flatnonzero(fa)] = True
        slots = [np.arange(2 * n)] + [2 * n + (j - 1) * n + np.arange(n) for j in range(1, m + 1) if read[j]]
        return np.concatenate(slots)

    @property
    def used_size(self) -> int:
        return len(self.used_slots())

    def monodromy(self, reduced: bool = False) -> np.ndarray:
        """The dense monodromy matrices, shape (B, N, N) (for small batches and checks). With
        `reduced`, only the rows and columns of `used_slots()`: the other columns are zero, so
        the reduced matrix has the same eigenvalues less some zeros."""
        cols = self.used_slots() if reduced else np.arange(self.size)
        eye = np.zeros((self.batch, self.size, len(cols)))
        eye[:, cols, np.arange(len(cols))] = 1.0
        psi = self.apply_many(eye)
        return np.ascontiguousarray(psi[:, cols] if reduced else psi)

    def transfers(self, mu: np.ndarray) -> np.ndarray:
        """T_i(mu) = (mu I - Fa_i S)^-1 (mu P_i + Fb_i S) for every step, shape (m, B, 2n, 2n).

        mu I - Fa_i S is block lower triangular ([[mu I - Fa_top, 0], [-Fa_bottom, mu I]]), so
        only n x n blocks are inverted (all steps at once)."""
        n = self.n
        P, Fb, Fa = self._batch_first
        mu = np.asarray(mu, dtype=complex)[:, None, None]  # (B, 1, 1)
        right = mu * P
        right[..., :n] += Fb
        if n == 1:
            top = right[:, :, :1] / (mu - Fa[:, :, :1, :1])
        else:
            top = np.linalg.solve(mu * np.eye(n) - Fa[:, :, :n], right[:, :, :n])
        bottom = (Fa[:, :, n:] @ top + right[:, :, n:]) / mu
        return np.concatenate([top, bottom], axis=2)

    def closed_loop(self, mu: np.ndarray) -> np.ndarray:
        """M(mu) = T_{m-1}(mu) ... T_0(mu), shape (B, 2n, 2n), by pairwise products (log2 m levels)."""
        T = self.transfers(mu)
        while len(T) > 1:
            half = len(T) // 2
            paired = T[1 : 2 * half : 2] @ T[0 : 2 * half : 2]
            T = np.concatenate([paired, T[-1:]]) if len(T) % 2 else paired
        return T[0]

    def characteristic(self, mu: np.ndarray) -> np.ndarray:
        """det(mu I - M(mu)) per batch element: zero exactly at the nonzero multipliers."""
        M = self.closed_loop(mu)
        return np.linalg.det(np.asarray(mu)[:, None, None] * np.eye(2 * self.n) - M)


def step_matrices(dyn: ToolTipDynamics, w_modal: np.ndarray, depth_m, dt_s, order: int = 0) -> StepMatrices:
    """Step matrices of one structure for B (depth, dt) pairs."""
    return stacked_step_matrices(dyn.stiffness_matrix, dyn.damping_matrix, w_modal, depth_m, dt_s, order)


def stacked_step_matrices(stiffness: np.ndarray, damping: np.ndarray, w_modal: np.ndarray, depth_m, dt_s, order: int = 0, inputs: np.ndarray | None = None) -> StepMatrices:
    """Step matrices for B (depth, dt) pairs, each with its own structure when `stiffness`,
    `damping` (n, n) or (B, n, n) and `w_modal` (m, n, n) or (B, m, n, n) are stacked. Steps where
    no tooth cuts (W_i = 0 for every element) share one free-vibration exponential.

    `inputs` (B, m, n, r), when given, is a factor of W_i = inputs_i Phi_L (for the cut,
    Phi_R^T H_i with r = 2): Fb and Fa then act on the delayed tool-tip displacement
    u = Phi_L q instead of on q (r columns instead of n)."""
    if order not in ORDERS:
        raise ValueError(f"order must be 0 or 1, got {order}")
    depth_m, dt_s = np.broadcast_arrays(np.asarray(depth_m, dtype=float).reshape(-1), np.asarray(dt_s, dtype=float).reshape(-1))
    batch, (m, n, _) = len(depth_m), w_modal.shape[-3:]
    wn2 = np.broadcast_to(stiffness, (batch, n, n))
    c = np.broadcast_to(damping, (batch, n, n))
    w_steps = w_modal if w_modal.ndim == 3 else np.moveaxis(w_modal, 1, 0)  # (m, [B,] n, n)
    cutting = np.any(w_steps != 0.0, axis=tuple(range(1, w_steps.ndim)))
    P = np.empty((m, 2 * n, 2 * n, batch))
    r = n if inputs is None else inputs.shape[-1]
    F0 = np.zeros((m, 2 * n, r, batch))
    F1 = np.zeros((m, 2 * n, r, batch)) if order == 1 else None
    if not cutting.all():
        free_p, _, _ = exponentials(wn2, c, dt_s, order=0)
        P[~cutting] = free_p.transpose(1, 2, 0)[None]
    idx = np.flatnonzero(cutting)
    if len(idx):
        w_cut = w_steps[idx][:, None] if w_modal.ndim == 3 else w_steps[idx]
        aw = w_cut * depth_m[None, :, None, None]  # (k, B, n, n)
        dt = np.broadcast_to(dt_s[None, :], aw.shape[:2]).reshape(-1)
        stiff, damp = (wn2 + aw).reshape(-1, n, n), np.broadcast_to(c, aw.shape).reshape(-1, n, n)
        to_layout = lambda a: a.reshape(len(idx), batch, *a.shape[1:]).transpose(0, 2, 3, 1)  # noqa: E731
        if inputs is None:  # F = int exp(A s) E ds a W_i
            p, g0, g1 = exponentials(stiff, damp, dt, order)
            awf = aw.reshape(-1, n, n)
            g0, g1 = g0 @ awf, (g1 @ awf if order == 1 else None)
        else:  # a Phi_R^T H_i inside the augmented exponential: r columns instead of n
            rows = (np.moveaxis(inputs, 1, 0)[idx] * depth_m[None, :, None, None]).reshape(-1, n, r)
            p, g0, g1 = exponentials(stiff, damp, dt, order, inputs=rows)
        P[idx] = to_layout(p)
        F0[idx] = to_layout(g0)
        if order == 1:
            F1[idx] = to_layout(g1)
    if order == 0:
        half = 0.5 * F0
        return StepMatrices(P, half, half, dt_s)
    return StepMatrices(P, F0 - F1, F1, dt_s)


def exponentials(stiffness: np.ndarray, damping: np.ndarray, dt: np.ndarray, order: int, inputs: np.ndarray | None = None):
    """For A = [[0, I], [-K, -C]]: exp(A dt), int_0^dt exp(A s) E ds and int_0^dt exp(A s) E (dt - s) / dt ds
    with E = [[0], [I]] (or [[0], [R]] for given `inputs` R (k, n, r)), batched over K, C (k, n, n)
    and dt (k,), from one augmented exponential."""
    k, n, _ = stiffness.shape
    if n == 1 and inputs is None:
        out = _exponentials_sdof(stiffness[:, 0, 0], damping[:, 0, 0], dt, order)
        if out is not None:
            return out
    r = n if inputs is None else inputs.shape[-1]
    size = 2 * n + r * (order + 1)
    # Balanced augmented matrix: positions scaled by w = sqrt(max |K|) so that every block is of
    # the order of the modal frequencies, exp(M) = S^-1 exp(S M S^-1) S with S = diag(w I, I, ...).
    w = np.sqrt(np.max(np.abs(stiffness), axis=(1, 2)))[:, None, None]
    M = np.zeros((k, size, size))
    M[:, :n, n : 2 * n] = w * np.eye(n)
    M[:, n : 2 * n, :n] = -stiffness / w
    M[:, n : 2 * n, n : 2 * n] = -damping
    M[:, n : 2 * n, 2 * n : 2 * n + r] = np.eye(n) if inputs is None else inputs
    if order == 1:
        M[:, 2 * n : 2 * n + r, 2 * n + r :] = np.eye(r) / dt[:, None, None]
    E = expm_batched(M * dt[:, None, None])
    E[:, :n, :] /= w
    E[:, :, :n] *= w
    return E[:, : 2 * n, : 2 * n], E[:, : 2 * n, 2 * n : 2 * n + r], (E[:, : 2 * n, 2 * n + r :] if order == 1 else None)


#: Taylor polynomial of degree 18 for exp in five matrix products (Bader, Blanes and Casas 2019,
#: "Computing the matrix exponential with an optimized Taylor polynomial approximation",
#: Mathematics 7, 1174, eq. (24)-(27), their coefficients): with P = (I, A, A^2, A^3, A^6) and
#: B_i = sum_j _BBC18[i, j] P_j,  A9 = B_0 B_4 + B_3,  T18(A) = B_1 + (B_2 + A9) A9.
#: THETA18: the 1-norm up to which T18 is accurate to double precision (backward error below the
#: unit round-off; the bound PyTorch's matrix_exp uses; forward truncation 1.09^19 / 19! = 4e-17).
_BBC18 = np.array([
    [0.0, -1.00365581030144618291e-01, -8.02924648241156932449e-03, -8.92138498045729985177e-04, 0.0],
    [0.0, 3.97849749499645077844e-01, 1.36783778460411720168e00, 4.98289622525382669416e-01, -6.37898194594723280150e-04],
    [-1.09676396052962061844e01, 1.68015813878906206114e00, 5.71779846478865511061e-02, -6.98210122488052056106e-03, 3.34975017086070470649e-05],
    [-9.04316832390810593223e-02, -6.76404519071381882256e-02, 6.75961301770459654925e-02, 2.95552570429315521194e-02, -1.39180257516060693404e-05],
    [0.0, 0.0, -9.23364619367118555360e-02, -1.69364939002081722752e-02, -1.40086798182036094347e-05],
])
THETA18 = 1.090863719290036

#: Bytes per matrix stack in a block of `expm_batched` (16-128 matrices): the temporaries stay
#: in cache (about 3x faster than one pass over thousands of 20 x 20 matrices; 20-24 square
#: complex matrices 1.3-1.6x faster in blocks of 32-48 than of 128).
EXPM_BLOCK_BYTES = 1 << 18


def expm_batched(A: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """exp(A) for a stack (k, s, s): Taylor degree 18 in five products (`_BBC18`) with scaling
    and squaring, vectorized over blocks of the stack (one scaling per block, from its largest
    1-norm). No linear solve: for the many small matrices here a batched LU costs as much as 15
    products (the [13/13] Pade this replaced, 1.5x slower; same results to 1e-14). `out`: a
    (k, s, s) array the blocks are written into (returned)."""
    block = min(max(EXPM_BLOCK_BYTES // (A.shape[-1] ** 2 * A.itemsize), 16), 128)
    if out is None and len(A) <= block:
        return _expm_block(A)
    out = np.empty_like(A) if out is None else out
    for i in range(0, len(A), block):
        out[i : i + block] = _expm_block(A[i : i + block])
    return out


def _expm_block(A: np.ndarray) -> np.ndarray:
    norm = np.max(np.abs(A).sum(axis=1))
    squarings = max(0, int(np.ceil(np.log2(norm / THETA18)))) if norm > 0 else 0
    powers = np.empty((4,) + A.shape, dtype=A.dtype)  # A, A^2, A^3, A^6 (A scaled)
    np.multiply(A, 0.5**squarings, out=powers[0])
    A = powers[0]
    np.matmul(A, A, out=powers[1])
    np.matmul(powers[1], A, out=powers[2])
    np.matmul(powers[2], powers[2], out=powers[3])
    flat = powers.reshape(4, -1)
    if flat.dtype.kind == "c":  # real coefficients: one real product over (re, im) pairs
        B = (_BBC18[:, 1:] @ flat.view(np.float64)).view(flat.dtype).reshape((5,) + A.shape)
    else:
        B = (_BBC18[:, 1:] @ flat).reshape((5,) + A.shape)
    n = A.shape[-1]
    B.reshape(5, len(A), n * n)[:, :, :: n + 1] += _BBC18[:, :1, None]  # and of I (the diagonals, a strided view)
    A9 = B[0] @ B[4]
    A9 += B[3]
    B[2] += A9
    R = B[2] @ A9
    R += B[1]
    for _ in range(squarings):
        R = R @ R
    return R


def _exponentials_sdof(kappa: np.ndarray, c: np.ndarray, dt: np.ndarray, order: int):
    """Closed form for one mode, A = [[0, 1], [-kappa, -c]]:
    exp(A dt) = exp(-c dt / 2) [C(u) I + S(u) dt (A + c/2 I)],  u = dt^2 (c^2 / 4 - kappa),
    C(u) = cosh(sqrt u), S(u) = sinh(sqrt u) / sqrt u (real for either sign of u); the input
    integrals are A^-1 (exp(A dt) - I) E and A^-1 (g0 - dt E) / dt. Returns None when kappa dt^2 is
    so small that A^-1 would lose digits; the caller then uses the general exponential."""
    if np.any(np.abs(kappa) * dt**2 < 1e-6):
        return None
    u = dt**2 * (0.25 * c**2 - kappa)
    root = np.sqrt(np.abs(u))
    small = root < 1e-3
    safe = np.where(small, 1.0, root)
    cosh = np.where(small, 1.0 + u / 2.0 + u**2 / 24.0 + u**3 / 720.0, np.where(u >= 0, np.cosh(safe), np.cos(safe)))
    sinhc = np.where(small, 1.0 + u / 6.0 + u**2 / 120.0 + u**3 / 5040.0, np.where(u >= 0, np.sinh(safe), np.sin(safe)) / safe)
    decay = np.exp(-0.5 * c * dt)
    s = sinhc * dt
    p = np.empty(kappa.shape + (2, 2))
    p[:, 0, 0] = decay * (cosh + 0.5 * c * s)
    p[:, 0, 1] = decay * s
    p[:, 1, 0] = -decay * kappa * s
    p[:, 1, 1] = decay * (cosh - 0.5 * c * s)
    g0 = np.empty(kappa.shape + (2, 1))
    g0[:, 0, 0] = (-c * p[:, 0, 1] - (p[:, 1, 1] - 1.0)) / kappa  # A^-1 = [[-c, -1], [kappa, 0]] / kappa
    g0[:, 1, 0] = p[:, 0, 1]
    g1 = None
    if order == 1:
        v0, v1 = g0[:, 0, 0], g0[:, 1, 0] - dt
        g1 = np.empty(kappa.shape + (2, 1))
        g1[:, 0, 0] = (-c * v0 - v1) / kappa / dt
        g1[:, 1, 0] = v0 / dt
    return p, g0, g1


# --- eigenvalues -----------------------------------------------------------------------------

#: Arnoldi vectors used to find candidate dominant multipliers.
KRYLOV_DIM = 12
#: Candidates (distinct up to conjugation) refined on the 2n x 2n problem.
CANDIDATES = 3
#: A Ritz value near the top must agree with its refined multiplier this well to be trusted.
RITZ_TOLERANCE = 1e-3
#: Rough costs (this machine class) for choosing LAPACK or Krylov: LAPACK eigenvalues of one
#: N x N matrix take about DENSE_SECONDS_PER_N3 * N^3; the Krylov path has a fixed cost (many
#: small numpy calls) plus a small cost per batch element.
DENSE_SECONDS_PER_N3 = 4e-9
KRYLOV_SECONDS = 0.012
KRYLOV_SECONDS_PER_ELEMENT = 6e-5
#: Batches with at most this many monodromy entries (B N^2) are formed for the Krylov run.
FORMED_ELEMENTS = 4_000_000


def dominant_multipliers(steps: StepMatrices, seed: int = 0) -> np.ndarray:
    """The multiplier of largest modulus of each batch element (complex, Im >= 0)."""
    size = steps.used_size
    if size <= 2 * KRYLOV_DIM or steps.batch * DENSE_SECONDS_PER_N3 * size**3 < KRYLOV_SECONDS + steps.batch * KRYLOV_SECONDS_PER_ELEMENT:
        return _dense_dominant(steps)
    candidates = _arnoldi_candidates(steps, seed)  # (C, B), NaN where not worth refining
    refined, converged = _refine(steps, candidates)
    score = np.where(converged, np.abs(refined), -1.0)
    pick = np.argmax(score, axis=0)
    best = np.take_along_axis(refined, pick[None], axis=0)[0]
    ok = np.take_along_axis(converged, pick[None], axis=0)[0]
    # A candidate near the top that did not settle, or settled far from its Ritz value, shows
    # that the Krylov space had not resolved the outer spectrum there: ask the dense solver.
    near_top = np.isfinite(candidates) & (np.abs(candidates) >= 0.9 * np.abs(best)[None])
    unresolved = ~converged | (np.abs(refined - candidates) > RITZ_TOLERANCE * np.abs(candidates))
    bad = np.flatnonzero(~ok | (near_top & unresolved).any(axis=0))
    if len(bad):
        best[bad] = _dense_dominant(steps.take(bad))
    return best


def _dense_dominant(steps: StepMatrices) -> np.ndarray:
    """Largest multiplier from LAPACK on the formed monodromy, less its zero columns (history
    slots no cutting step reads: each adds a zero eigenvalue and nothing else)."""
    eig = np.linalg.eigvals(steps.monodromy(reduced=True))
    best = np.take_along_axis(eig, np.argmax(np.abs(eig), axis=1)[:, None], axis=1)[:, 0]
    return np.where(best.imag < 0, best.conj(), best)


def _arnoldi_candidates(steps: StepMatrices, seed: int):
    """Top Ritz values after KRYLOV_DIM Arnoldi steps (classical Gram-Schmidt, twice), distinct
    up to conjugation, shape (CANDIDATES, B); NaN where a candidate is below 0.9 of the largest.

    Small batches form the (reduced) monodromy once and multiply by it; large ones apply it
    through the step recursion, which needs no N x N storage."""
    batch, k = steps.batch, KRYLOV_DIM
    if batch * steps.used_size**2 <= FORMED_ELEMENTS:
        psi = steps.monodromy(reduced=True)  # (B, N, N)
        size = psi.shape[1]

        def operator(x):
            return np.matmul(psi, x.T[:, :, None])[:, :, 0].T

    else:
        size, operator = steps.size, steps.apply
    rng = np.random.default_rng(seed)
    V = np.zeros((k + 1, size, batch))
    H = np.zeros((k + 1, k, batch))
    v = rng.standard_normal((size, batch))
    V[0] = v / np.linalg.norm(v, axis=0)
    scale = np.zeros(batch)
    for j in range(k):
        w = operator(V[j])
        scale = np.maximum(scale, np.linalg.norm(w, axis=0))
        for _ in range(2):
            h = np.einsum("jnb,nb->jb", V[: j + 1], w)
            w = w - np.einsum("jnb,jb->nb", V[: j + 1], h)
            H[: j + 1, j] += h
        norm = np.linalg.norm(w, axis=0)
        alive = norm > 1e-13 * np.maximum(scale, 1e-300)
        H[j + 1, j] = np.where(alive, norm, 0.0)
        V[j + 1] = np.where(alive, w / np.where(alive, norm, 1.0), 0.0)
    ritz = np.linalg.eigvals(H[:k].transpose(2, 0, 1))  # (B, k)
    ritz = np.where(ritz.imag < 0, ritz.conj(), ritz)
    order = np.argsort(-np.abs(ritz) - 1e-9 * ritz.imag, axis=1)
    ritz = np.take_along_axis(ritz, order, axis=1)
    gap = np.abs(ritz[:, :, None] - ritz[:, None, :]) <= 1e-8 * np.abs(ritz[:, None, :])
    repeat = np.any(np.tril(gap, -1), axis=2)  # equal (up to conjugation) to an earlier, larger one
    first = np.argsort(repeat, axis=1, kind="stable")[:, :CANDIDATES]
    count = (~repeat).sum(axis=1, keepdims=True)
    first = np.where(np.arange(CANDIDATES)[None] < count, first, first[:, :1])
    picked = np.take_along_axis(ritz, first, axis=1).T
    top = np.abs(picked[0])
    worth = (np.abs(picked) >= 0.9 * top) & (top > 0)
    worth[1:] &= first[:, 1:].T != first[:, :1].T
    return np.where(worth, picked, np.nan)


def _refine(steps: StepMatrices, mu0: np.ndarray, iterations: int = 10):
    """Secant iteration on det(mu I - M(mu)) = 0 from each finite candidate of mu0 (C, B).

    Returns the refined values and whether each converged (to 1e-13 relative, without moving
    more than 20 % from its start, which would mean it ran to another multiplier).
    """
    shape = mu0.shape
    start = mu0.reshape(-1)
    # start slightly off the real axis so that the iteration can reach a complex pair
    mu = np.where(np.isfinite(start), start + 1e-6j * np.abs(start), 0.0).astype(complex)
    done = np.zeros(mu.shape, dtype=bool)
    failed = ~np.isfinite(start)
    column = np.tile(np.arange(steps.batch), shape[0])
    active = np.flatnonzero(~failed)
    sub = steps.take(column[active])
    mu_prev = mu[active] * (1.0 + 1e-7)
    with np.errstate(all="ignore"):
        f_prev = sub.characteristic(mu_prev)
        f = sub.characteristic(mu[active])
        for _ in range(iterations):
            denom = f - f_prev
            step = f * (mu[active] - mu_prev) / denom
            finite = np.isfinite(step)
            failed[active[~finite]] = True
            mu_prev = mu[active]
            mu[active] = np.where(finite, mu[active] - step, mu[active])
            settled = finite & (np.abs(step) <= 1e-13 * np.abs(mu[active]))
            done[active[settled]] = True
            keep = finite & ~settled
            if not keep.any():
                break
            active, mu_prev, f_prev = active[keep], mu_prev[keep], f[keep]
            sub = steps.take(column[active])
            f = sub.characteristic(mu[active])
    moved_far = np.abs(mu - start) > 0.2 * np.abs(start)
    converged = done & ~failed & ~moved_far
    mu = np.where(mu.imag < 0, mu.conj(), mu)
    return mu.reshape(shape), converged.reshape(shape)


def _tile(steps: StepMatrices, count: int) -> StepMatrices:
    if count == 1:
        return steps
    tile = lambda a: np.tile(a, (1,) * (a.ndim - 1) + (count,))  # noqa: E731
    return StepMatrices(tile(steps.P), tile(steps.Fb), tile(steps.Fa), np.tile(steps.dt_s, count))


#: A matrix has a simple null vector where its smallest singular value is below this fraction
#: of the next (`null_vectors`).
NULL_GAP = 1e-3


def null_vectors(D: np.ndarray, gap: float = NULL_GAP):
    """(z, ok) of a stack D (B, N, N): z (B, N) the unit right singular vector of each one's
    smallest singular value, ok where that value is below `gap` x the next (a simple null
    vector; a non-finite D gives ok False). The SVD, not LAPACK's eigenvectors of the monodromy:
    where the modes die out between cuts it is graded (singular values from 20 down to 1e-54)
    and geev's eigenvector for the critical multiplier had a residual of |z| (its balancing)."""
    D = np.array(D, dtype=complex)
    bad = ~np.all(np.isfinite(D), axis=(1, 2))
    D[bad] = np.eye(D.shape[-1])
    _, sv, vh = np.linalg.svd(D)
    return np.conj(vh[:, -1, :]), (sv[:, -1] <= gap * sv[:, -2]) & ~bad


def floquet_positions(steps: StepMatrices, mu: np.ndarray) -> np.ndarray:
    """Positions q_0..q_{m-1} over one period of the Floquet solution with multiplier mu,
    shape (m, n, B): the eigenvector of the monodromy matrix (up to scale), rebuilt by running
    z_{i+1} = T_i(mu) z_i from the null vector z_0 of mu I - M(mu)."""
    n, m = steps.n, steps.steps
    mu = np.asarray(mu, dtype=complex).reshape(-1)
    M = steps.closed_loop(mu)
    z = null_vectors(mu[:, None, None] * np.eye(M.shape[-1]) - M)[0].T  # (2n, B)
    q = np.empty((m, n, len(mu)), dtype=complex)
    T = steps.transfers(mu)
    for i in range(m):
        q[i] = z[:n]
        z = np.einsum("brc,cb->rb", T[i], z)
    return q
