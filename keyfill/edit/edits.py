"""Edit files (TOML) for ``keyfill edit-tangents`` and ``keyfill pose``.

Units are the curves file's: positions in its length unit, angles in
degrees, times in frames. Example::

    tolerance = 0.1                    # reach targets this closely (default 1e-3 x character size)
    epsilon = 0.01                     # pin/contact band of Eq. 11 (default 1e-4 x character size)
    pins = ["Hips"]                    # points whose trajectories stay, in every edit
    lock = ["joint_Root"]              # joints or controls ("Spine.Xrotation") no edit may change
    break_tangents = false             # default for every move edit (see [[edit]])

    [limits]                           # per control (or all rotation channels of a joint): [low, high]
    "LowerArm_L.Zrotation" = [-150, 0]

    [stiffness]                        # per joint or control; default 1; higher moves less
    Spine = 10

    [[contact]]                        # a point that stays put between two keys
    joint = "Toes_R"
    frames = [10, 20]

    [[edit]]                           # move a point at a frame between keys
    joint = "Hand_L"
    offset = [0, 0, 0]                 # in the joint's frame (optional)
    frame = 15                         # or time = 15.5
    move = [0, 10, 0]                  # or target = [x, y, z] (world)
    orientation = [1, 0, 0, 0]         # optional world orientation (w, x, y, z)
    hold = [12]                        # optional frames where the point keeps its current state
    break_tangents = false             # optional: break the segment's end tangents and change only
                                       # this segment (E_b keeps them close); default keeps unified
                                       # keys unified, so the neighbouring segments follow
    pins = [{joint = "Hand_R", offset = [0, 5, 0]}]   # optional, for this edit only
    contacts = [{joint = "Toes_L", frames = [0, 10]}] # optional, for this edit only

    [[edit]]                           # a timing edit (Eq. 12)
    frame = 15
    timing = 2.0                       # frames; > 0 spreads the frames around 15 apart (faster)
    joint = "Hand_L"                   # optional: only the controls that move this joint

Edits are applied in order. :func:`load` checks the whole file against the
curves before anything is solved, so a bad file fails with one message
(``path:line: ...``) and no output.
"""

from __future__ import annotations

import math
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from keyfill import limits
from keyfill.curves import Curves
from keyfill.edit.rig import Point
from keyfill.errors import FormatError, KeyfillError, NoSuchFile
from keyfill.files import read_regular


@dataclass(frozen=True, eq=False)
class Contact:
    """``point`` stays put from key time ``start`` to key time ``end``."""

    point: Point
    start: float
    end: float


@dataclass(frozen=True, eq=False)
class Manipulation:
    """Move ``point`` at ``time`` to ``target`` (world position, and optionally orientation)."""

    index: int
    line: int
    point: Point
    time: float
    target: np.ndarray | None
    move: np.ndarray | None
    orientation: np.ndarray | None
    holds: tuple[float, ...]
    pins: tuple[Point, ...]
    contacts: tuple[Contact, ...]
    break_tangents: bool = False


@dataclass(frozen=True, eq=False)
class TimingEdit:
    """Eq. 12: widen (``amount > 0``) or narrow the frame spacing around ``time``."""

    index: int
    line: int
    time: float
    amount: float
    joint: int | None


@dataclass(frozen=True, eq=False)
class EditFile:
    """A parsed, checked edit file.

    Attributes:
        edits: manipulations and timing edits, in file order.
        pins, contacts: constraints of every edit.
        limits: control index -> (low, high) in internal units (radians, file units).
        stiffness: ``(C,)`` per-control stiffness (the diagonal of D).
        locked: control indices no edit may change.
        tolerance, epsilon: file units, or None for the defaults.
    """

    path: str
    edits: tuple
    pins: tuple[Point, ...] = ()
    contacts: tuple[Contact, ...] = ()
    limits: dict = field(default_factory=dict)
    stiffness: np.ndarray | None = None
    locked: frozenset = frozenset()
    tolerance: float | None = None
    epsilon: float | None = None


