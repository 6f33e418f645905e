"""The one schema of a model folder's ``config.json``, for every model kind (issue 32).

:func:`check_config` runs when a model folder is read (:func:`keyfill.learn.modelfile.read_config`): every
field a loader uses is checked for its type, size and range before any loader touches it, and a field that is
wrong is one :class:`~keyfill.errors.ModelError` naming the file and the field::

    model/config.json: architecture.heads must be a whole number from 1 to 256, got -8

The schema has two parts:

* the fields every model shares (:func:`_shared`): ``kind``; the ``skeleton`` (joint ``names``, ``parents``,
  rest ``offsets``, and in the full form per-joint ``channels``, ``up_axis``, ``meters_per_unit``); ``fps``;
  ``folded_root``; ``training`` (free-form notes of the run that made the model);
* per kind, its sections (:data:`KINDS`). A section that holds a method's settings dataclass
  (``architecture``: :class:`keyfill.learn.transformer.config.ModelConfig`, ``gan``:
  :class:`keyfill.learn.gan.config.GanConfig`) is checked from the dataclass itself: each field by its
  annotation (``int``, ``float``, ``bool``, ``str``, ``dict``) and the method's table of number limits, then
  the dataclass is built, so that its own cross-field checks run. A field added to the dataclass later is
  checked with no change here.

Fields the schema does not know are left alone (notes a later keyfill may add).
"""

from __future__ import annotations

import dataclasses
import importlib
import math
import os

from keyfill.errors import KeyfillError, ModelError


class _Bad(Exception):
    """A field that breaks the schema: its message names the field."""


def _short(value) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def _must(field: str, what: str, value) -> None:
    raise _Bad(f"{field} must be {what}, got {_short(value)}")


def _get(data: dict, field: str, key: str, required: bool = True):
    if key not in data:
        if required:
            raise _Bad(f"{field}{key} is missing")
        return None
    return data[key]


def _is_number(v) -> bool:
    return type(v) in (int, float) and math.isfinite(v)


def _number(field: str, v, low=None, high=None, *, whole=False, low_ok=True) -> None:
    """``v`` an int (or, unless ``whole``, a float) from ``low`` (excluded unless ``low_ok``) to ``high``."""
    from keyfill.limits import max_abs

    high = max_abs() if high is None else high
    low = -max_abs() if low is None else low
    kind = "a whole number" if whole else "a number"
    ok = type(v) is int if whole else _is_number(v)
    if not (ok and (low <= v if low_ok else low < v) and v <= high):
        if low == 1 and whole and high >= 2**31:
            _must(field, "a positive integer", v)
        _must(field, f"{kind} from {low:g}{'' if low_ok else ' (excluded)'} to {high:g}", v)


def _string(field: str, v, choices=None) -> None:
    if not isinstance(v, str) or (choices is not None and v not in choices):
        _must(field, "a string" if choices is None else "one of " + ", ".join(map(repr, choices)), v)


def _list(field: str, v, length=None) -> list:
    if not isinstance(v, list) or (length is not None and len(v) != length):
        _must(field, "a list" if length is None else f"a list of {length}", v)
    return v


def _object(field: str, v) -> dict:
    if not isinstance(v, dict):
        _must(field, "a JSON object", v)
    return v


def _vectors(field: str, v, n: int, low=None, above=None) -> None:
    for i, o in enumerate(_list(field, v, n)):
        for k, x in enumerate(_list(f"{field}[{i}]", o, 3)):
            _number(f"{field}[{i}][{k}]", x, above if above is not None else low, low_ok=above is None)


def _numbers(field: str, v, n=None, above=None) -> None:
    for i, x in enumerate(_list(field, v, n)):
        _number(f"{field}[{i}]", x, above, low_ok=above is None)


# --- the parts every model shares ------------------------------------------------------------------


