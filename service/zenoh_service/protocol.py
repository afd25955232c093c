"""Validation of the service's JSON requests: every way a request can be wrong gets a code and
a message naming the field and what was expected (`RequestError`), before any work is done."""

from __future__ import annotations

import json
import math

from posedyn.stability.cutting import MAX_COEFFICIENT_PA, MAX_TEETH, RPM_RANGE

POSE_FIELDS = ("pose_id", "x_mm", "y_mm", "z_mm", "beta_deg", "a_deg", "b_deg", "c_deg")
CUT_FIELDS = ("rpm", "teeth", "kt_mpa", "kn_mpa", "radial_immersion", "milling", "feed_angle_deg")

# Physical ranges, (low, high, low inclusive). Positions: a robot cell's workspace (the largest
# industrial arms reach about 3.9 m; the pose model and inverse kinematics narrow it further).
# Cut: spindle speeds of milling spindles, cutting-force coefficients from soft aluminium
# (~100 MPa) to hardened steel and nickel alloys (~6 GPa) with margin.
RANGES = {
    "x_mm": (-10_000.0, 10_000.0, True),
    "y_mm": (-10_000.0, 10_000.0, True),
    "z_mm": (-10_000.0, 10_000.0, True),
    "beta_deg": (-360.0, 360.0, True),
    "a_deg": (-360.0, 360.0, True),
    "b_deg": (-360.0, 360.0, True),
    "c_deg": (-360.0, 360.0, True),
    "rpm": (*RPM_RANGE, True),  # the cut's ranges: posedyn.stability.cutting, as for a cut file or a flag
    "kt_mpa": (0.0, MAX_COEFFICIENT_PA * 1e-6, False),
    "kn_mpa": (0.0, MAX_COEFFICIENT_PA * 1e-6, True),
    "radial_immersion": (0.0, 1.0, False),
    "feed_angle_deg": (-360.0, 360.0, True),
}
TIMEOUT_MS = (1, 3_600_000)  # the querier's budget for one request


class RequestError(Exception):
    """A request the service refuses: `code` (machine-readable) and a message for people."""

    def __init__(self, code: str, message: str, retry_after_ms: int | None = None):
        super().__init__(message)
        self.code, self.message, self.retry_after_ms = code, message, retry_after_ms

    def __reduce__(self):  # crosses the worker processes' boundary intact
        return RequestError, (self.code, self.message, self.retry_after_ms)

    def to_json(self) -> bytes:
        doc = {"error": self.code, "message": self.message}
        if self.retry_after_ms is not None:
            doc["retry_after_ms"] = self.retry_after_ms
        return json.dumps(doc).encode()


#: Longest integer a request may hold (digits).
MAX_INTEGER_DIGITS = 30


def parse_json(payload: bytes | None, max_bytes: int, required: bool = True):
    """The JSON document of a payload: size, UTF-8, syntax, and no NaN or Infinity."""
    if payload is None or len(payload) == 0:
        if required:
            raise RequestError("missing_payload", "expected a JSON payload, got none")
        return None
    if len(payload) > max_bytes:
        raise RequestError("payload_too_large", f"expected a payload of at most {max_bytes} bytes, got {len(payload)}")
    try:
        text = payload.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise RequestError("malformed_json", f"expected UTF-8 JSON, got undecodable bytes at offset {exc.start}") from None

    def refuse(constant):
        raise RequestError("not_finite", f"expected finite numbers, got {constant}")

    def unique(pairs):  # a key given twice: which one counts is the parser's choice, not the sender's
        keys = [k for k, _ in pairs]
        twice = sorted({k for k in keys if keys.count(k) > 1})
        if twice:
            raise RequestError("malformed_json", f"expected each key once in an object, got {twice[0]!r} twice")
        return dict(pairs)

    def integer(digits):  # no field takes more; Python's own limit (4300 digits) answered with its advice to the server's programmer
        if len(digits.lstrip("-")) > MAX_INTEGER_DIGITS:
            raise RequestError("invalid_field", f"expected integers of at most {MAX_INTEGER_DIGITS} digits, got {len(digits.lstrip('-'))} digits")
        return int(digits)

    try:
        return json.loads(text, parse_constant=refuse, object_pairs_hook=unique, parse_int=integer)
    except RequestError:
        raise
    except (ValueError, RecursionError) as exc:
        raise RequestError("malformed_json", f"expected JSON, got: {exc}") from None


def _object(value, where: str, allowed: tuple[str, ...]) -> dict:
    if not isinstance(value, dict):
        raise RequestError("invalid_field", f"{where}: expected a JSON object, got {type(value).__name__}")
    unknown = sorted(set(value) - set(allowed))
    if unknown:
        raise RequestError("unknown_field", f"{where}: unknown field(s) {unknown}; expected among {list(allowed)}")
    return value


