"""Curve files: Bezier animation curves (:class:`~keyfill.curves.Curves`) as ``pxr.Ts`` splines in a USD file.

Layout (``.usda``, ``.usdc`` or ``.usd``)::

    /Root                      SkelRoot (defaultPrim)
    /Root/Skeleton             UsdSkel Skeleton, as keyfill.io.usd writes it (joint names,
                               BVH channel layouts, End Sites and the keys in customData)
    /Root/Skeleton/<name>      SkelAnimation: the curves baked at every frame, so that any
                               UsdSkel viewer plays the motion (named after the file's stem)
    /Root/Curves               Scope; customData keyfill = {layout = "keyfill.curves", version = 1}
        double <Joint>_<Channel>.spline = { bezier, <knots> }   one attribute per control

Each control attribute (for example ``Hips_Zrotation``) carries
``customData keyfill = {joint = "Hips", channel = "Zrotation", unit = "radians"}`` and a
spline of Bezier knots at the key times (time codes are frames;
``timeCodesPerSecond`` is the frame rate). A knot's pre/post tangent
*width* is the tangent's extent in frames and its *slope* the value change
per frame, so the Bezier control points are ``(t - preWidth, v - preWidth *
preSlope)`` and ``(t + postWidth, v + postWidth * postSlope)``; knot
customData ``broken`` says whether the two slopes may differ. Rotation
channels are Euler angles in **radians** (keyfill's unit everywhere but BVH
text, so values round-trip bit for bit) in the joint's declared order (the
Skeleton's channel layout); translations are in the stage's units
(``metersPerUnit``). Every control has a knot at every key (global key
poses); extrapolation is held.

Reading also accepts Hermite splines (widths a third of the segment) and
linear segments (turned into the equivalent Bezier); held segments, dual
values, loops and other extrapolations are refused with a clear message.
``attr.Get(time)`` on the saved file equals :meth:`Curves.evaluate` to
rounding: both solve the same cubic.

:func:`keyfill.io.load` reads every USD file through :func:`read_motion`, so a
curves file opened as a motion gives its curves baked at every frame.

Long takes: the writer adds the curves to the in-memory stage of the baked
SkelAnimation (:func:`keyfill.io.usd.stage_of`) and USD writes the file once;
each knot is one ``Ts.Knot`` call with all its fields, from Python lists made
a control at a time. The reader reads the SkelAnimation as
:mod:`keyfill.io.usd` does and each knot's fields as Python floats into the
(K, C) arrays of :class:`~keyfill.curves.Curves`. Both hold the stage, the
motion's arrays and the knots: linear in frames and keys.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from keyfill import io
from keyfill.curves import Control, Curves
from keyfill.errors import DataError, FormatError, NoSuchFile, UsageError
from keyfill.files import quiet_stderr
from keyfill.io import usd
from keyfill.io.usd_custom import CURVE, CURVES, KNOT, checked
from keyfill.motion import POSITION_CHANNELS, ROTATION_CHANNELS, Motion

LAYOUT = "keyfill.curves"
VERSION = 1
CURVES_PRIM = "Curves"
_CUSTOM = "keyfill"


def _attr_name(skeleton, control: Control, used: set[str]) -> str:
    base = f"{usd._identifier(skeleton.names[control.joint])}_{control.channel}"
    name, n = base, 1
    while name in used:
        name, n = f"{base}_{n}", n + 1
    used.add(name)
    return name


def write(curves: Curves, path: str | Path, name: str | None = None) -> None:
    """Write ``curves`` to a USD file (format from the suffix); see the module docstring.

    ``name``: the SkelAnimation's (see :func:`keyfill.io.usd.write`).

    Not atomic by itself: callers write through :func:`keyfill.files.atomic_output`.
    """
    from pxr import Sdf, Ts, UsdGeom

    stage = usd.stage_of(curves.bake(), name=name)
    root = stage.GetDefaultPrim()
    scope = UsdGeom.Scope.Define(stage, root.GetPath().AppendChild(CURVES_PRIM)).GetPrim()
    scope.SetCustomDataByKey(_CUSTOM, {"layout": LAYOUT, "version": VERSION})
    sk = curves.skeleton
    used: set[str] = set()
    # Python numbers a control at a time ((C, K) lists), and one Ts.Knot call per knot with all its fields
    times = [float(t) for t in curves.times]
    values = curves.values.T.tolist()
    widths, slopes = [], []
    for tan in (curves.in_tan, curves.out_tan):
        width, height = tan[..., 0], tan[..., 1]
        widths.append(width.T.tolist())
        slopes.append(np.divide(height, width, out=np.zeros_like(height), where=width > 0).T.tolist())
    broken = curves.broken.T.tolist()
    with Sdf.ChangeBlock():
        for i, c in enumerate(curves.controls):
            attr = scope.CreateAttribute(_attr_name(sk, c, used), Sdf.ValueTypeNames.Double, custom=True)
            unit = "radians" if c.is_rotation else "file units"
            attr.SetCustomDataByKey(_CUSTOM, {"joint": sk.names[c.joint], "channel": c.channel, "unit": unit})
            spline = Ts.Spline()
            spline.SetCurveType(Ts.CurveTypeBezier)
            for k, t in enumerate(times):
                spline.SetKnot(Ts.Knot(time=t, value=values[i][k], nextInterp=Ts.InterpCurve,
                                       preTanWidth=widths[0][i][k], preTanSlope=slopes[0][i][k],
                                       postTanWidth=widths[1][i][k], postTanSlope=slopes[1][i][k],
                                       customData={"broken": broken[i][k]}))
            attr.SetSpline(spline)
    # usd-core 26.11 warns "TsSpline inner looping is deprecated" for every spline written to text,
    # and about the crate upgrade for splines in .usdc: expected here, and noise on the CLI's stderr.
    with quiet_stderr():
        stage.GetRootLayer().Export(str(path))


def save(curves: Curves, path: str | Path) -> None:
    """Write ``curves`` atomically: a curves file for USD suffixes, the baked motion for the other formats."""
    from keyfill.files import atomic_output

    fmt = io.format_of(path)
    if io.FORMATS[fmt].family != "usd":
        io.save(curves.bake(), path)
        return
    if fmt == "usdz":  # USD writes no package through Export; a curves file is a layer to edit
        raise UsageError(f"{path}: a curves file is a USD layer ({io.listing(io.suffixes('usd')[:-1])}), not a "
                         ".usdz package")
    with atomic_output(path) as tmp:
        write(curves, tmp, name=Path(path).stem)


def curves_prim(stage):
    """The stage's keyfill Curves prim (marked by its layout customData), or None."""
    root = stage.GetDefaultPrim() or stage.GetPseudoRoot()
    for prim in root.GetChildren():
        data = prim.GetCustomDataByKey(_CUSTOM)
        if isinstance(data, dict) and data.get("layout") == LAYOUT:  # the prim's other fields: from_stage
            return prim
    return None


