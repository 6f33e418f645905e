"""The one type check of keyfill's own USD ``customData`` dictionaries.

keyfill writes four dictionaries into USD files (:mod:`keyfill.io.usd`, :mod:`keyfill.io.usd_curves`); a reader
takes each through :func:`checked` first, so a field of another type (a ``string version``, an ``int[] names``)
or a missing required field is one :class:`~keyfill.errors.FormatError` naming the file, the dictionary and the
field, never an exception of the code that uses it:

=================  ===========================================  ==================================================
dictionary         where                                        fields (required ones starred)
=================  ===========================================  ==================================================
:data:`SKELETON`   the Skeleton's ``customData["keyfill"]``     names, channels (string[]), endSiteJoints, keys,
                                                                keyMask (int[]), endSiteOffsets (double3[]),
                                                                keyGiven (string)
:data:`CURVES`     the Curves scope's ``customData["keyfill"]``  layout*, version* (int, 0 or more)
:data:`CURVE`      each curve attribute's ``customData["keyfill"]``  joint*, channel*, unit (strings)
:data:`KNOT`       each spline knot's ``customData``            broken (bool)
=================  ===========================================  ==================================================

Fields keyfill does not know are left alone (a later keyfill may add some).
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass

from keyfill.errors import FormatError


def _is_int(v) -> bool:
    return isinstance(v, numbers.Integral) and not isinstance(v, bool) and abs(int(v)) < 2**62


def _is_seq(v) -> bool:
    """A list or a Vt array (Gf vectors iterate through ``__getitem__``)."""
    return not isinstance(v, (str, bytes, dict)) and hasattr(v, "__len__") and hasattr(v, "__getitem__")


def _is_vec3(v) -> bool:
    return _is_seq(v) and len(v) == 3 and all(isinstance(x, numbers.Real) and not isinstance(x, bool) for x in v)


#: each kind of field: (test, what the message says it must be)
KINDS = {
    "string": (lambda v: isinstance(v, str), "a string"),
    "int": (_is_int, "an integer"),
    "count": (lambda v: _is_int(v) and v >= 0, "an integer of at least 0"),
    "bool": (lambda v: isinstance(v, bool), "a bool"),
    "strings": (lambda v: _is_seq(v) and all(isinstance(x, str) for x in v), "a list of strings (string[])"),
    "ints": (lambda v: _is_seq(v) and all(_is_int(x) for x in v), "a list of integers (int[])"),
    "vec3s": (lambda v: _is_seq(v) and all(_is_vec3(x) for x in v), "a list of 3-vectors (double3[])"),
}


@dataclass(frozen=True)
class Dictionary:
    """One of keyfill's customData dictionaries: ``fields`` name -> kind (of :data:`KINDS`)."""

    what: str
    fields: dict
    required: tuple = ()


SKELETON = Dictionary("the Skeleton's customData keyfill", {
    "names": "strings", "channels": "strings", "endSiteJoints": "ints", "endSiteOffsets": "vec3s",
    "keys": "ints", "keyGiven": "string", "keyMask": "ints"})
CURVES = Dictionary("the Curves prim's customData keyfill", {"layout": "string", "version": "count"},
                    ("layout", "version"))
CURVE = Dictionary("customData keyfill of curve {}", {"joint": "string", "channel": "string", "unit": "string"},
                   ("joint", "channel"))
KNOT = Dictionary("customData of a knot of curve {}", {"broken": "bool"})


def _short(value) -> str:
    text = repr(value) if isinstance(value, (str, int, float, bool, dict)) else f"{type(value).__name__} {value}"
    return text if len(text) <= 40 else text[:37] + "..."


def checked(data, dictionary: Dictionary, label, *names: str) -> dict:
    """``data`` as a ``dict`` once every field ``dictionary`` knows has its kind; ``None`` reads as ``{}``.

    ``names`` fill the ``{}`` of the dictionary's description (a curve's attribute name). Raises a
    :class:`FormatError` (on ``label``, the file) naming the dictionary and the field.
    """
    if data is None:
        data = {}
    what = dictionary.what.format  # the description, made only for a message (a file's knots are many)
    if not isinstance(data, dict):
        raise FormatError(f"{what(*names)} must be a dictionary, got {_short(data)}", label)
    for name in dictionary.required:
        if name not in data:
            raise FormatError(f"{what(*names)} has no {name!r}", label)
    for name, kind in dictionary.fields.items():
        if name in data:
            test, must = KINDS[kind]
            if not test(data[name]):
                raise FormatError(f"{what(*names)}: {name} must be {must}, got {_short(data[name])}", label)
    return data
