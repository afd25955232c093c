"""Coil-voltage trajectories that keep the MRF absorber tuned along a tool path (issue 21): an
optimal-control problem on the dynamics of `absorber.coil_dynamics`, solved with CasADi's Opti
and IPOPT by multiple shooting.

Time nodes t_0..t_N (the path's timing), the voltage V_k held on [t_k, t_k+1], states
x_k = (B_k, B_f,k, T_k) at the nodes; one shooting step per interval of `substeps` substeps of
length h: on the coil, exponential Euler, B += h phi_1(h J) dB/dt with J = d(dB/dt)/dB and
phi_1(z) = (e^z - 1) / z (exact for a linear coil and stable for any h, so an interval of
seconds in a long cut needs no more substeps than one of 50 ms in a transition); on T an
explicit step with the substep's mid-field current (its time constant is minutes); on the fluid
lag the exact solution for a field linear over the substep,

    B_f(t + h) = B(t + h) - (B(t + h) - B(t)) tau / h (1 - e^(-h / tau)) + (B_f(t) - B(t)) e^(-h / tau),

which stays stable and accurate when tau << h (the fluid follows in milliseconds, poses change
in tenths of seconds). Problem:

    min  sum_k w_k ((f_a(B_f,k, T_k) - f*_k) / f*_k)^2 + rho sum_k ((V_k+1 - V_k) / V_max)^2
    s.t. x_k+1 = step(x_k, V_k, h_k),  x_0 given,  |V_k| <= V_max,  0 <= B_k <= B_max,
         i(B_k) <= I_max,  T_k <= T_max,

f*_k the per-pose target frequency, w_k its weight (how much depth the pose loses per unit
mistuning, divided by the target's variance, or 1). The solution ramps the current ahead of a
pose change where the coil's L / R and the voltage limit need it, and raises the field as the
fluid warms. `FieldPlanner` keeps the built problem: a re-plan of a shifted horizon only
changes its parameters and starts from the previous solution (IPOPT warm start).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from scipy.integrate import solve_ivp

from absorber.coil import Coil
from absorber.coil_dynamics import CoilDrive, absorber_frequency, field_rates
from absorber.mrf import MRFAbsorber
from posedyn.errors import InputError


def shooting_step(coil: Coil, drive: CoilDrive, state, voltage_v, step_s, substeps: int, xp=np):
    """x(t + h) from x(t) = (B, B_f, T) under a constant voltage (module docstring)."""
    b, b_f, t = state
    h = step_s / substeps
    tau = drive.fluid_lag_s
    decay = xp.exp(-h / tau)
    flux = coil.turns * drive.gap_area_m2
    for _ in range(substeps):
        resistance = drive.resistance(t, xp)
        rate = (voltage_v - resistance * coil.current(b, xp)) / flux
        z = -h * resistance * coil.current_slope(b, xp) / flux  # h x d(rate)/dB < 0
        b_next = b + h * (xp.exp(z) - 1.0) / z * rate  # exponential Euler: exact for a linear coil, stable at any h
        current = coil.current(0.5 * (b + b_next), xp)
        t = t + h * (resistance * current**2 - (t - drive.ambient_c) / drive.thermal_resistance_k_per_w) / drive.heat_capacity_j_per_k
        b_f = b_next - (b_next - b) * tau / h * (1.0 - decay) + (b_f - b) * decay  # the lag, exact for B linear over the substep
        b = b_next
    return b, b_f, t


@dataclass(frozen=True)
class FieldPlan:
    """A planned trajectory: voltages per interval, states, current and absorber frequency at
    the nodes, and how the solver did."""

    time_s: np.ndarray
    voltage_v: np.ndarray
    field_t: np.ndarray
    fluid_field_t: np.ndarray
    temperature_c: np.ndarray
    current_a: np.ndarray
    frequency_hz: np.ndarray
    target_hz: np.ndarray
    solver: dict = field(default_factory=dict)
    duals: tuple = ()  # (lam_g) for a warm start

    def shifted(self, nodes: int) -> "FieldPlan":
        """The trajectory `nodes` later (the horizon moved on; its end held at the last values): a
        start for the next plan. The multipliers go with it, shifted alike: the constraints are
        stacked node by node in the same order each solve."""
        def move(a):
            a = np.asarray(a)
            return np.concatenate([a[nodes:], np.repeat(a[-1:], nodes, axis=0)]) if nodes else a

        duals = ()
        if self.duals:
            lam = self.duals[0]
            n = len(self.voltage_v)
            blocks = [lam[:3], lam[3 : 3 + 3 * n].reshape(n, 3), lam[3 + 3 * n : 3 + 4 * n], lam[3 + 4 * n : 3 + 5 * n], lam[3 + 5 * n : 3 + 6 * n], lam[3 + 6 * n :]]
            if sum(np.size(b) for b in blocks) == len(lam) and len(blocks[5]) == n:
                duals = (np.concatenate([blocks[0], move(blocks[1]).ravel(), move(blocks[2]), move(blocks[3]), move(blocks[4]), move(blocks[5])]),)
        return FieldPlan(self.time_s, move(self.voltage_v), move(self.field_t), move(self.fluid_field_t), move(self.temperature_c),
                         move(self.current_a), move(self.frequency_hz), move(self.target_hz), {}, duals)


class FieldPlanner:
    """The problem for N intervals, built once (CasADi Opti); `solve` for one horizon."""

    def __init__(self, intervals: int, absorber: MRFAbsorber = MRFAbsorber(), coil: Coil = Coil(), drive: CoilDrive = CoilDrive(),
                 substeps: int = 4, smoothness: float = 1e-4):
        import casadi as cs  # heavy (0.3 s import): only where a plan is made

        if not isinstance(intervals, int) or intervals < 1:
            raise InputError("at least one interval", got=intervals, column="intervals")
        self.n, self.absorber, self.coil, self.drive = intervals, absorber, coil, drive
        x, v, h = cs.MX.sym("x", 3), cs.MX.sym("v"), cs.MX.sym("h")
        # small functions expanded to scalar graphs, mapped over the horizon without expanding the
        # map: the NLP's setup stays linear in N (expanding the whole map took 9 s at N = 1000)
        step = cs.Function("step", [x, v, h], [cs.vertcat(*shooting_step(coil, drive, (x[0], x[1], x[2]), v, h, substeps, cs))]).expand()
        freq = cs.Function("freq", [x], [absorber_frequency(absorber, drive, x[1], x[2], cs)]).expand()
        opti = cs.Opti()
        X, V = opti.variable(3, intervals + 1), opti.variable(1, intervals)
        self.x0, self.dt = opti.parameter(3), opti.parameter(1, intervals)
        self.target, self.weight = opti.parameter(1, intervals + 1), opti.parameter(1, intervals + 1)
        opti.subject_to(X[:, 0] == self.x0)
        opti.subject_to(X[:, 1:] == step.map(intervals)(X[:, :-1], V, self.dt))
        vmax = drive.voltage_limit_v
        opti.subject_to(opti.bounded(-vmax, V, vmax))
        opti.subject_to(opti.bounded(0.0, X[0, 1:], absorber.field_max_t))
        opti.subject_to(coil.current(X[0, 1:], cs) <= coil.max_current_a)
        opti.subject_to(X[2, 1:] <= drive.temperature_limit_c)
        f = freq.map(intervals + 1)(X)
        mistune = (f - self.target) / self.target
        cost = cs.sum2(self.weight * mistune**2)
        if intervals > 1:
            cost += smoothness * cs.sumsqr((V[1:] - V[:-1]) / vmax)
        opti.minimize(cost)
        self.opti, self.X, self.V, self.freq = opti, X, V, freq
        self._warm = None
        self._use_solver(warm=False)

    IPOPT = {"print_level": 0, "sb": "yes", "tol": 1e-10, "acceptable_tol": 1e-8, "max_iter": 500}
    #: From a previous solution and its multipliers: start near the optimum's barrier parameter.
    IPOPT_WARM = {"warm_start_init_point": "yes", "mu_init": 1e-9, "warm_start_bound_push": 1e-9, "warm_start_mult_bound_push": 1e-9,
                  "warm_start_slack_bound_push": 1e-9}

    def _use_solver(self, warm: bool) -> None:
        if self._warm is not warm:
            self.opti.solver("ipopt", {"print_time": False}, {**self.IPOPT, **(self.IPOPT_WARM if warm else {})})
            self._warm = warm

    def solve(self, time_s, target_hz, weight=None, initial_state=None, warm: FieldPlan | None = None) -> FieldPlan:
        """The plan for nodes `time_s` (N + 1, increasing), per-node targets and weights; the
        initial state (B, B_f, T) defaults to no field at ambient temperature; `warm`: a plan of
        the same N whose trajectory (shifted by the caller if the horizon moved) starts IPOPT."""
        time_s = np.asarray(time_s, dtype=float)
        target_hz = np.asarray(target_hz, dtype=float)
        weight = np.ones_like(target_hz) if weight is None else np.asarray(weight, dtype=float)
        if time_s.shape != (self.n + 1,) or target_hz.shape != time_s.shape or weight.shape != time_s.shape:
            raise InputError(f"{self.n + 1} times, targets and weights", got=(time_s.shape, target_hz.shape, weight.shape), column="time_s")
        if not np.all(np.diff(time_s) > 0):
            raise InputError("increasing times", got=time_s[:3].tolist(), column="time_s")
        lo, hi = self.absorber.range_hz
        x0 = np.array([0.0, 0.0, self.drive.ambient_c] if initial_state is None else initial_state, dtype=float)
        opti = self.opti
        opti.set_value(self.x0, x0)
        opti.set_value(self.dt, np.diff(time_s)[None, :])
        opti.set_value(self.target, np.clip(target_hz, lo, hi)[None, :])
        opti.set_value(self.weight, weight[None, :])
        self._use_solver(warm=warm is not None and bool(warm.duals))
        if warm is not None:
            opti.set_initial(self.X, np.vstack([warm.field_t, warm.fluid_field_t, warm.temperature_c]))
            opti.set_initial(self.V, warm.voltage_v[None, :])
            if warm.duals:
                opti.set_initial(opti.lam_g, warm.duals[0])
        else:
            guess = np.array([self.absorber.field_for_frequency(float(f), clamp=True).field_t for f in np.clip(target_hz, lo, hi)])
            opti.set_initial(self.X, np.vstack([guess, guess, np.full_like(guess, x0[2])]))
            opti.set_initial(self.V, (self.drive.resistance_ohm * np.array([self.coil.current(b) for b in guess[1:]]))[None, :])
        start = time.perf_counter()
        try:
            sol = opti.solve()
            status, values = "solved", sol.value
        except RuntimeError:  # IPOPT did not converge: the debug values are its last iterate
            status, values = "not_converged", opti.debug.value
        seconds = time.perf_counter() - start
        X = np.atleast_2d(values(self.X))
        X[:2] = np.where((X[:2] < 0.0) & (X[:2] > -1e-9), 0.0, X[:2])  # the field bound met within IPOPT's tolerance (-4e-42 T refused downstream)
        V = np.atleast_1d(values(self.V)).ravel()
        stats = opti.stats()
        return FieldPlan(
            time_s=time_s, voltage_v=V, field_t=X[0], fluid_field_t=X[1], temperature_c=X[2],
            current_a=np.array([self.coil.current(b) for b in X[0]]),
            frequency_hz=np.array([float(absorber_frequency(self.absorber, self.drive, bf, t)) for bf, t in zip(X[1], X[2])]),
            target_hz=target_hz,
            solver={"status": status, "iterations": int(stats.get("iter_count", -1)), "seconds": seconds},
            duals=(np.array(values(opti.lam_g)).ravel(),),
        )


def simulate(coil: Coil, drive: CoilDrive, absorber: MRFAbsorber, time_s, voltage_v, initial_state=None, rtol: float = 1e-9):
    """The same equations integrated by scipy (Radau, an implicit method sharing nothing with the
    planner's shooting) under the piecewise-constant voltages: (B, B_f, T, current, f_a) at the
    nodes."""
    voltages = np.asarray(voltage_v, dtype=float)
    return _integrate(coil, drive, absorber, time_s, lambda k, x: voltages[k], initial_state, rtol)


def _integrate(coil: Coil, drive: CoilDrive, absorber: MRFAbsorber, time_s, voltage_of, initial_state, rtol: float):
    """(B, B_f, T, current, f_a) at the nodes, scipy's Radau interval by interval with the voltage
    `voltage_of(interval, state)`."""
    time_s = np.asarray(time_s, dtype=float)
    state = np.array([0.0, 0.0, drive.ambient_c] if initial_state is None else initial_state, dtype=float)
    out = [state]
    for k in range(len(time_s) - 1):
        sol = solve_ivp(lambda t, x: field_rates(coil, drive, x[0], x[1], x[2], voltage_of(k, x)), (time_s[k], time_s[k + 1]), state,
                        method="Radau", rtol=rtol, atol=1e-12)
        state = sol.y[:, -1]
        out.append(state)
    X = np.array(out).T
    current = np.array([coil.current(b) for b in X[0]])
    freq = np.array([float(absorber_frequency(absorber, drive, bf, t)) for bf, t in zip(X[1], X[2])])
    return X[0], X[1], X[2], current, freq


def step_schedule(coil: Coil, drive: CoilDrive, absorber: MRFAbsorber, time_s, target_hz, initial_state=None, gain_v_per_a: float = 500.0):
    """The baseline: each node's current set-point (the static field for its target, at the
    modulus's reference temperature) held from that node to the next by a fast current-controlled
    driver (V = R i* + K (i* - i), clipped to the voltage limit; K = 500 V/A, a loop far faster
    than the coil), with no anticipation and no temperature correction. Integrated by scipy:
    (B, B_f, T, current, f_a) at the nodes, and the largest |V| the loop asked for."""
    lo, hi = absorber.range_hz
    setpoints = [coil.current_for_field(absorber.field_for_frequency(float(f), clamp=True).field_t) for f in np.clip(target_hz, lo, hi)]

    def asked(k, x):
        return drive.resistance(x[2]) * setpoints[k] + gain_v_per_a * (setpoints[k] - coil.current(x[0]))

    B, Bf, T, current, freq = _integrate(coil, drive, absorber, time_s, lambda k, x: float(np.clip(asked(k, x), -drive.voltage_limit_v, drive.voltage_limit_v)),
                                         initial_state, 1e-8)
    return B, Bf, T, current, freq, max(abs(asked(k, x)) for k, x in enumerate(zip(B[:-1], Bf[:-1], T[:-1])))