def _skeleton(config: dict) -> int:
    """Check ``config["skeleton"]``; its number of joints."""
    from keyfill.limits import max_joints
    from keyfill.motion import POSITION_CHANNELS, ROTATION_CHANNELS, check_channels

    sk = _object("skeleton", _get(config, "", "skeleton"))
    names = _list("skeleton.names", _get(sk, "skeleton.", "names"))
    if not 1 <= len(names) <= max_joints():
        _must("skeleton.names", f"a list of 1 to {max_joints()} joint names", names)
    for j, n in enumerate(names):
        if not isinstance(n, str) or not n:
            _must(f"skeleton.names[{j}]", "a joint name (a string)", n)
        if n in names[:j]:
            raise _Bad(f"skeleton.names[{j}] {n!r} names a joint twice")
    J = len(names)
    for j, p in enumerate(_list("skeleton.parents", _get(sk, "skeleton.", "parents"), J)):
        if type(p) is not int or not -1 <= p < j:
            _must(f"skeleton.parents[{j}]", f"the index of an earlier joint (-1 to {j - 1})", p)
    _vectors("skeleton.offsets", _get(sk, "skeleton.", "offsets"), J)
    if "channels" in sk:  # the full form: what a BVH file of the model's skeleton holds
        known = POSITION_CHANNELS + ROTATION_CHANNELS
        for j, chans in enumerate(_list("skeleton.channels", sk["channels"], J)):
            for k, c in enumerate(_list(f"skeleton.channels[{j}]", chans)):
                _string(f"skeleton.channels[{j}][{k}]", c, known)
            try:
                check_channels(chans)
            except (ValueError, KeyfillError) as e:
                raise _Bad(f"skeleton.channels[{j}]: {e}") from None
        _string("skeleton.up_axis", _get(sk, "skeleton.", "up_axis"), ("Y", "Z"))
        _number("skeleton.meters_per_unit", _get(sk, "skeleton.", "meters_per_unit"), 0, low_ok=False)
    return J


def _shared(config: dict, kind_fields: dict) -> int:
    from keyfill.limits import MAX_FPS, MIN_FPS

    _string("kind", config.get("kind"))
    J = _skeleton(config)
    if "fps" in config or "fps" in kind_fields:
        _number("fps", _get(config, "", "fps"), MIN_FPS, MAX_FPS)
    folded = "folded_root" in config or "folded_root" in kind_fields
    if folded and not isinstance(_get(config, "", "folded_root"), bool):
        _must("folded_root", "true or false", config["folded_root"])
    if "training" in config and config["training"] is not None:
        _object("training", config["training"])
    return J


# --- settings dataclasses ---------------------------------------------------------------------------


#: the JSON values each annotation of a settings dataclass takes (an int where a float is meant)
_ANNOTATED = {"int": ((int,), "a whole number"), "float": ((int, float), "a number"), "bool": ((bool,), "true or false"),
              "str": ((str,), "a string"), "dict": ((dict,), "a JSON object"), "list": ((list,), "a list")}


def _limits(table: dict, name: str):
    """``(whole, low, high, low_ok)`` of ``name`` in a method's table of number limits, or None.

    Two layouts occur: ``(whole, low, high)`` (the transformer's) and ``(low, high, low_ok)`` (the gan's)."""
    entry = table.get(name)
    if entry is None:
        return None
    if isinstance(entry[0], bool):
        return entry[0], entry[1], entry[2], True
    return None, entry[0], entry[1], entry[2]


def _dataclass(section: str, data, spec: tuple) -> None:
    """``data`` (a section) against the settings dataclass ``spec = (module, class, limits table)``."""
    module = importlib.import_module(spec[0])
    cls, table = getattr(module, spec[1]), getattr(module, spec[2], {}) if spec[2] else {}
    data = _object(section, data)
    fields = {f.name: f for f in dataclasses.fields(cls)}
    for name, value in data.items():
        field = f"{section}.{name}"
        if name not in fields:
            raise _Bad(f"{field} is not a setting of {cls.__name__} (settings: {', '.join(fields)})")
        annotation = str(fields[name].type)
        types, what = _ANNOTATED.get(annotation, (None, None))
        limits = _limits(table, name)
        if limits is not None:
            whole, low, high, low_ok = limits
            _number(field, value, low, high, whole=annotation == "int" if whole is None else whole, low_ok=low_ok)
        elif types is not None and type(value) not in types:
            _must(field, what, value)
        elif types is not None and type(value) in (int, float):
            _number(field, value, whole=annotation == "int")
    for name, check in spec[3].items() if len(spec) > 3 else ():
        if name in data:
            check(f"{section}.{name}", data[name])
    try:
        getattr(cls, "from_json", None)(data) if hasattr(cls, "from_json") else cls(**data)
    except (KeyfillError, TypeError, ValueError) as e:
        raise _Bad(f"{section}: {' '.join(str(e).split())[:200]}") from None