def from_stage(stage, motion: Motion, label) -> Curves:
    """The :class:`Curves` of an open stage; ``motion`` is its UsdSkel part (skeleton, fps, frames)."""
    from pxr import Ts

    prim = curves_prim(stage)
    if prim is None:
        raise FormatError(
            "not a keyfill curves file (no Curves prim); make one with keyfill convert IN OUT.usda --curves --keys ...",
            label,
        )
    version = checked(prim.GetCustomDataByKey(_CUSTOM), CURVES, label)["version"]
    if version > VERSION:
        raise FormatError(f"curves layout version {version} is newer than this keyfill reads ({VERSION})", label)
    sk = motion.skeleton
    controls, splines, names = [], [], []
    for attr in prim.GetAttributes():
        if not attr.HasSpline():
            continue
        where = f"{attr.GetName()}"
        data = checked(attr.GetCustomDataByKey(_CUSTOM), CURVE, label, where)
        joint, channel = data.get("joint"), data.get("channel")
        if joint not in sk.names:
            raise FormatError(f"curve {where} names joint {joint!r}, which is not in the Skeleton", label)
        if channel not in POSITION_CHANNELS + ROTATION_CHANNELS:
            raise FormatError(f"curve {where} has channel {channel!r}; expected one like Zrotation or Xposition", label)
        ctl = Control(sk.index(joint), channel)
        if channel not in sk.channels[ctl.joint]:
            raise FormatError(f"curve {where}: joint {joint} has no {channel} channel in the Skeleton's layout", label)
        if ctl in controls:
            raise FormatError(f"two curves animate {joint}.{channel}", label)
        controls.append(ctl)
        splines.append(attr.GetSpline())
        names.append(where)
    if not controls:
        raise FormatError("the Curves prim holds no spline attributes", label)
    # keep the skeleton's joint and channel order whatever the attribute order
    order = sorted(
        range(len(controls)),
        key=lambda i: (controls[i].joint, sk.channels[controls[i].joint].index(controls[i].channel)),
    )
    controls = [controls[i] for i in order]
    splines = [splines[i] for i in order]
    names = [names[i] for i in order]

    times = None
    C = len(controls)
    per_control = []
    for name, spline in zip(names, splines):
        knots = list(spline.GetKnots().values())
        t = np.array([k.GetTime() for k in knots], dtype=np.float64)
        if times is None:
            times = t
        elif len(t) != len(times) or not np.allclose(t, times, rtol=0, atol=1e-9):
            raise FormatError(
                f"curve {name} has knots at {_short(t)} but {names[0]} at {_short(times)}; "
                "keyfill curves need every control keyed at the same times",
                label,
            )
        if spline.HasLoops():
            raise FormatError(f"curve {name} loops; keyfill curves do not", label)
        for extrap in (spline.GetPreExtrapolation(), spline.GetPostExtrapolation()):
            if extrap.mode != Ts.ExtrapHeld:
                raise FormatError(
                    f"curve {name} extrapolates with {extrap.mode}; keyfill curves hold their end values", label
                )
        per_control.append((spline.GetCurveType(), knots))
    K = len(times)
    if K < 2:
        raise FormatError(f"the curves have {K} knot(s); at least 2 keys are needed", label)
    seg = np.diff(times)
    values = np.empty((K, C))
    in_tan = np.empty((K, C, 2))
    out_tan = np.empty((K, C, 2))
    broken = np.zeros((K, C), dtype=bool)
    with np.errstate(over="ignore", invalid="ignore"):  # a huge width or slope: Curves rejects what is not finite
        for i, (curve_type, knots) in enumerate(per_control):
            for k, knot in enumerate(knots):
                if knot.IsDualValued():
                    raise FormatError(
                        f"curve {names[i]} has a dual-valued knot at {times[k]:g} (a jump); not supported", label
                    )
                values[k, i] = float(knot.GetValue())
                pre_width, pre_slope = knot.GetPreTanWidth(), knot.GetPreTanSlope()  # Python floats: no
                post_width, post_slope = knot.GetPostTanWidth(), knot.GetPostTanSlope()  # array per knot
                if curve_type == Ts.CurveTypeHermite:
                    pre_width = seg[k - 1] / 3 if k > 0 else seg[0] / 3
                    post_width = seg[k] / 3 if k < K - 1 else seg[-1] / 3
                in_tan[k, i] = pre_width, pre_width * pre_slope
                out_tan[k, i] = post_width, post_width * post_slope
                # GetCustomDataByKey segfaults on a missing key (usd-core 26.11)
                flag = checked(knot.GetCustomData(), KNOT, label, names[i]).get("broken")
                broken[k, i] = bool(flag) if flag is not None else not np.isclose(pre_slope, post_slope, rtol=1e-9,
                                                                                  atol=1e-12)
            for k, knot in enumerate(knots[:-1]):
                interp = knot.GetNextInterpolation()
                if interp == Ts.InterpLinear:
                    rise = (values[k + 1, i] - values[k, i]) / 3
                    out_tan[k, i] = seg[k] / 3, rise
                    in_tan[k + 1, i] = seg[k] / 3, rise
                    broken[k, i] = broken[k + 1, i] = True
                elif interp != Ts.InterpCurve:
                    raise FormatError(
                        f"curve {names[i]} holds its value after {times[k]:g}; keyfill curves are Bezier", label
                    )
    try:
        return Curves(
            skeleton=sk,
            fps=motion.fps,
            num_frames=max(motion.num_frames, int(np.floor(times[-1])) + 1),
            controls=tuple(controls),
            times=times,
            values=values,
            in_tan=in_tan,
            out_tan=out_tan,
            broken=broken,
        )
    except DataError as e:  # from the validation of Curves: name the file
        raise FormatError(str(e), label) from None


