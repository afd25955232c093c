"""Copied into the test suite from /work/indep19/sle_td.py (issue 19). Only change: DATA points at
this repository's datasets/seeds instead of an absolute path. Not to be aligned with posedyn.sle:
it exists to check posedyn.sle with conventions derived separately (table below).

Independent time-domain (geometric) surface-location-error check for seed 001
(Swan, Penney, Corson, Nazario, Schmitz: "Surface location error in robotic milling ...").

Written without reading the project's SLE code.  Inputs used as data only:
/work/main/datasets/seeds/swan_machine_tool.csv (seed Table 6), swan_spindle_robot.csv
(Table 4), swan_fixture.csv (Table 5).  Everything else is from the seed text (quoted below
as "S:<line/section>") and from first principles.

What is simulated
-----------------
A 12.7 mm, 3-flute, 40 deg helix end mill (S:sec.3 "A 12.7 mm diameter, three-flute, 40 deg
helix tool") cut into A axial slices of height db, rotating at Omega and feeding at
f_t * N_t * Omega/60 along a straight wall (one side of the square of Fig. 1), radial depth
a = 2 mm, down milling (S:Table 7; S:sec.4.5 "2 mm radial immersion for down milling").
Per slice and tooth the mechanistic force  F_t = K_t h db,  F_n = K_n h db  (S:Eqs. 9-10,
with b -> db per slice), K_t = 597.3 N/mm^2, K_n = 59.8 N/mm^2 (S:Table 3).  The chip
thickness h is NOT f_t sin(phi): it is read geometrically from a stored surface (per slice,
per angular bin) left by the previous tooth *including its vibration* (regenerative),
and clipped by the un-cut stock boundary (geometric engagement, see below).  The relative
tool/workpiece displacement is the sum of SDOF modes, each acting in its own direction
(x-table modes in x, y-table modes in y, no cross terms, as the seed gives only direct
FRFs).  Each mode: FRF = (1/k) / (1 - r^2 + 2 i zeta r) (modal stiffness k, S:Tables 4-6),
i.e. m = k/wn^2, c = 2 zeta sqrt(k m).  The spindle-robot case adds the workpiece /
positioner / track modes (Table 5) to the robot (Table 4) modes in the same direction
(S:sec.4.3 "The stability and SLE predictions were completed using the sum of the
spindle-robot and rotary positioner-linear track FRFs"): in the time domain this is exact
because the workpiece sees -F, so the relative displacement tool-minus-workpiece is
(H_tool + H_wp) F.  Machine tool: Table 6 only.  Every mode is integrated with its exact
zero-order-hold state-transition matrix (unconditionally stable, exact for a force that is
constant over the step); the force is evaluated from the state at t_n and held over
[t_n, t_n+1] (one-step explicit coupling -> resolution study in M).  The modal displacement
is the tool-tip displacement and is applied uniformly over the (<= 2.5 mm) axial depth.

Steady state: the low robot modes (7.8-26 Hz, decay rates ~ zeta*wn ~ 10 s^-1) would need
~1 s of cutting from rest.  The modal states are therefore started at the static deflection
under the mean force of a rigid-tool pre-revolution (q_m = Fbar/k_m, v_m = 0), then the full
nonlinear time-domain equations are integrated for T_sim (default 0.8 s, ~140 revolutions,
> 7 e-folds of the slowest mode).  Convergence is checked by reading the SLE in two windows
0.2 s apart and by the tooth-period periodicity of the displacement (chatter check).

Conventions (derived; source of each)
------------------------------------
| item | choice here | source / reasoning |
|---|---|---|
| local frame | x_l = feed direction, y_l = outward normal of the wall being finished (from part toward tool), z up the spindle (away from the part floor) | S:Fig.4 "feed direction is x"; S:Eq.9 h = f_t sin(phi) |
| cutter angle phi | measured from +y_l, increasing with time; edge radial unit vector r = (sin phi, cos phi) | S:Eq.9: h = f_t sin(phi) requires r.x_l = sin(phi) (h = feed . r), so phi = 0 / pi where r is normal to the feed |
| rotation | clockwise seen from the spindle (from +z): r(0)=+y, r(pi/2)=+x (front), r(pi)=-y | standard right-hand spindle (M03).  Check against the seed: with CW rotation down milling keeps the part on the right of the path, so an outside square is traversed clockwise and its top edge in +x: S:Fig.3 caption "square tool path top (+x direction feed); ... bottom (-x direction feed)" -- consistent |
| down milling limits | phi_s = pi - arccos((R-a)/R) = 133.2 deg, phi_e = pi | S:sec.2.2 step 4 "sample y(t) at the cut ... exit (down milling)"; S:Fig.4 start/exit angles; in down milling the tooth enters thick (sin phi_s > 0) and leaves at phi = pi with h = 0, where r is normal to the wall |
| part side | part (stock) occupies y_l < -R + a; the finished wall is at y_l = -R (commanded) | follows from the two rows above: the exit phi = pi points to -y_l; with CW rotation the tooth at phi = pi moves in -x_l, against the feed = down/climb milling |
| tooth phase | phi_ij(t) = Omega t + 2 pi (i-1)/N_t - chi(z_j) | S:Eq.7 |
| helix lag | chi(z) = 2 z tan(gamma)/d, z from the tool tip (bottom of cut) upward; higher slices lag (smaller phi) | S:Eq.8 (printed "2dbt tan gamma/d" = 2 db tan(gamma)/d per slice) and the minus sign of Eq.7 (right-hand helix, right-hand cut). Slice j is evaluated at its mid-height z_j = (j - 1/2) db (Eq.7 uses the slice bottom (j-1) db; difference is a constant db/2 shift) |
| force on tool | F_tool = -F_t t - F_n r, t = dr/dphi = (cos phi, -sin phi): Fx = -F_t cos phi - F_n sin phi, Fy = F_t sin phi - F_n cos phi | tangential force opposes edge motion, normal force pushes tool out of the cut (S:Fig.4). At phi = pi: Fy = +F_n, tool pushed away from the wall -> undercut, as S:sec.4.5 reports large positive SLE for the robot. (Schmitz-Smith print Fx with the opposite sign -- force on part / x flipped; only the normal (y) direction decides the wall.) |
| chip thickness | h = (c(t).r + R) - s_prev(phi) with s_prev the radial coordinate of the surface left at the same fixed-frame angle by the last tooth that cut there; clipped by the stock: h_eff = min(h, R - d_stock), d_stock = distance along r from the centre to the stock face y_l = -R + a; h_eff <= 0 -> no cut | geometric regenerative model (brief); S:sec.2.2 ignores regeneration, this check keeps it |
| regen=False (checks only) | chip from the commanded path (no vibration feedback); used for the quasi-static limit check, where a tooth-periodic steady state has zero regenerative chip anyway, and where the explicit one-step force coupling with dt ~ 20 ms would otherwise be a diverging fixed-point iteration for the quasi-static spindle modes (C_static * cutting stiffness ~ 1) | numerical, see report |
| engagement ('geometric', default) | tooth may cut for phi in (pi/2, pi] where the edge is inside the stock (y_edge < -R + a in the workpiece frame, deflection included) and ahead of the previous tooth's surface | physical; the tool's static normal deflection reduces the true radial depth |
| engagement ('nominal') | fixed phi in [phi_s, pi] (no stock clipping) | the Schmitz-Mann frequency-domain assumption (S:sec.2.2, Fig.4) -- kept as a column for apples-to-apples comparison |
| surface generation | the wall at height z_j is the ENVELOPE (minimum y_l over all passes, at each x along the wall) of the edge point of slice j of every tooth, edge = commanded centre + relative displacement + R r(phi) | brief; equivalent to S:sec.2.2 "sample at exit" when the bottom of each pass is the deepest point |
| SLE sign | SLE = y_wall - (-R), positive = wall further out than commanded = less material removed = undercut | S:sec.4.5 "a positive SLE value indicates an undercut condition, where less material than commanded was removed" |
| reported number | mean over x (whole number of feed marks) and over z of the envelope, in um. Also given: envelope bottoms only (per-pass minimum = Schmitz-Mann sampling) and cusp tops | CMM dimension (S:sec.4.6) is a fitted surface; the cusp height f_t^2/(8R) is 0.3-1.2 um so the choice matters < 1 um |
| "x" and "y" faces | "y" = top/bottom faces (normal +/-y, feed +/-x): normal-axis modes = y table, feed-axis modes = x table.  "x" = left/right faces (normal +/-x, feed -/+y): normal = x table, feed = y table | S:sec.4.5 "the x direction part dimensions (i.e., the left and right surfaces of the square) were calculated using the x direction FRFs because this is the surface normal direction. Similarly, the y direction part dimensions (top and bottom) ... y direction FRFs."  The right face traversed in -y has local frame (x_l, y_l) = (-y, +x), right-handed with the same spindle z, so the same local simulation applies with the tables swapped; each table is direction-symmetric, so opposite faces give the same SLE |
| robot path offset | NOT added (Table 2 mean offsets 14-34 um are kinematic path errors, not vibration) | S:Table 2 / sec.4.1; the seed adds it to Fig.10 -- add it yourself to compare with that figure |
"""
import numpy as np
from scipy.linalg import expm
import csv, os, sys, time, json