def _number(obj: dict, key: str, where: str, required: bool = True):
    if key not in obj:
        if required:
            raise RequestError("missing_field", f"{where}.{key}: expected a number, got nothing")
        return None
    value = obj[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise RequestError("invalid_field", f"{where}.{key}: expected a number, got {json.dumps(value)[:40]}")
    number = float(value)  # (integers of more than MAX_INTEGER_DIGITS are refused by parse_json: no overflow here)
    if not math.isfinite(number):
        raise RequestError("not_finite", f"{where}.{key}: expected a finite number, got {value}")
    if key in RANGES:
        low, high, closed = RANGES[key]
        if not (low <= number if closed else low < number) or number > high:
            raise RequestError("invalid_field", f"{where}.{key}: expected {'[' if closed else '('}{low:g}, {high:g}], got {number:g}")
    return number


def parse_pose(value, where: str = "pose") -> dict:
    """{pose_id, x_mm, y_mm, z_mm, and beta_deg or a_deg, b_deg, c_deg}, numbers finite."""
    obj = _object(value, where, POSE_FIELDS)
    pose = {k: _number(obj, k, where) for k in ("x_mm", "y_mm", "z_mm")}
    has_beta, has_abc = "beta_deg" in obj, any(k in obj for k in ("a_deg", "b_deg", "c_deg"))
    if has_beta == has_abc:
        raise RequestError("missing_field" if not has_beta else "invalid_field", f"{where}: expected either beta_deg or a_deg, b_deg, c_deg")
    for key in ("beta_deg",) if has_beta else ("a_deg", "b_deg", "c_deg"):
        pose[key] = _number(obj, key, where)
    pose_id = obj.get("pose_id", "pose")
    if not isinstance(pose_id, str) or not pose_id or len(pose_id) > 200:
        raise RequestError("invalid_field", f"{where}.pose_id: expected a non-empty string of at most 200 characters")
    pose["pose_id"] = pose_id
    return pose


def parse_cut(value, where: str = "cut") -> dict:
    """Overrides of the service's default cut (any subset of CUT_FIELDS)."""
    if value is None:
        return {}
    obj = _object(value, where, CUT_FIELDS)
    cut = {}
    for key in CUT_FIELDS:
        if key not in obj:
            continue
        if key == "milling":
            if obj[key] not in ("down", "up"):
                raise RequestError("invalid_field", f"{where}.milling: expected 'down' or 'up', got {json.dumps(obj[key])[:40]}")
            cut[key] = obj[key]
        elif key == "teeth":
            teeth = obj[key]
            if isinstance(teeth, bool) or not isinstance(teeth, int) or not 1 <= teeth <= MAX_TEETH:
                raise RequestError("invalid_field", f"{where}.teeth: expected an integer from 1 to {MAX_TEETH}, got {json.dumps(teeth)[:40]}")
            cut[key] = teeth
        else:
            cut[key] = _number(obj, key, where)
    return cut


def parse_timeout(value: str | None) -> float | None:
    """The querier's budget in seconds, from the query's `timeout_ms` parameter (a selector
    `.../schedule?timeout_ms=4000`; optional): work it cannot wait for is refused `busy` at once,
    and it is answered before the budget runs out."""
    if value is None:
        return None
    low, high = TIMEOUT_MS
    if not value.isdigit() or not low <= int(value) <= high:
        raise RequestError("invalid_field", f"timeout_ms: expected an integer from {low} to {high}, got {value[:40]!r}")
    return int(value) / 1000.0


def parse_schedule_request(payload: bytes | None, max_bytes: int) -> tuple[dict, dict]:
    """(pose, cut overrides)."""
    doc = parse_json(payload, max_bytes)
    obj = _object(doc, "request", ("pose", "cut"))
    if "pose" not in obj:
        raise RequestError("missing_field", "request.pose: expected a pose object, got nothing")
    return parse_pose(obj["pose"]), parse_cut(obj.get("cut"))


def parse_plan_request(payload: bytes | None, max_bytes: int, max_poses: int) -> tuple[list[dict], dict, list[float] | None] | None:
    """(poses, cut overrides, the poses' times or None); None when there is no payload (a query
    for a stored plan). With `times_s` (s, one per pose, increasing) the plan also carries the
    coil's voltage and current trajectory (`absorber.field_plan`)."""
    doc = parse_json(payload, max_bytes, required=False)
    if doc is None:
        return None
    obj = _object(doc, "request", ("poses", "cut", "times_s"))
    poses = obj.get("poses")
    if not isinstance(poses, list) or not poses:
        raise RequestError("missing_field" if poses is None else "invalid_field", "request.poses: expected a non-empty list of pose objects")
    if len(poses) > max_poses:
        raise RequestError("payload_too_large", f"request.poses: expected at most {max_poses} poses, got {len(poses)}")
    parsed = [parse_pose(p, f"poses[{i}]") for i, p in enumerate(poses)]
    return parsed, parse_cut(obj.get("cut")), parse_times(obj.get("times_s"), len(parsed))


def parse_times(value, count: int, where: str = "request.times_s") -> list[float] | None:
    """None, or `count` finite times in seconds, strictly increasing (at least two)."""
    if value is None:
        return None
    if not isinstance(value, list) or len(value) != count or count < 2:
        raise RequestError("invalid_field", f"{where}: expected a list of {count} times, one per pose (at least two poses)")
    times = [_number({"t": v}, "t", f"{where}[{i}]") for i, v in enumerate(value)]
    if any(b <= a for a, b in zip(times, times[1:])):
        raise RequestError("invalid_field", f"{where}: expected increasing times")
    return times


#: What a cell name and a plan id may be (each a key expression's chunk: no wildcards, no '/').
CELL_RULE = "letters, digits, - or _"
PLAN_ID_RULE = "1-100 characters from A-Z a-z 0-9 - _ ."


def valid_cell(cell: str) -> str:
    if not cell or not all(c.isalnum() or c in "-_" for c in cell):
        raise RequestError("invalid_cell", f"cell: expected {CELL_RULE}, got {cell!r}")
    return cell


def valid_plan_id(plan_id: str) -> str:
    if not plan_id or len(plan_id) > 100 or not all(c.isalnum() or c in "-_." for c in plan_id):
        raise RequestError("invalid_plan_id", f"plan id: expected {PLAN_ID_RULE}, got {plan_id[:40]!r}")
    return plan_id