_TOP = {"tolerance", "epsilon", "pins", "lock", "limits", "stiffness", "contact", "edit", "break_tangents"}
_MOVE = {
    "joint",
    "offset",
    "frame",
    "time",
    "target",
    "move",
    "orientation",
    "hold",
    "pins",
    "contacts",
    "break_tangents",
}
_TIMING = {"frame", "time", "timing", "joint"}
_POINT = {"joint", "offset", "orientation"}
_CONTACT = {"joint", "offset", "frames"}


def _short(value: int) -> str:
    """A huge integer as a short text (its digits could run to thousands)."""
    if abs(value) < 10**30:
        return str(value)
    return f"{'-' if value < 0 else ''}about 1e{int(abs(value).bit_length() * 0.30103)}"


class _Where:
    """Line numbers of tables and keys in the TOML text, for messages."""

    def __init__(self, text: str):
        self.lines = text.splitlines()

    def table(self, name: str, n: int) -> int | None:
        pat = re.compile(r"^\s*\[\[\s*" + re.escape(name) + r"\s*\]\]")
        hits = [i + 1 for i, line in enumerate(self.lines) if pat.match(line)]
        return hits[n] if n < len(hits) else None

    def header(self, name: str) -> int | None:
        pat = re.compile(r"^\s*\[\s*" + re.escape(name) + r"\s*\]")
        return next((i + 1 for i, line in enumerate(self.lines) if pat.match(line)), None)

    def key(self, name: str, after: int | None = None) -> int | None:
        pat = re.compile(r"^\s*[\"']?" + re.escape(name) + r"[\"']?\s*=")
        start = (after or 1) - 1
        for i in range(start, len(self.lines)):
            if pat.match(self.lines[i]):
                return i + 1
        return after