DATA = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "datasets", "seeds")
KT, KN = 597.3e6, 59.8e6          # N/m^2 (Table 3)
D, NT, HELIX = 12.7e-3, 3, np.deg2rad(40.0)
R = D / 2
AE = 2.0e-3                        # radial depth (Table 7)


def load_modes(name):
    rows = list(csv.DictReader(open(os.path.join(DATA, name))))
    out = {"x": [], "y": []}
    for r in rows:
        out[r["direction"]].append((float(r["fn_hz"]), float(r["zeta"]), float(r["k_n_per_m"])))
    return out


def machine_modes(machine):
    if machine == "machine_tool":
        return load_modes("swan_machine_tool.csv")
    if machine == "spindle_robot":
        a, b = load_modes("swan_spindle_robot.csv"), load_modes("swan_fixture.csv")
        return {"x": a["x"] + b["x"], "y": a["y"] + b["y"]}
    if machine == "rigid":
        return {"x": [], "y": []}
    raise ValueError(machine)


def face_modes(machine, face):
    """local (feed, normal) mode lists for the 'x' or 'y' face (see docstring)."""
    m = machine_modes(machine)
    if face == "y":
        return m["x"], m["y"]
    if face == "x":
        return m["y"], m["x"]
    raise ValueError(face)


def zoh(modes, dt):
    """exact ZOH discretisation of each SDOF m q'' + c q' + k q = F."""
    co = []
    for fn, z, k in modes:
        wn = 2 * np.pi * fn
        m = k / wn**2
        c = 2 * z * np.sqrt(k * m)
        Ac = np.zeros((3, 3))
        Ac[0, 1] = 1.0
        Ac[1, 0] = -k / m
        Ac[1, 1] = -c / m
        Ac[1, 2] = 1.0 / m
        E = expm(Ac * dt)
        co.append((E[0, 0], E[0, 1], E[0, 2], E[1, 0], E[1, 1], E[1, 2]))
    return np.array(co).reshape(-1, 6)


