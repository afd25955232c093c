"""Modal-test tables: tool-tip modes measured (or predicted) at robot poses.

A `ModalTable` holds one row per pose x direction x mode, as frozen numpy arrays. Each mode is
described canonically by its natural frequency, damping ratio and modal stiffness,

    H_dd(w) = sum_r 1 / (k_r (1 - r_r^2 + 2 i zeta_r r_r)),   r_r = w / w_r,

with modal mass m = k / w_n^2 and viscous damping c = 2 zeta sqrt(k m) derived, not stored.
Values are kept in the units of the table columns (mm, deg, Hz, N/m) so that a table written
and read back is bit-for-bit the same; SI views are properties.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from posedyn.errors import InputError, check_open_interval, check_positive

DIRECTIONS = ("x", "y", "z")
POSITION_COLUMNS = ("x_mm", "y_mm", "z_mm")
ORIENTATION_COLUMNS = {"abc": ("a_deg", "b_deg", "c_deg"), "beta": ("beta_deg",)}
JOINT_COLUMNS = tuple(f"q{j}_deg" for j in range(1, 7))
MODAL_PARAMS = ("fn_hz", "zeta", "k_n_per_m")  # the positive parameters of a mode row
#: A modal stiffness below this is no milling tool tip's (robots 1e5-1e7 N/m, spindles more):
#: `ModalTable.soft_modes` names such rows (N/mm written as N/m; an accelerance fitted as a receptance).
IMPLAUSIBLE_K_N_PER_M = 1e4
#: Highest natural frequency of a mode row: far beyond any machine's modes, below where the modal
#: masses k / w^2 underflow (fn_hz = 1e308 reached the shapes as 1 / 0). (Stiffnesses have no upper
#: end: a mode nearly invisible in a direction has a huge one there, 1e39 N/m in the twin's campaigns.)
MAX_FN_HZ = 1e6
STD_COLUMNS = tuple("std_" + name for name in MODAL_PARAMS)
#: Optional cross-coupling: on an x row, the modal stiffness of the x response to a y force of
#: the same mode (H_xy = 1 / (k_xy (1 - r^2 + 2 i zeta r))); on a y row, k_yx. Signed; empty
#: where a mode is not coupled. A mode number with cross terms on both its x and y rows is one
#: physical mode seen in both directions (see ToolTipDynamics.from_table).
CROSS_COLUMNS = ("k_xy_n_per_m", "k_yx_n_per_m")


def coupled_y_stiffness(k_xx, k_xy, k_yx):
    """The y row's direct modal stiffness of a coupled (rank-one) mode, k_yy = k_xy k_yx / k_xx:
    with H_ab = phi_La phi_Rb / (w^2 - ...) and k_ab = w^2 / (phi_La phi_Rb), phi_Ly phi_Ry =
    (phi_Ly phi_Rx)(phi_Lx phi_Ry) / (phi_Lx phi_Rx)."""
    return k_xy * k_yx / k_xx
Orientation = Literal["abc", "beta"]


@dataclass(frozen=True)
class Mode:
    """One structural mode seen at the tool tip: H(w) = 1 / (k (1 - r^2 + 2 i zeta r)), r = w / wn."""

    fn_hz: float
    zeta: float
    k_n_per_m: float

    def __post_init__(self):
        check_positive("fn_hz", self.fn_hz)
        check_open_interval("zeta", self.zeta, 0.0, 1.0)
        check_positive("k_n_per_m", self.k_n_per_m)

    @property
    def wn_rad_s(self) -> float:
        return 2.0 * np.pi * self.fn_hz

    @property
    def m_kg(self) -> float:
        return self.k_n_per_m / self.wn_rad_s**2

    @property
    def c_ns_per_m(self) -> float:
        return 2.0 * self.zeta * self.k_n_per_m / self.wn_rad_s

    def receptance(self, omega_rad_s: np.ndarray) -> np.ndarray:
        """H(w) in m/N."""
        r = np.asarray(omega_rad_s, dtype=float) / self.wn_rad_s
        return 1.0 / (self.k_n_per_m * (1.0 - r**2 + 2j * self.zeta * r))


def _frozen(values, dtype) -> np.ndarray:
    array = np.array(values, dtype=dtype)
    array.setflags(write=False)
    return array


def _same(a, b) -> bool:
    if a is None or b is None:
        return a is None and b is None
    if isinstance(a, np.ndarray) and a.dtype.kind == "f":
        return a.shape == b.shape and bool(np.array_equal(a, b, equal_nan=True))
    return bool(np.array_equal(np.asarray(a), np.asarray(b)))


@dataclass(frozen=True, eq=False)
class PoseSet:
    """Robot poses: tool-tip position in the base frame plus an orientation.

    `orientation` is "abc" (KUKA A/B/C: ZYX Euler angles, `orientation_deg` has 3 columns) or
    "beta" (the redundant angle about a tool axis held along base -z, seed 003; 1 column).
    `joints_deg` (n x 6) is optional.
    """

    pose_id: tuple[str, ...]
    position_mm: np.ndarray
    orientation: Orientation
    orientation_deg: np.ndarray
    joints_deg: np.ndarray | None = None

    def __post_init__(self):
        n = len(self.pose_id)
        if n == 0:
            raise InputError("at least one pose", got=0)
        if len(set(self.pose_id)) != n:
            raise InputError("unique pose_id values", column="pose_id")
        if self.orientation not in ORIENTATION_COLUMNS:
            raise InputError("orientation 'abc' or 'beta'", got=self.orientation)
        width = len(ORIENTATION_COLUMNS[self.orientation])
        object.__setattr__(self, "pose_id", tuple(str(p) for p in self.pose_id))
        object.__setattr__(self, "position_mm", _frozen(self.position_mm, float).reshape(n, 3))
        object.__setattr__(self, "orientation_deg", _frozen(self.orientation_deg, float).reshape(n, width))
        if self.joints_deg is not None:
            object.__setattr__(self, "joints_deg", _frozen(self.joints_deg, float).reshape(n, 6))
        for name, array in self.numeric_columns().items():
            if not np.all(np.isfinite(array)):
                raise InputError("finite numbers", column=name)

    def __len__(self) -> int:
        return len(self.pose_id)

    def __eq__(self, other) -> bool:
        return isinstance(other, PoseSet) and all(
            _same(getattr(self, f), getattr(other, f))
            for f in ("pose_id", "position_mm", "orientation", "orientation_deg", "joints_deg")
        )

    @property
    def position_m(self) -> np.ndarray:
        return self.position_mm * 1e-3

    @property
    def columns(self) -> tuple[str, ...]:
        joints = JOINT_COLUMNS if self.joints_deg is not None else ()
        return ("pose_id",) + POSITION_COLUMNS + ORIENTATION_COLUMNS[self.orientation] + joints

    def numeric_columns(self) -> dict[str, np.ndarray]:
        """Pose columns by name (everything but pose_id), one array of length n each."""
        out = {name: self.position_mm[:, j] for j, name in enumerate(POSITION_COLUMNS)}
        for j, name in enumerate(ORIENTATION_COLUMNS[self.orientation]):
            out[name] = self.orientation_deg[:, j]
        if self.joints_deg is not None:
            for j, name in enumerate(JOINT_COLUMNS):
                out[name] = self.joints_deg[:, j]
        return out

    @classmethod
    def from_columns(cls, pose_id, columns: dict) -> "PoseSet":
        """Poses from named columns (x_mm, y_mm, z_mm, then beta_deg or a_deg, b_deg, c_deg, and
        optionally q1_deg..q6_deg), one value per pose: the one place a request, a campaign or
        a table row becomes a PoseSet. A/B/C wins when both orientation forms are given."""
        missing = [c for c in POSITION_COLUMNS if c not in columns]
        abc = all(c in columns for c in ORIENTATION_COLUMNS["abc"])
        if missing or not (abc or "beta_deg" in columns):
            raise InputError("x_mm, y_mm, z_mm and beta_deg or a_deg, b_deg, c_deg", got=sorted(columns), column=(missing or ["beta_deg"])[0])
        orientation = "abc" if abc else "beta"

        def stack(names):
            try:
                return np.column_stack([np.asarray(columns[c], dtype=float).reshape(-1) for c in names])
            except (TypeError, ValueError) as exc:
                raise InputError("numbers", got=str(exc), column=names[0]) from None

        joints = stack(JOINT_COLUMNS) if all(c in columns for c in JOINT_COLUMNS) else None
        return cls(tuple(pose_id), stack(POSITION_COLUMNS), orientation, stack(ORIENTATION_COLUMNS[orientation]), joints)

    def records(self) -> list[dict]:
        """One {pose_id, x_mm, ..., orientation columns} dict per pose (JSON-ready floats)."""
        names = POSITION_COLUMNS + ORIENTATION_COLUMNS[self.orientation]
        values = np.column_stack([self.position_mm, self.orientation_deg])
        return [{"pose_id": p, **{n: float(v) for n, v in zip(names, row)}} for p, row in zip(self.pose_id, values)]

    def subset(self, indices) -> "PoseSet":
        """The poses at `indices`, in that order."""
        idx = list(indices)
        return PoseSet(
            tuple(self.pose_id[i] for i in idx), self.position_mm[idx], self.orientation, self.orientation_deg[idx],
            None if self.joints_deg is None else self.joints_deg[idx],
        )

    def index(self, pose_id: str) -> int:
        try:
            return self.pose_id.index(str(pose_id))
        except ValueError:
            raise InputError("a pose_id present in the table", got=pose_id, column="pose_id") from None


@dataclass(frozen=True, eq=False)
class ModalTable:
    """Tool-tip modes per pose, direction and mode number (one entry per table row).

    `pose_index[i]` points into `poses`. Optional `std_*` arrays hold measurement standard
    deviations (NaN where a row gives none); `source` is free text per row.
    """

    poses: PoseSet
    pose_index: np.ndarray
    direction: np.ndarray
    mode: np.ndarray
    fn_hz: np.ndarray
    zeta: np.ndarray
    k_n_per_m: np.ndarray
    std: dict[str, np.ndarray] = field(default_factory=dict)
    source: tuple[str, ...] | None = None
    cross: dict[str, np.ndarray] = field(default_factory=dict)

    def __post_init__(self):
        n = len(np.atleast_1d(self.fn_hz))
        set_ = lambda name, value: object.__setattr__(self, name, value)  # noqa: E731
        set_("pose_index", _frozen(self.pose_index, np.int64).reshape(n))
        set_("direction", _frozen([str(d) for d in np.atleast_1d(self.direction)], "<U1").reshape(n))
        set_("mode", _frozen(self.mode, np.int64).reshape(n))
        for name in ("fn_hz", "zeta", "k_n_per_m"):
            set_(name, _frozen(getattr(self, name), float).reshape(n))
        unknown = set(self.std) - set(STD_COLUMNS)
        if unknown:
            raise InputError("std columns among " + ", ".join(STD_COLUMNS), got=sorted(unknown))
        set_("std", {k: _frozen(self.std[k], float).reshape(n) for k in STD_COLUMNS if k in self.std})
        unknown = set(self.cross) - set(CROSS_COLUMNS)
        if unknown:
            raise InputError("cross-coupling columns among " + ", ".join(CROSS_COLUMNS), got=sorted(unknown))
        set_("cross", {k: _frozen(self.cross[k], float).reshape(n) for k in CROSS_COLUMNS if k in self.cross})
        for k, v in self.cross.items():
            bad = ~(np.isnan(v) | (np.isfinite(v) & (v != 0)))
            if bad.any():
                raise InputError("empty or a finite non-zero number", got=v[bad][0].item(), column=k, row=_row(bad))
        if self.source is not None:
            set_("source", tuple(str(s) for s in self.source))
            if len(self.source) != n:
                raise InputError(f"{n} source entries", got=len(self.source), column="source")
        if n == 0:
            raise InputError("at least one mode row", got=0)
        if np.any((self.pose_index < 0) | (self.pose_index >= len(self.poses))):
            raise InputError("pose_index within the pose set", column="pose_id")
        bad = ~np.isin(self.direction, DIRECTIONS)
        if bad.any():
            raise InputError("one of x, y, z", got=str(self.direction[bad][0]), column="direction", row=_row(bad))
        checks = (
            ("mode", self.mode >= 1, "an integer >= 1"),
            ("fn_hz", np.isfinite(self.fn_hz) & (self.fn_hz > 0) & (self.fn_hz <= MAX_FN_HZ), f"a number in (0, {MAX_FN_HZ:.0e}] Hz"),
            ("zeta", np.isfinite(self.zeta) & (self.zeta > 0) & (self.zeta < 1), "a number in (0, 1)"),
            ("k_n_per_m", np.isfinite(self.k_n_per_m) & (self.k_n_per_m > 0), "a finite number > 0"),
        ) + tuple((k, np.isnan(v) | (np.isfinite(v) & (v >= 0)), "empty or a finite number >= 0") for k, v in self.std.items())
        for name, ok, expected in checks:
            if not ok.all():
                value = getattr(self, name) if name in ("mode", "fn_hz", "zeta", "k_n_per_m") else self.std[name]
                raise InputError(expected, got=value[~ok][0].item(), column=name, row=_row(~ok))
        keys = np.rec.fromarrays([self.pose_index, self.direction, self.mode])
        _, first, counts = np.unique(keys, return_index=True, return_counts=True)
        if (counts > 1).any():
            dup = first[counts > 1][0]
            raise InputError(
                "one row per pose_id, direction and mode",
                got=f"{self.poses.pose_id[self.pose_index[dup]]}/{self.direction[dup]}/{self.mode[dup]} repeated",
                column="mode",
            )

    def __len__(self) -> int:
        return len(self.fn_hz)

    def __eq__(self, other) -> bool:
        if not isinstance(other, ModalTable) or self.poses != other.poses or set(self.std) != set(other.std) or set(self.cross) != set(other.cross):
            return False
        fields = ("pose_index", "direction", "mode", "fn_hz", "zeta", "k_n_per_m", "source")
        return all(_same(getattr(self, f), getattr(other, f)) for f in fields) and all(
            _same(self.std[k], other.std[k]) for k in self.std
        ) and all(_same(self.cross[k], other.cross[k]) for k in self.cross)

    @property
    def wn_rad_s(self) -> np.ndarray:
        return 2.0 * np.pi * self.fn_hz

    @property
    def m_kg(self) -> np.ndarray:
        return self.k_n_per_m / self.wn_rad_s**2

    @property
    def c_ns_per_m(self) -> np.ndarray:
        return 2.0 * self.zeta * self.k_n_per_m / self.wn_rad_s

    @property
    def directions(self) -> tuple[str, ...]:
        return tuple(d for d in DIRECTIONS if d in set(self.direction.tolist()))

    def mode_numbers(self, direction: str) -> tuple[int, ...]:
        return tuple(int(m) for m in np.unique(self.mode[self.direction == direction]))

    def modes(self, pose_id: str, direction: str) -> tuple[Mode, ...]:
        """The modes of one pose in one direction, in mode-number order."""
        rows = np.flatnonzero((self.pose_index == self.poses.index(pose_id)) & (self.direction == direction))
        rows = rows[np.argsort(self.mode[rows])]
        return tuple(Mode(float(self.fn_hz[i]), float(self.zeta[i]), float(self.k_n_per_m[i])) for i in rows)

    def select_poses(self, indices) -> "ModalTable":
        """The rows of the given poses (indices into `poses`), as a new table."""
        keep = [int(i) for i in indices]
        p = self.poses
        poses = PoseSet(
            pose_id=tuple(p.pose_id[i] for i in keep),
            position_mm=p.position_mm[keep],
            orientation=p.orientation,
            orientation_deg=p.orientation_deg[keep],
            joints_deg=None if p.joints_deg is None else p.joints_deg[keep],
        )
        remap = {old: new for new, old in enumerate(keep)}
        rows = np.flatnonzero(np.isin(self.pose_index, keep))
        return ModalTable(
            poses=poses,
            pose_index=[remap[int(i)] for i in self.pose_index[rows]],
            direction=self.direction[rows],
            mode=self.mode[rows],
            fn_hz=self.fn_hz[rows],
            zeta=self.zeta[rows],
            k_n_per_m=self.k_n_per_m[rows],
            std={k: v[rows] for k, v in self.std.items()},
            source=None if self.source is None else tuple(self.source[i] for i in rows),
            cross={k: v[rows] for k, v in self.cross.items()},
        )

    def soft_modes(self) -> list[str]:
        """The rows whose stiffness is below IMPLAUSIBLE_K_N_PER_M (no milling tool tip is that soft:
        N/mm read as N/m, or an accelerance read as a receptance), one line each."""
        return [f"pose {self.poses.pose_id[self.pose_index[i]]}, {self.direction[i]} mode {self.mode[i]}: k = {self.k_n_per_m[i]:.3g} N/m, "
                f"softer than any milling tool tip ({IMPLAUSIBLE_K_N_PER_M:.0e} N/m)" for i in np.flatnonzero(self.k_n_per_m < IMPLAUSIBLE_K_N_PER_M)]

    def summary(self) -> dict:
        """Counts and parameter ranges, as `posedyn data check` reports them."""
        ranges = {}
        for name, values in (("fn_hz", self.fn_hz), ("zeta", self.zeta), ("k_n_per_m", self.k_n_per_m)):
            ranges[name] = [float(values.min()), float(values.max())]
        return {
            "rows": len(self),
            "poses": len(np.unique(self.pose_index)),
            "directions": list(self.directions),
            "modes": {d: len(self.mode_numbers(d)) for d in self.directions},
            "ranges": ranges,
        }


def _row(mask: np.ndarray) -> int:
    """1-based row number of the first True entry."""
    return int(np.flatnonzero(mask)[0]) + 1
