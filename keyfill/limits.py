"""Limits on what keyfill reads and on the numbers its options take, and the one number grammar of its
text formats.

Readers check a file's declared sizes against these limits and against the
data the file holds *before* they allocate, so a few bytes can never ask for
gigabytes. The defaults are far above any real motion file; the environment
variables below raise them for a file that really needs more.

=======================  ==============  ======================================================
limit                    default         meaning (environment variable to override)
=======================  ==============  ======================================================
``max_frames``           10,000,000      frames in one motion (``KEYFILL_MAX_FRAMES``)
``max_joints``           10,000          joints in one skeleton (``KEYFILL_MAX_JOINTS``)
``free_joint_frames``    2,000,000       frames x (joints + 8) a file may declare beyond one per
                                         byte of the file (``KEYFILL_FREE_JOINT_FRAMES``); a motion
                                         takes 56 bytes per joint and frame in memory, and USD
                                         costs about as much per frame as per 8 joints
``free_accessor_reads``  16,000,000      numbers a glTF file's accessors may yield, summed over
                                         every time one is read (channels share accessors; sparse
                                         ones are mostly zeros), beyond one per byte of the file
                                         (``KEYFILL_FREE_ACCESSOR_READS``)
``max_abs``              1e12            largest magnitude of a coordinate or angle (file units,
                                         degrees); USD stores 32-bit floats (``KEYFILL_MAX_ABS``)
fps                      1e-6 .. 1e6     frames per second (BVH ``Frame Time``, USD
                                         ``timeCodesPerSecond``)
time codes               |t| <= 1e12     USD start, end and sample times
model sizes              see             :mod:`keyfill.learn.modelfile`
=======================  ==============  ======================================================

Options: ``--seed`` 0 to 2**63-1 (what numpy's and torch's generators both take), ``--workers`` and
``--threads`` 1 to 1,024, ``--connect-timeout`` up to a day; a value outside is a :class:`UsageError`
before any work, not an overflow deep inside a library.

JSON (glTF, model configs, libraries) is strict: no ``NaN`` or ``Infinity``, no number that overflows a
64-bit float (``1e400``), no whole number beyond 64 bits (:func:`json_int64`: Python would otherwise spend
time on, or refuse with its own error, an integer of thousands of digits).

Numbers in BVH text follow one grammar, ``[+-]?(digits[.digits]|.digits)([eE][+-]?digits)?``,
in the hierarchy and in the motion block alike: no ``inf``, ``nan``, ``1_0`` or hexadecimal.
"""

from __future__ import annotations

import math
import os
import re

import numpy as np

from keyfill.errors import DataError, UsageError

#: what one frame costs beside its joints, in joint-frames (a USD time sample's own overhead)
FRAME_COST = 8
MIN_FPS = 1e-6
MAX_FPS = 1e6
MAX_TIME_CODE = 1e12
MAX_SEED = 2**63 - 1
#: local worker processes, jobs in flight on a cluster, and torch threads
MAX_WORKERS = 1024
MAX_CONNECT_SECONDS = 86_400.0
#: the bytes of a settings file a user hands keyfill: a ``--rig-map`` (a few dozen lines), a ``--config`` or
#: an edit file (a few lines per edit) (keyfill.files.read_regular)
MAX_SETTINGS_BYTES = 2**20
#: how long ``--scheduler`` is tried before one error line (``--connect-timeout``'s default, CLI and library)
CONNECT_SECONDS = 3.0

#: one number in keyfill's text formats (bytes or str via :func:`is_number`)
NUMBER = r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?"
_NUMBER_STR = re.compile(NUMBER, re.ASCII)
#: every byte a motion block may hold: digits, signs, point, exponent and whitespace
NUMBER_BYTES = frozenset(b"0123456789+-.eE \t\r\n\f\v")


def _env_int(name: str, default: int) -> int:
    text = os.environ.get(name)
    if text is None:
        return default
    try:
        value = int(text)
    except ValueError:
        raise DataError(f"{name}={text!r}: must be a whole number") from None
    if value < 1:
        raise DataError(f"{name}={text!r}: must be positive")
    return value


def _env_float(name: str, default: float) -> float:
    text = os.environ.get(name)
    if text is None:
        return default
    try:
        value = float(text)
    except ValueError:
        raise DataError(f"{name}={text!r}: must be a number") from None
    if not (math.isfinite(value) and value > 0):
        raise DataError(f"{name}={text!r}: must be a positive finite number")
    return value


def max_frames() -> int:
    return _env_int("KEYFILL_MAX_FRAMES", 10_000_000)


def max_joints() -> int:
    return _env_int("KEYFILL_MAX_JOINTS", 10_000)


def free_joint_frames() -> int:
    return _env_int("KEYFILL_FREE_JOINT_FRAMES", 2_000_000)


def free_accessor_reads() -> int:
    return _env_int("KEYFILL_FREE_ACCESSOR_READS", 16_000_000)


def check_reads(numbers: int, file_bytes: int) -> str | None:
    """Why reading ``numbers`` accessor numbers in all (every use of an accessor counted) is more than a
    ``file_bytes``-byte file may ask for, or None."""
    allowed = file_bytes + free_accessor_reads()
    if numbers > allowed:
        return (f"the file asks for {numbers:,} numbers from its accessors (each counted every time a channel "
                f"uses it), more than a {file_bytes}-byte file can describe (at most {allowed:,}; set "
                "KEYFILL_FREE_ACCESSOR_READS to raise it)")
    return None


def max_abs() -> float:
    return _env_float("KEYFILL_MAX_ABS", 1e12)