def simulate(machine, face, rpm, b, ft, M=720, db=0.1e-3, T_sim=0.8, n_rev_win=12,
             engagement="geometric", win_gap=0.2, rigid_pre=True, n_rev_sim=None,
             up=4, return_profile=False, regen=True):
    feed_modes, norm_modes = face_modes(machine, face)
    modes = [(m, 0) for m in feed_modes] + [(m, 1) for m in norm_modes]
    isy = np.array([d for _, d in modes], dtype=bool)
    kk = np.array([m[2] for m, _ in modes]) if modes else np.zeros(0)
    omega = rpm / 60 * 2 * np.pi
    dphi = 2 * np.pi / M
    dt = dphi / omega
    assert M % NT == 0
    V = ft * NT * rpm / 60
    A = max(1, int(round(b / db)))
    dbs = b / A
    zj = (np.arange(A) + 0.5) * dbs
    chi = 2 * zj * np.tan(HELIX) / D
    co = zoh([m for m, _ in modes], dt) if modes else np.zeros((0, 6))
    # tables per slice and fixed-frame angle bin: phi = bin*dphi - chi_j
    bins = np.arange(M)
    PHI = (bins[None, :] * dphi - chi[:, None]) % (2 * np.pi)
    S, C = np.sin(PHI), np.cos(PHI)
    phis = np.pi - np.arccos((R - AE) / R)
    if engagement == "nominal":
        ENG = (PHI >= phis) & (PHI <= np.pi + 1e-12)
    else:
        ENG = (PHI > np.pi / 2) & (PHI <= np.pi + 1e-12)
    ystock = -R + AE
    toff = (np.arange(NT) * (M // NT))
    if n_rev_sim is None:
        n_rev_sim = int(np.ceil(T_sim * rpm / 60))
    nsteps = n_rev_sim * M
    q = np.zeros(len(modes))
    v = np.zeros(len(modes))
    cxh = np.empty(nsteps)
    cyh = np.empty(nsteps)
    fyh = np.empty(nsteps)
    # 1/cos for the stock clip (only used where ENG and cos < 0)
    invC = np.where(ENG & (C < -1e-12), 1.0 / np.where(C < -1e-12, C, -1.0), 0.0)
    # first step at which some tooth of slice j is at bin b, and the time of the (virtual)
    # previous tooth there: the surface "left before the start" is the commanded path
    # shifted by the initial static deflection (u0x, u0y)
    nfirst = np.min((bins[None, :] - toff[:, None]) % M, axis=0)
    tprev = (nfirst - M // NT) * dt
    TAB = np.stack([S, C, ENG.astype(float), invC])          # (4, A, M)
    surf = np.empty((A, M))

    def reset_surf(u0x, u0y):
        surf[:] = R + (V * tprev[None, :] + u0x) * S + u0y * C

    def step_force(n, cx, cy):
        bidx = (n + toff) % M
        Sj, Cj, E, iC = TAB[:, :, bidx]
        pos = cx * Sj + cy * Cj + R
        sp = surf[:, bidx]
        h = pos - sp
        if engagement == "nominal":
            he = h
        else:
            he = np.minimum(h, R - (ystock - cy) * iC)
        hc = E * np.maximum(he, 0.0)
        surf[:, bidx] = np.where((E > 0) & (h > 0), pos, sp)
        Ftn = hc * dbs
        Fx = -(KT * np.vdot(Ftn, Cj) + KN * np.vdot(Ftn, Sj))
        Fy = KT * np.vdot(Ftn, Sj) - KN * np.vdot(Ftn, Cj)
        return Fx, Fy

    wx = (~isy).astype(float)
    wy = isy.astype(float)
    u0x = u0y = 0.0
    if rigid_pre and len(modes):
        reset_surf(0.0, 0.0)
        sx = sy = 0.0
        for n in range(M):
            fx, fy = step_force(n, V * n * dt, 0.0)
            sx += fx
            sy += fy
        fxm, fym = sx / M, sy / M
        q = np.where(isy, fym, fxm) / kk
        u0x, u0y = q @ wx, q @ wy
    reset_surf(u0x, u0y)
    if len(modes):
        a11, a12, b1, a21, a22, b2 = co.T
        b1x, b1y, b2x, b2y = b1 * wx, b1 * wy, b2 * wx, b2 * wy
    for n in range(nsteps):
        if len(modes):
            ux = q @ wx
            uy = q @ wy
        else:
            ux = uy = 0.0
        cx = V * n * dt + ux
        cy = uy
        cxh[n] = cx
        cyh[n] = cy
        if regen:
            Fx, Fy = step_force(n, cx, cy)
        else:   # chip from the commanded (vibration-free) path; the wall still uses c
            Fx, Fy = step_force(n, V * n * dt + u0x, u0y)
        fyh[n] = Fy
        if len(modes):
            q, v = a11 * q + a12 * v + b1x * Fx + b1y * Fy, a21 * q + a22 * v + b2x * Fx + b2y * Fy
    res = {"machine": machine, "face": face, "rpm": rpm, "b_mm": b * 1e3, "ft_mm": ft * 1e3,
           "M": M, "A": A, "n_rev": n_rev_sim, "engagement": engagement}
    w_end = wall(cxh, cyh, nsteps, M, n_rev_win, chi, ft, up)
    res.update({k: v_ for k, v_ in w_end.items() if not k.startswith("profile_z")})
    gap = int(round(win_gap * rpm / 60)) * M
    if nsteps - gap > n_rev_win * M + 2 * M:
        w0 = wall(cxh, cyh, nsteps - gap, M, n_rev_win, chi, ft, up)
        res["sle_mean_um_prev_window"] = w0["sle_mean_um"]
    # periodicity (tooth period) of the normal displacement over the last revolution
    tp = M // NT
    last = cyh[nsteps - M:nsteps]
    prev = cyh[nsteps - M - tp:nsteps - tp]
    res["nonperiodicity_um"] = float(np.max(np.abs(last - prev)) * 1e6)
    res["uy_ptp_last_rev_um"] = float(np.ptp(last) * 1e6)
    res["uy_mean_um"] = float(last.mean() * 1e6)
    res["Fy_mean_N"] = float(fyh[nsteps - M:nsteps].mean())
    if return_profile:
        res["profile_z_um"] = w_end["profile_z"]
        res["profile_z_bottoms_um"] = w_end["profile_z_bottoms"]
        res["z_mm"] = (zj * 1e3).tolist()
    return res


def wall(cxh, cyh, nend, M, n_rev_win, chi, ft, up):
    """envelope of the edge trajectories of every slice over the last n_rev_win revolutions
    before step nend.  Returns SLE statistics (um)."""
    n0 = nend - n_rev_win * M
    nn = np.arange(n0, nend)
    # upsample time by `up` (linear interpolation of the centre, exact circle of the edge)
    nf = np.arange(n0 * up, (nend - 1) * up + 1) / up
    cxf = np.interp(nf, nn, cxh[n0:nend])
    cyf = np.interp(nf, nn, cyh[n0:nend])
    dphi = 2 * np.pi / M
    half = 0.12  # rad around phi = pi (edge is 46 um above its bottom there)
    A = len(chi)
    prof_mean, prof_min, prof_max = [], [], []
    # x grid: central part of the window, integer number of feed marks
    mrg = R * np.sin(half) + ft * NT
    xlo = cxh[n0] + mrg  # passes outside the window cannot reach [xlo, xhi]
    xhi = cxh[nend - 1] - mrg
    nmark = int(np.floor((xhi - xlo) / ft))
    xhi = xlo + nmark * ft
    xg = np.linspace(xlo, xhi, nmark * 200, endpoint=False)
    for j in range(A):
        env = np.full(xg.size, np.inf)
        for i in range(NT):
            phi = nf * dphi + 2 * np.pi * i / NT - chi[j]
            ph = phi % (2 * np.pi)
            sel = np.abs(ph - np.pi) < half
            idx = np.flatnonzero(sel)
            if idx.size == 0:
                continue
            brk = np.flatnonzero(np.diff(idx) > 1)
            starts = np.r_[0, brk + 1]
            ends = np.r_[brk + 1, idx.size]
            for s0, e0 in zip(starts, ends):
                k = idx[s0:e0]
                xe = cxf[k] + R * np.sin(phi[k])
                ye = cyf[k] + R * np.cos(phi[k])
                o = np.argsort(xe)
                xe, ye = xe[o], ye[o]
                inside = (xg >= xe[0]) & (xg <= xe[-1])
                if inside.any():
                    yi = np.interp(xg[inside], xe, ye)
                    env[inside] = np.minimum(env[inside], yi)
        if np.isinf(env).any():
            raise RuntimeError("envelope has holes: widen window")
        sle = (env + R) * 1e6
        prof_mean.append(sle.mean())
        # cusp bottoms / tops: per feed mark
        marks = sle.reshape(nmark, -1)
        prof_min.append(marks.min(axis=1).mean())
        prof_max.append(marks.max(axis=1).mean())
    pm = np.array(prof_mean)
    return {"sle_mean_um": float(pm.mean()), "sle_bottoms_um": float(np.mean(prof_min)),
            "sle_cusptops_um": float(np.mean(prof_max)), "sle_z_min_um": float(pm.min()),
            "sle_z_max_um": float(pm.max()), "profile_z": pm.tolist(),
            "profile_z_bottoms": list(map(float, prof_min))}


if __name__ == "__main__":
    t0 = time.time()
    r = simulate(sys.argv[1], sys.argv[2], float(sys.argv[3]), float(sys.argv[4]) * 1e-3,
                 float(sys.argv[5]) * 1e-3)
    r["runtime_s"] = time.time() - t0
    print(json.dumps(r, indent=1))
