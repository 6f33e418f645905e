"""Time samples of a UsdSkel animation, read a block at a time (:mod:`keyfill.io.usd`'s reader).

:func:`resolve` hands an attribute's value at every frame to the caller a block of :data:`BLOCK` frames at a
time, as float64 ``(frames, joints, width)``: with a sample at every frame (what keyfill writes) the samples
stream through one ``Usd.AttributeQuery.Get`` each, straight into the block (a ``memoryview`` of the Vt
array's buffer, no Python per value); sparser samples are read whole and the frames between them
interpolated as USD does. Every value is checked on the way (shape, finite, within :mod:`keyfill.limits`).

:func:`shortest_decimal` turns the 32-bit floats USD stores back into the decimals that went in;
:func:`decimals` does it for a block, once for each coordinate that holds one value over the block.
"""

from __future__ import annotations

import numpy as np

from keyfill import limits
from keyfill.errors import FormatError

#: frames (or samples) handled at once by keyfill's USD reader and writer: a few MB of temporaries at any length
BLOCK = 4096


def shortest_decimal(values: np.ndarray) -> np.ndarray:
    """The 32-bit floats ``values`` (read from USD) as the doubles of their shortest decimals: ``-0.2399``
    stored as float32 reads back as the double ``-0.2399``, not ``-0.239899992943``, so a round trip writes
    the number that went in. Each value is the double nearest to the decimal of fewest significant digits
    (1 to 9) that rounds to the same float32; no negative zero. Same shape as ``values``, float64.

    Each pass of digits works on the values still undecided only, :data:`BLOCK` x 64 of them at a time,
    so the temporaries stay a few MB whatever the input's size."""
    x = np.asarray(values, dtype=np.float64)
    out = x.ravel() + 0.0  # a copy, no negative zero
    step = BLOCK * 64
    for a in range(0, out.size, step):
        part = out[a : a + step]
        part[:] = _shortest(part)
    return out.reshape(x.shape)


def _shortest(x: np.ndarray) -> np.ndarray:
    """:func:`shortest_decimal` of a 1-D float64 array."""
    x32 = x.astype(np.float32)
    out = x.copy()
    todo = np.flatnonzero(np.isfinite(x) & (x != 0))
    v = x[todo]
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        powers = 10.0 ** np.arange(400)  # beyond 10**308: inf, as the power itself would be
        exponent = np.floor(np.log10(np.abs(v))).astype(np.int64)
        for digits in range(1, 10):
            if not todo.size:
                break
            k = digits - 1 - exponent  # decimal places
            scale = powers[np.minimum(np.abs(k), len(powers) - 1)]
            # one correctly rounded operation on exact operands: the double nearest to the decimal
            candidate = np.where(k >= 0, np.rint(v * scale) / scale, np.rint(v / scale) * scale)
            hit = candidate.astype(np.float32) == x32[todo]
            out[todo[hit]] = candidate[hit]
            miss = ~hit
            todo, v, exponent = todo[miss], v[miss], exponent[miss]
    return out


def samples(attr, times: np.ndarray, rows: int | None, width: int, label, update):
    """``(times (T,), blocks)``: an attribute's time samples at ``times`` (its ``GetTimeSamples()``), or with
    none its default value as one sample at time 0, or None when it has no value.

    ``blocks`` yields ``(i, values)``, the values at ``times[i : i + b]`` as float64 ``(b, rows, width)``,
    :data:`BLOCK` samples at a time, each checked: an array of ``rows`` (None: as many as the first value
    holds) ``width``-vectors, every number finite and within the limits. Values are read through a
    ``Usd.AttributeQuery`` (the composed value, one C++ call per sample) straight into the block.
    """
    from pxr import Usd

    if times.size:
        get = Usd.AttributeQuery(attr).Get
    elif attr.Get() is None:
        return None
    else:
        times, get = np.zeros(1), lambda _t: attr.Get()
    return times, _blocks(attr.GetName(), times, get, rows, width, label, update)


def _blocks(name: str, times: np.ndarray, get, rows: int | None, width: int, label, update):
    """The generator of :func:`samples`: ``get(t)`` for each of ``times``, checked, a block at a time.

    A value of the same Vt array type and shape as one already checked goes into the block through a
    ``memoryview`` of its buffer (a third of the cost of handing numpy the Vt array); only the first, and any
    other, is looked at in full."""
    limit = limits.max_abs()
    kind = shape = None
    for i in range(0, len(times), BLOCK):
        chunk = times[i : i + BLOCK].tolist()
        block = None
        for k, t in enumerate(chunk):
            v = get(t)
            view = memoryview(v) if type(v) is kind else None
            if view is None or view.shape != shape:
                kind, view = type(v), _value(v, name, t, rows, width, label)
                rows, shape = view.shape[0], view.shape
            if block is None:
                block = np.empty((len(chunk), rows, width))
            block[k] = view
        bad = np.flatnonzero(~(np.abs(block) <= limit).all(axis=(1, 2)))
        if bad.size:
            t = chunk[bad[0]]
            raise FormatError(f"{name} at time {t:g} holds a value that is not finite or beyond {limit:g}", label)
        update(len(chunk))
        yield i, block


