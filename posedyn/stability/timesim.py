"""Time-domain simulation of the same milling delay equation, for verification.

    q'' + C q' + W0 q = a_p Phi^T H(t) (U(t - tau) - U(t)),   U = Phi q

integrated with classical Runge-Kutta at a fixed step h = tau / K, the delayed state read from a
history buffer (grid points exactly; the half-step value by cubic Hermite interpolation from the
stored positions and velocities) and H(t) evaluated at the exact tool angle, not averaged. Only
the regenerative (homogeneous) part is simulated: the static chip thickness adds a periodic
forced response that does not change stability.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from posedyn.dynamics import ToolTipDynamics
from posedyn.stability.cutting import Cut, force_matrix


@dataclass(frozen=True, eq=False)
class Simulation:
    """Tool-tip displacement u_m (samples, 2, B) at times t_s for each simulated depth."""

    t_s: np.ndarray
    u_m: np.ndarray
    tau_s: float

    def growth_rate(self, start_fraction: float = 0.5) -> np.ndarray:
        """sigma (1/s) per depth: slope of ln(max |u| per delay period) over the later part of
        the run (a least-squares line); > 0 grows (chatter), < 0 decays."""
        per = int(round(self.tau_s / (self.t_s[1] - self.t_s[0])))
        periods = len(self.t_s) // per
        mag = np.linalg.norm(self.u_m[: periods * per], axis=1).reshape(periods, per, -1).max(axis=1)
        first = int(start_fraction * periods)
        t = (np.arange(first, periods) + 0.5) * self.tau_s
        return np.polyfit(t, np.log(mag[first:]), 1)[0]

    def spectrum(self, index: int = 0, start_fraction: float = 0.5):
        """(frequency_hz, amplitude) of the tool-tip motion over the later part of the run, the
        exponential growth or decay divided out, Hann-windowed, summed over x and y."""
        sigma = self.growth_rate(start_fraction)[index]
        first = int(start_fraction * len(self.t_s))
        t = self.t_s[first:]
        u = self.u_m[first:, :, index] * np.exp(-sigma * (t - t[0]))[:, None]
        window = np.hanning(len(t))[:, None]
        spec = np.abs(np.fft.rfft((u - u.mean(axis=0)) * window, axis=0))
        freq = np.fft.rfftfreq(len(t), t[1] - t[0])
        return freq, np.sqrt(np.sum(spec**2, axis=1))

    def peak_hz(self, index: int = 0, start_fraction: float = 0.5) -> float:
        """Frequency of the largest spectral peak, refined by a parabola through the log
        amplitudes of the peak bin and its neighbours."""
        freq, amp = self.spectrum(index, start_fraction)
        k = int(np.argmax(amp[1:])) + 1
        if 0 < k < len(amp) - 1:
            a, b, c = np.log(amp[k - 1 : k + 2])
            offset = 0.5 * (a - c) / (a - 2 * b + c)
            return float(freq[k] + offset * (freq[1] - freq[0]))
        return float(freq[k])


def simulate(
    dyn: ToolTipDynamics,
    cut: Cut,
    rpm: float,
    depth_m,
    periods: int = 300,
    steps_per_delay: int = 200,
    initial_m: float = 1e-6,
) -> Simulation:
    """Simulate `periods` delays from rest history with an initial tool-tip displacement,
    for one or several depths at once (batched)."""
    depth = np.atleast_1d(np.asarray(depth_m, dtype=float))
    batch = len(depth)
    tau = float(cut.tooth_period_s(rpm))
    steps = int(steps_per_delay)
    h = tau / steps
    turned = dyn.rotated(np.deg2rad(cut.feed_angle_deg))
    shapes = turned.shapes
    n = dyn.n_modes
    omega = 2.0 * np.pi * rpm / 60.0
    # modal force matrices at t = k h / 2 over one period (H is tau-periodic)
    half_times = np.arange(2 * steps) * (h / 2.0)
    W = np.einsum("ir,kij,jq->krq", turned.force_shapes, force_matrix(cut, omega * half_times), shapes)  # (2K, n, n)
    aW = W[:, None] * depth[None, :, None, None]  # (2K, B, n, n)
    K, C = dyn.stiffness_matrix, dyn.damping_matrix

    total = periods * steps
    q_hist = np.zeros((total + steps + 1, batch, n))  # q at grid point k is q_hist[k + steps]
    v_hist = np.zeros((total + steps + 1, batch, n))
    q = np.zeros((batch, n))
    v = np.zeros((batch, n))
    q[:] = np.linalg.lstsq(shapes, np.full(2, initial_m), rcond=None)[0]  # small displacement
    q_hist[steps], v_hist[steps] = q, v

    def accel(k2, q, v, q_delayed):
        force = np.einsum("brq,bq->br", aW[k2 % (2 * steps)], q_delayed - q)
        return force - v @ C.T - q @ K.T

    for k in range(total):
        qd0, vd0 = q_hist[k], v_hist[k]  # state at t_k - tau
        qd1, vd1 = q_hist[k + 1], v_hist[k + 1]
        qdm = 0.5 * (qd0 + qd1) + (h / 8.0) * (vd0 - vd1)  # cubic Hermite at the midpoint
        k2 = 2 * k
        a1 = accel(k2, q, v, qd0)
        q2, v2 = q + 0.5 * h * v, v + 0.5 * h * a1
        a2 = accel(k2 + 1, q2, v2, qdm)
        q3, v3 = q + 0.5 * h * v2, v + 0.5 * h * a2
        a3 = accel(k2 + 1, q3, v3, qdm)
        q4, v4 = q + h * v3, v + h * a3
        a4 = accel(k2 + 2, q4, v4, qd1)
        q = q + (h / 6.0) * (v + 2.0 * v2 + 2.0 * v3 + v4)
        v = v + (h / 6.0) * (a1 + 2.0 * a2 + 2.0 * a3 + a4)
        q_hist[k + steps + 1], v_hist[k + steps + 1] = q, v
    u = np.einsum("dr,kbr->kdb", shapes, q_hist[steps:])
    return Simulation(t_s=np.arange(total + 1) * h, u_m=u, tau_s=tau)