def json_no_constant(name: str):
    """``parse_constant`` of :func:`json.loads`: ``NaN`` and ``Infinity`` are a :class:`ValueError`."""
    raise ValueError(f"{name} is not a number JSON allows")


def json_int64(text: str) -> int:
    """``parse_int`` of :func:`json.loads`: a JSON integer must fit in 64 bits (checked by its length first, so
    an integer of thousands of digits is never converted)."""
    if len(text) > 20 or not -(2**63) <= int(text) < 2**63:
        raise ValueError(f"the integer {text[:12]}{'...' if len(text) > 12 else ''} does not fit in 64 bits")
    return int(text)


def json_finite(text: str) -> float:
    """``parse_float`` of :func:`json.loads`: a JSON number must be a finite 64-bit float (``1e400`` is not)."""
    value = float(text)
    if not math.isfinite(value):
        raise ValueError(f"{text[:20]} is not a finite number")
    return value


def is_number(text: str) -> bool:
    """``text`` follows the number grammar (it may still overflow to infinity)."""
    return _NUMBER_STR.fullmatch(text) is not None


def parse_number(text: str) -> float | None:
    """The finite value of ``text``, or None when it is not a number of the grammar or overflows."""
    if not is_number(text):
        return None
    value = float(text)
    return value if math.isfinite(value) else None


def check_size(frames: int, joints: int, file_bytes: int) -> str | None:
    """Why a motion of ``frames`` x ``joints`` cannot come from ``file_bytes`` bytes, or None."""
    if joints > max_joints():
        return f"{joints} joints is more than keyfill reads ({max_joints()}; set KEYFILL_MAX_JOINTS to raise it)"
    if frames > max_frames():
        return f"{frames} frames is more than keyfill reads ({max_frames()}; set KEYFILL_MAX_FRAMES to raise it)"
    allowed = file_bytes + free_joint_frames()
    if frames * (joints + FRAME_COST) > allowed:
        return (
            f"{frames} frames x {joints} joints is more than a {file_bytes}-byte file can describe "
            f"(frames x (joints + {FRAME_COST}) at most {allowed}; set KEYFILL_FREE_JOINT_FRAMES to raise it)"
        )
    return None


def check_fps(fps: float) -> str | None:
    """Why ``fps`` is not a usable frame rate, or None (an int too large for a float is not one either)."""
    try:
        fps = float(fps)
    except OverflowError:
        fps = math.inf
    if not (math.isfinite(fps) and MIN_FPS <= fps <= MAX_FPS):
        return f"the frame rate {fps:g} fps is outside {MIN_FPS:g} to {MAX_FPS:g}"
    return None


#: frames :func:`check_values` looks at at once
CHECK_ROWS = 65_536


def check_values(motion, what: str = "the motion") -> None:
    """Raise :class:`DataError` unless every number of ``motion`` can be written to a file.

    Writers call this: a file never gets a value that is not finite, that
    overflows a 32-bit float in USD, or that keyfill would refuse to read back.
    """
    problem = check_fps(motion.fps)
    if problem:
        raise DataError(f"{what}: {problem}; refusing to write it")
    limit = max_abs()
    sk = motion.skeleton
    for name, arr in (("rest offset", sk.offsets), ("position", motion.positions)):
        for start in range(0, len(arr), CHECK_ROWS):  # a block of frames at a time: no full-size temporary
            big = ~(np.abs(arr[start : start + CHECK_ROWS]) <= limit)  # NaN counts as too big
            if big.any():
                idx = np.argwhere(big)[0] + np.array([start] + [0] * (arr.ndim - 1))  # in the whole array
                where = f"joint {sk.names[idx[-2]]!r}" + (f" at frame {idx[0]}" if arr.ndim == 3 else "")
                raise DataError(f"{what}: a {name} of {where} is beyond {limit:g} (or not finite); refusing to "
                                "write it")
    for j, off in sk.end_sites:
        if not np.all(np.abs(off) <= limit):
            raise DataError(f"{what}: an End Site offset of joint {sk.names[j]!r} is beyond {limit:g}; refusing to write it")


def check_seed(seed: int) -> None:
    """Raise :class:`UsageError` (naming the parameter ``seed``) unless ``seed`` is a seed every generator
    keyfill seeds can take."""
    if not 0 <= seed <= MAX_SEED:
        raise UsageError(f"seed must be between 0 and 2**63-1, got {seed}", params="seed")


def check_count(param: str, value: int, high: int) -> None:
    """Raise :class:`UsageError` unless ``value`` of the parameter ``param`` (e.g. ``"workers"``) is 1 to
    ``high``; the error names ``param`` (in ``params``)."""
    if not 1 <= value <= high:
        raise UsageError(f"{param} must be between 1 and {high:,}, got {value}", params=param)


def check_number(what: str, value, low: float, high: float, *, whole: bool = False, low_ok: bool = True,
                 error: type[Exception] = UsageError) -> None:
    """Raise ``error`` unless ``value`` (a setting named ``what``) is an int (or, unless ``whole``, a float)
    from ``low`` (excluded unless ``low_ok``) to ``high``: NaN, infinities, bools and strings fail too."""
    kinds = (int,) if whole else (int, float)  # type(), not isinstance: True is no number here
    if type(value) not in kinds or not ((low <= value) if low_ok else (low < value)) or not value <= high:
        kind = "a whole number" if whole else "a number"
        raise error(f"{what} must be {kind} from {low:g}{'' if low_ok else ' (excluded)'} to {high:g}, "
                    f"not {value!r:.40}")