# --- the kinds --------------------------------------------------------------------------------------


def _gan_widths(field: str, value) -> None:
    from keyfill.learn.gan.config import MAX_CHANNELS

    for net, widths in _object(field, value).items():
        for i, w in enumerate(_list(f"{field}.{net}", widths)):
            _number(f"{field}.{net}[{i}]", w, 1, MAX_CHANNELS, whole=True)


def _transformer(config: dict, J: int) -> None:
    _dataclass("architecture", _get(config, "", "architecture"),
               ("keyfill.learn.transformer.config", "ModelConfig", "NUMBER_LIMITS"))
    stats = _object("statistics", _get(config, "", "statistics"))
    _numbers("statistics.pos_mean", _get(stats, "statistics.", "pos_mean"), 3 * J)
    _numbers("statistics.pos_std", _get(stats, "statistics.", "pos_std"), 3 * J, above=0)


def _gan(config: dict, J: int) -> None:
    from keyfill.rotations import EULER_ORDERS

    _dataclass("gan", _get(config, "", "gan"),
               ("keyfill.learn.gan.config", "GanConfig", "_RANGES", {"widths": _gan_widths}))
    ranges = _object("ranges", _get(config, "", "ranges"))
    driven = _list("ranges.driven", _get(ranges, "ranges.", "driven"))
    for i, j in enumerate(driven):
        _number(f"ranges.driven[{i}]", j, 1, J - 1, whole=True)
    D = len(driven)
    for i, order in enumerate(_list("ranges.orders", _get(ranges, "ranges.", "orders"), D)):
        _string(f"ranges.orders[{i}]", order, EULER_ORDERS)
    for key in ("lo", "hi"):
        _vectors(f"ranges.{key}", _get(ranges, "ranges.", key), D)
    _string("stage", _get(config, "", "stage"), ("path", "full"))


def _arnn(config: dict, J: int) -> None:
    _string("arch", _get(config, "", "arch"))
    for name, size in _object("sizes", config.get("sizes", {})).items():
        _number(f"sizes.{name}", size, 1, 2**31, whole=True)
    norm = _object("normalizer", _get(config, "", "normalizer"))
    mean = _get(norm, "normalizer.", "mean")
    _numbers("normalizer.mean", mean)  # one per animation variable: the Normalizer checks how many
    _numbers("normalizer.std", _get(norm, "normalizer.", "std"), len(mean), above=0)
    if "variables" in config:
        for i, v in enumerate(_list("variables", config["variables"])):
            _string(f"variables[{i}]", v)


#: per model kind: (its checker, the shared fields it needs)
KINDS = {
    "transformer": (_transformer, {"folded_root"}),
    "gan": (_gan, {"fps", "folded_root"}),
    "arnn": (_arnn, set()),
}


def check_config(config: dict, path: str | os.PathLike) -> None:
    """Raise a :class:`ModelError` naming ``path`` (the ``config.json``) and the field unless ``config`` fits
    the schema of its kind (a kind the schema does not know: only the shared fields). The error's ``path``
    is set, so ``--json`` names the file."""
    check, needed = KINDS.get(config.get("kind"), (None, set()))
    try:
        J = _shared(config, needed)
        if check is not None:
            check(config, J)
    except _Bad as e:
        error = ModelError(f"{path}: {e}")
        error.path = str(path)
        raise error from None