class _Parser:
    def __init__(self, path: str, text: str, curves: Curves, mode: str, frame: float | None = None):
        self.path = path
        self.frame = frame
        self.where = _Where(text)
        self.curves = curves
        self.sk = curves.skeleton
        self.mode = mode
        self.line: int | None = None
        self.context = ""

    def fail(self, message: str, params: tuple[str, ...] = ()) -> FormatError:
        return FormatError(f"{self.context}{message}", self.path, self.line, params=params)

    # --- values ------------------------------------------------------------

    def check_keys(self, table: dict, allowed: set[str], what: str) -> None:
        unknown = sorted(set(table) - allowed)
        if unknown:
            raise self.fail(f"unknown field {unknown[0]!r} in {what} (expected: {', '.join(sorted(allowed))})")

    def number(self, value, what: str) -> float:
        """A finite number of at most :func:`keyfill.limits.max_abs` in magnitude (TOML integers of any size too)."""
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.fail(f"{what} must be a number, got {value!r}")
        limit = limits.max_abs()
        if isinstance(value, int) and not -limit <= value <= limit:  # compared as integers: no overflow
            raise self.fail(f"{what} is {_short(value)}, beyond {limit:g}")
        if not math.isfinite(value):
            raise self.fail(f"{what} is {value}, not a finite number")
        if not abs(value) <= limit:
            raise self.fail(f"{what} is {value:g}, beyond {limit:g}")
        return float(value)

    def vector(self, value, n: int, what: str) -> np.ndarray:
        if not isinstance(value, list) or len(value) != n:
            raise self.fail(f"{what} must be a list of {n} numbers, got {value!r}")
        return np.array([self.number(v, what) for v in value])

    def joint(self, value, what: str = "joint") -> int:
        if not isinstance(value, str):
            raise self.fail(f"{what} must be a joint name (a string), got {value!r}")
        try:
            return self.sk.index(value)
        except KeyfillError as e:
            raise self.fail(str(e)) from None

    def time(self, table: dict, what: str) -> float:
        if self.frame is not None:
            if "frame" not in table and "time" not in table:
                return self.inside(self.frame, "frame", params=("frame",))  # load()'s frame
            given = table.get("frame", table.get("time"))
            if isinstance(given, (int, float)) and not isinstance(given, bool):
                given = self.number(given, "frame" if "frame" in table else "time")
                if given != self.frame:
                    raise self.fail(f"frame is {self.frame:g} but this edit is at frame {given:g}", ("frame",))
        if ("frame" in table) == ("time" in table):
            raise self.fail(f"{what} needs one of 'frame' or 'time'")
        if "frame" in table:
            f = table["frame"]
            if isinstance(f, bool) or not isinstance(f, int):
                raise self.fail(f"frame must be a whole number, got {f!r} (use 'time' for times between frames)")
        t = self.number(table.get("frame", table.get("time")), "frame" if "frame" in table else "time")
        return self.inside(t, "frame" if "frame" in table else "time")

    def inside(self, t: float, what: str, params: tuple[str, ...] = ()) -> float:
        times = self.curves.times
        last = min(times[-1], self.curves.num_frames - 1)
        if not times[0] <= t <= last:
            raise self.fail(f"{what} {t:g} is outside the curves (keys from {times[0]:g} to {times[-1]:g})", params)
        return t

    def point(self, spec, what: str, orientation_ok: bool = True) -> Point:
        if isinstance(spec, str):
            return Point(self.joint(spec, what))
        if not isinstance(spec, dict):
            raise self.fail(f"{what} must be a joint name or a table with joint and offset, got {spec!r}")
        self.check_keys(spec, _POINT if orientation_ok else _POINT - {"orientation"}, what)
        if "joint" not in spec:
            raise self.fail(f"{what} needs a joint")
        offset = self.vector(spec["offset"], 3, f"{what} offset") if "offset" in spec else np.zeros(3)
        orient = spec.get("orientation", False)
        if not isinstance(orient, bool):
            raise self.fail(f"{what} orientation must be true or false")
        return Point(self.joint(spec["joint"], what), offset, orient)

    def contact(self, spec, what: str) -> Contact:
        if not isinstance(spec, dict):
            raise self.fail(f"{what} must be a table with joint and frames, got {spec!r}")
        self.check_keys(spec, _CONTACT, what)
        if "frames" not in spec:
            raise self.fail(f"{what} needs frames = [first key, last key]")
        point = self.point({k: v for k, v in spec.items() if k != "frames"}, what, orientation_ok=False)
        frames = spec["frames"]
        if not isinstance(frames, list) or len(frames) != 2:
            raise self.fail(f"{what} frames must be [first key, last key], got {frames!r}")
        a, b = (self.number(f, f"{what} frame") for f in frames)
        keys = ", ".join(f"{t:g}" for t in self.curves.times)
        for f in (a, b):
            if self.curves.key_index(f) is None:
                raise self.fail(
                    f"{what} on {self.sk.names[point.joint]}: frame {f:g} is not a key (keys: {keys}); "
                    "a contact spans whole segments between keys"
                )
        if not a < b:
            raise self.fail(
                f"{what} on {self.sk.names[point.joint]}: frames [{a:g}, {b:g}] must go from an earlier key to a later one"
            )
        return Contact(point, a, b)

    def controls(self, name, what: str) -> list[int]:
        """Control indices named by ``"Joint"`` (all its controls) or ``"Joint.Channel"``."""
        if not isinstance(name, str):
            raise self.fail(f"{what} must name a joint or a control like 'Spine.Xrotation', got {name!r}")
        if name in self.sk.names:
            j = self.sk.index(name)
            out = [i for i, c in enumerate(self.curves.controls) if c.joint == j]
            if not out:
                raise self.fail(f"{what}: joint {name!r} has no animated channels")
            return out
        try:
            return [self.curves.control_index(name)]
        except KeyfillError as e:
            raise self.fail(f"{what}: {e}") from None

    # --- sections ----------------------------------------------------------

    def parse(self, data: dict) -> EditFile:
        self.check_keys(data, _TOP, "the edit file")
        out: dict = {}
        for key in ("tolerance", "epsilon"):
            if key in data:
                self.line = self.where.key(key)
                v = self.number(data[key], key)
                if v <= 0:
                    raise self.fail(f"{key} must be positive, got {v:g}")
                out[key] = v
        self.line = self.where.key("pins")
        out["pins"] = tuple(self.point(p, "pin") for p in self._list(data.get("pins", []), "pins"))
        self.line = self.where.key("lock")
        out["locked"] = frozenset(c for n in self._list(data.get("lock", []), "lock") for c in self.controls(n, "lock"))
        out["limits"] = self.limits(data.get("limits", {}))
        out["stiffness"] = self.stiffness(data.get("stiffness", {}))
        self.line = self.where.key("break_tangents")
        self.break_default = self.flag(data.get("break_tangents", False), "break_tangents")
        contacts = []
        for n, spec in enumerate(self._list(data.get("contact", []), "contact")):
            self.line = self.where.table("contact", n)
            contacts.append(self.contact(spec, f"contact {n + 1}"))
        out["contacts"] = tuple(contacts)
        edits = []
        for n, spec in enumerate(self._list(data.get("edit", []), "edit")):
            self.line = self.where.table("edit", n)
            self.context = f"edit {n + 1}: "
            if not isinstance(spec, dict):
                raise self.fail("must be a table ([[edit]])")
            edits.append(self.timing(spec, n) if "timing" in spec else self.manipulation(spec, n))
            self.context = ""
        if not edits:
            self.line = None
            raise self.fail("no [[edit]] in the file; nothing to do")
        return EditFile(path=self.path, edits=tuple(edits), **out)

    def flag(self, value, what: str) -> bool:
        if not isinstance(value, bool):
            raise self.fail(f"{what} must be true or false, got {value!r}")
        return value

    def _list(self, value, what: str) -> list:
        if not isinstance(value, list):
            raise self.fail(f"{what} must be a list, got {value!r}")
        return value

    def limits(self, table) -> dict:
        if not isinstance(table, dict):
            raise self.fail(f"[limits] must be a table, got {table!r}")
        out = {}
        for name, rng in table.items():
            self.line = self.where.key(name, self.where.header("limits"))
            what = f"limit on {name}"
            idx = self.controls(name, what)
            if isinstance(rng, list) and len(rng) == 2:
                low, high = (self.number(v, what) if not (isinstance(v, float) and math.isinf(v)) else v for v in rng)
            else:
                raise self.fail(f"{what} must be [low, high], got {rng!r}")
            if not low <= high:
                raise self.fail(f"{what}: low {low:g} is above high {high:g}")
            for c in idx:
                ctl = self.curves.controls[c]
                unit = math.radians(1.0) if ctl.is_rotation else 1.0
                lo, hi = low * unit, high * unit
                vals = self.curves.values[:, c]
                bad = np.flatnonzero((vals < lo - 1e-12) | (vals > hi + 1e-12))
                if len(bad):
                    k = bad[0]
                    shown = vals[k] / unit
                    units = " degrees" if ctl.is_rotation else ""
                    raise self.fail(
                        f"limit [{low:g}, {high:g}]{units} on {ctl.name(self.sk)}: the key at frame "
                        f"{self.curves.times[k]:g} is already outside it ({shown:.6g}{units}); keys never move, so widen the limit"
                    )
                out[c] = (lo, hi)
        return out

    def stiffness(self, table) -> np.ndarray:
        if not isinstance(table, dict):
            raise self.fail(f"[stiffness] must be a table, got {table!r}")
        out = np.ones(self.curves.num_controls)
        # joints first, then single controls, so "Spine.Xrotation" overrides "Spine"
        for name, value in sorted(table.items(), key=lambda kv: "." in kv[0]):
            self.line = self.where.key(name, self.where.header("stiffness"))
            idx = self.controls(name, f"stiffness of {name}")
            v = self.number(value, f"stiffness of {name}")
            if v <= 0:
                raise self.fail(f"stiffness of {name} must be positive, got {v:g} (use lock to forbid changes)")
            out[idx] = v
        return out

    def manipulation(self, spec: dict, n: int) -> Manipulation:
        self.check_keys(spec, _MOVE, "a move edit")
        if "joint" not in spec:
            raise self.fail("needs a joint (the point to move) or timing (a timing edit)")
        point = self.point({k: spec[k] for k in ("joint", "offset") if k in spec}, "the moved point")
        t = self.time(spec, "a move edit")
        if self.mode == "tangents" and self.curves.key_index(t) is not None:
            raise self.fail(
                f"frame {t:g} is a key; edit-tangents moves only the frames between keys "
                f"(use keyfill pose --frame {t:g} to change a key pose)"
            )
        if self.mode == "pose" and self.curves.key_index(t) is None:
            raise self.fail(f"frame {t:g} is not a key; keyfill pose changes key poses")
        if ("target" in spec) == ("move" in spec):
            raise self.fail("needs one of 'target' (world position) or 'move' (world displacement)")
        target = self.vector(spec["target"], 3, "target") if "target" in spec else None
        move = self.vector(spec["move"], 3, "move") if "move" in spec else None
        orientation = None
        if "orientation" in spec:
            q = self.vector(spec["orientation"], 4, "orientation")
            norm = float(np.linalg.norm(q))
            if norm < 1e-9:
                raise self.fail("orientation must be a unit quaternion (w, x, y, z), got zeros")
            orientation = q / norm
            point = Point(point.joint, point.offset, True)
        holds = tuple(
            self.inside(self.number(h, "hold frame"), "hold frame") for h in self._list(spec.get("hold", []), "hold")
        )
        if any(abs(h - t) < 1e-9 for h in holds):
            raise self.fail(f"hold frame {t:g} is the frame being edited")
        pins = tuple(self.point(p, "pin") for p in self._list(spec.get("pins", []), "pins"))
        contacts = tuple(
            self.contact(c, f"contact {k + 1}") for k, c in enumerate(self._list(spec.get("contacts", []), "contacts"))
        )
        if self.mode == "pose" and ("hold" in spec or "break_tangents" in spec):
            raise self.fail("hold and break_tangents apply to edit-tangents, not to keyfill pose")
        broken = self.flag(spec.get("break_tangents", self.break_default), "break_tangents")
        return Manipulation(n + 1, self.line or 0, point, t, target, move, orientation, holds, pins, contacts, broken)

    def timing(self, spec: dict, n: int) -> TimingEdit:
        if self.mode == "pose":
            raise self.fail("timing edits change tangents; use them with keyfill edit-tangents")
        self.check_keys(spec, _TIMING, "a timing edit")
        t = self.time(spec, "a timing edit")
        if self.curves.key_index(t) is not None:
            raise self.fail(f"frame {t:g} is a key; a timing edit scales the spacing between keys")
        amount = self.number(spec["timing"], "timing")
        joint = self.joint(spec["joint"]) if "joint" in spec else None
        return TimingEdit(n + 1, self.line or 0, t, amount, joint)