def read(path: str | Path, label=None) -> Curves:
    """Read a keyfill curves file written by :func:`write` (or following its layout)."""
    label = path if label is None else label
    hint = "make one with keyfill convert IN.bvh OUT.usda --curves --keys ..."
    if Path(path).suffix.lower() not in io.suffixes("usd"):
        raise FormatError(f"not a keyfill curves file (a {io.listing(io.suffixes('usd'))} file); {hint}", label)
    if not Path(path).is_file():
        raise NoSuchFile(label, "no such file" if not Path(path).exists() else "not a file")
    stage = usd.open_stage(path, label)
    return from_stage(stage, usd.read_stage(stage, label), label)


def read_motion(path: str | Path, label=None) -> Motion:
    """Any USD file as a :class:`Motion`: a curves file gives its curves baked at every frame
    (exact, where its SkelAnimation holds 32-bit floats), any other file its UsdSkel animation."""
    label = path if label is None else label
    stage = usd.open_stage(path, label)
    motion = usd.read_stage(stage, label)
    if curves_prim(stage) is None:
        return motion
    return from_stage(stage, motion, label).bake()


def _short(t: np.ndarray) -> str:
    text = ", ".join(f"{x:g}" for x in t[:6])
    return text + (", ..." if len(t) > 6 else "")