def _value(v, name: str, t: float, rows: int | None, width: int, label) -> np.ndarray:
    """One sample ``v`` at time ``t`` as ``(rows, width)`` float64 (``rows`` None: any), or a :class:`FormatError`."""
    if v is None:
        raise FormatError(f"{name} has a blocked time sample at {t:g}", label)
    try:
        a = np.asarray(v, dtype=np.float64)
    except (TypeError, ValueError):
        a = np.zeros(0)
    if a.ndim != 2 or a.shape[1] != width:
        raise FormatError(f"{name} at time {t:g} is not an array of {width}-vectors", label)
    if rows is not None and len(a) != rows:
        raise FormatError(f"{name} at time {t:g} holds {len(a)} values for {rows} animated joints", label)
    return a


def resolve(attr, times: np.ndarray, frame_times: np.ndarray, n: int, width: int, held: bool, put, label,
            update) -> None:
    """Hand the attribute's value at every frame, as USD resolves it, to ``put(frames, values)``: ``frames`` a
    slice of frame indices, ``values`` float64 ``(frames, n, width)``; nothing when it has no value. ``times``:
    the attribute's sample times.

    With a sample at every frame (what keyfill writes) the samples stream through a block at a time.
    Otherwise the samples are read whole (``(T, n, width)`` float64) and the frames between them are
    interpolated here as USD does (linear for vectors, GfSlerp for quaternions; held before the first and
    after the last sample, and everywhere when the stage's interpolation is held), a block of frames at a
    time, so a file with two samples far apart costs no more than its frames.
    """
    got = samples(attr, times, n, width, label, update)
    if got is None:
        return
    times, blocks = got
    F = len(frame_times)
    if np.array_equal(times, frame_times):
        for i, values in blocks:
            put(slice(i, i + len(values)), values)
        return
    whole = np.concatenate([values for _i, values in blocks])
    for a in range(0, F, BLOCK):
        put(slice(a, min(a + BLOCK, F)), _interpolated(times, whole, frame_times[a : a + BLOCK], held))


def _interpolated(times: np.ndarray, samples: np.ndarray, frame_times: np.ndarray, held: bool) -> np.ndarray:
    """``(len(frame_times), n, width)``: ``samples`` ``(T, n, width)`` at ``times`` resolved at ``frame_times``
    (see :func:`resolve`)."""
    T = len(times)
    lo = np.clip(np.searchsorted(times, frame_times, side="right") - 1, 0, T - 1)
    out = samples[lo]
    if held or T == 1:
        return out
    hi = np.minimum(lo + 1, T - 1)
    inside = (frame_times > times[lo]) & (frame_times < times[hi])
    if not inside.any():
        return out
    k = np.flatnonzero(inside)
    u = ((frame_times[k] - times[lo[k]]) / (times[hi[k]] - times[lo[k]]))[:, None, None]
    a, b = samples[lo[k]], samples[hi[k]]
    if samples.shape[-1] == 3:
        out[k] = a + u * (b - a)
        return out
    # GfSlerp on (x, y, z, w) quaternions: the shorter way round, linear when nearly equal
    cos = np.sum(a * b, axis=-1, keepdims=True)
    flip = cos < 0
    cos = np.abs(cos)
    theta = np.arccos(np.clip(cos, -1.0, 1.0))
    sin = np.sin(theta)
    near = 1.0 - cos <= 1e-5
    safe = np.where(near, 1.0, sin)
    s0 = np.where(near, 1.0 - u, np.sin((1.0 - u) * theta) / safe)
    s1 = np.where(near, u, np.sin(u * theta) / safe)
    out[k] = s0 * a + np.where(flip, -s1, s1) * b
    return out


def decimals(values: np.ndarray) -> np.ndarray:
    """:func:`shortest_decimal` of a block ``(b, n, 3)``, worked out once for each coordinate that holds one
    value over the block (in a capture most joints' translations never change)."""
    flat = values.reshape(len(values), -1)
    same = (flat == flat[:1]).all(axis=0)
    out = np.empty_like(flat)
    out[:, same] = shortest_decimal(flat[:1, same])
    out[:, ~same] = shortest_decimal(flat[:, ~same])
    return out.reshape(values.shape)