def load(path: str | Path, curves: Curves, mode: str = "tangents", frame: float | None = None) -> EditFile:
    """Read and check an edit file against ``curves``.

    ``mode`` is ``"tangents"`` (edit frames between keys) or ``"pose"`` (edit
    key poses; ``frame`` is the key for edits that give none). Raises
    :class:`FormatError` naming the file and line (:class:`NoSuchFile` when there is no file).
    """
    path = Path(path)
    if not path.exists():
        raise NoSuchFile(path)
    try:  # a regular file of bounded size: never /dev/zero or a FIFO
        text = read_regular(path, limits.MAX_SETTINGS_BYTES, "the edit file").decode("utf-8")
    except UnicodeDecodeError as e:
        raise FormatError(f"cannot read the edit file ({e})", path) from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        m = re.search(r"\(at line (\d+)", str(e))
        raise FormatError(
            f"not valid TOML: {str(e).split(' (at line')[0]}", path, int(m.group(1)) if m else None
        ) from None
    except ValueError as e:  # tomllib's int() of an integer of thousands of digits
        raise FormatError(f"not a usable edit file: {str(e).split(':')[0]}", path) from None
    except RecursionError:  # tomllib nests arrays and inline tables by recursion
        raise FormatError("not a usable edit file: arrays or tables nested too deeply", path) from None
    return _Parser(str(path), text, curves, mode, frame).parse(data)
