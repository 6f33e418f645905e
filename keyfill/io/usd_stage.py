"""USD that keeps the stage: a motion written over the USD file it came from, and ``.usdz`` packages.

A USD shot from Blender, Maya or Houdini holds more than keyfill's motion: a ``SkelRoot`` with meshes skinned
to the ``Skeleton`` (``skel:joints``, ``primvars:skel:jointIndices`` / ``jointWeights``, ``skel:skeleton``),
materials bound to them, its own prim names, hierarchy and metadata. Given that file as ``template``
(:func:`keyfill.io.save` passes its ``source`` when both are USD), :func:`write_kept` writes

* ``over=False`` (``usd_layer="stage"``, the default): the source's root layer with every prim, property and
  piece of metadata as it was, except the animation of its Skeleton (the first Skeleton under the default prim
  and its ``skel:animationSource``, as the reader picks them): the SkelAnimation's ``translations`` and
  ``rotations`` time samples are the motion's (translations that never move are one default value, as in a
  new file), its ``scales`` are one default ``(1, 1, 1)`` per joint where they had samples, its ``joints``
  are the Skeleton's where they were not, and the stage's ``startTimeCode`` stays the source's while
  ``endTimeCode`` (and ``timeCodesPerSecond`` / ``framesPerSecond``) follow the motion. Frame ``i`` is time code
  ``start + i``: a Blender shot that starts at frame 1 still starts there. The Skeleton's
  ``customData["keyfill"]`` (names, channels, keys) is the motion's, as in a new file; other customData
  stays. What the root layer takes from other files (sublayers, references, payloads, textures) stays where
  it was: asset paths that were relative are rewritten to resolve from the output's folder (unchanged where
  they already do), or written absolute where the output has no folder (standard output).
* ``over=True`` (``usd_layer="over"``): a small layer that sublayers the source (its path relative to the
  output's folder) and holds only ``over`` opinions: the same SkelAnimation samples and customData, the time
  range, and the stage metadata a sublayer cannot give (``defaultPrim``, ``upAxis``, ``metersPerUnit``).
  Opened, it composes to the stage of ``over=False``; the asset itself is not copied.

The motion must have the source Skeleton's joints (names and parents, as the reader gives them): otherwise
the meshes bound to that Skeleton cannot be kept, and writing is refused (a :class:`UsageError`; write with
``usd_layer="new"`` for a new file of the skeleton and animation alone).

Long takes: the source's root layer is read into a private copy (memory-mapped for ``.usdc``; a ``.usda``
copied from the parse its layer check makes) and its animation's old translation and rotation samples are
dropped as a whole at once; the new ones go in a
block of frames at a time (:func:`keyfill.io.usd.write_samples`), as in a new file. A caller that reads the
motion from the source itself opens that copy *before* reading (:func:`open_template`, handed to
:func:`keyfill.io.save` as ``template=``), so that a text ``.usda`` source is never held parsed beside the
motion's arrays (1,000,000 frames of 22 joints: about 0.6 GB of samples beside 1.2 GB of arrays).

``.usdz``: :func:`read_usdz` reads a package's default layer (its first file) through the USD reader, after
checking that there is one; :func:`write_usdz` writes the USD file (new, kept or over) as
``<name>.usdc`` in a temporary folder and packages it with ``UsdUtils.CreateNewUsdzPackage``, which takes its
dependencies (textures, references, the sublayered source) into the package. A package writes the same bytes
for the same input.
"""

from __future__ import annotations

import os
import posixpath
import re
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from keyfill import limits
from keyfill.errors import FormatError, OutputError, UsageError
from keyfill.motion import Motion

#: the values of ``usd_layer`` (the CLI's ``--usd-layer``), the default first
LAYERS = ("stage", "over", "new")
_SCHEME = re.compile(r"^[A-Za-z][A-Za-z0-9+.\-]*:")


def write(motion: Motion, path: str | Path, template: str | Path | None = None, usd_layer: str = "stage",
          relative: bool = True, **options) -> None:
    """Write ``motion`` to a USD file: :func:`keyfill.io.save`'s writer of the USD formats.

    Args:
        template: the USD file the motion came from (``io.save`` passes its ``source``), or a
            :class:`Template` opened from it; with ``usd_layer`` ``"stage"`` or ``"over"`` its stage is kept
            (:func:`write_kept`, see the module docstring).
        usd_layer: ``"stage"``: the template's whole stage with the motion's joint samples; ``"over"``: a
            layer over the template holding them alone; ``"new"``: a new file of the skeleton and animation
            (as without a template).
        relative: asset paths of the template that were relative stay relative, rewritten to resolve from the
            folder of ``path``; False: they are written absolute (``io.save`` gives False on standard output,
            which has no folder).
        options: ``sparse``; and for a new file ``name`` and ``root_name`` (:func:`keyfill.io.usd.write`).
    """
    from keyfill.io import usd

    check_layer(usd_layer, template)
    if template is not None and usd_layer != "new":
        write_kept(motion, path, template, over=usd_layer == "over", sparse=options.get("sparse", False),
                   relative=relative)
    else:
        usd.write(motion, path, **options)


def check_layer(usd_layer: str, template) -> None:
    """A :class:`UsageError` unless ``usd_layer`` is one of :data:`LAYERS` and, for ``"over"``, there is a
    USD ``template`` to write over."""
    if usd_layer not in LAYERS:
        raise UsageError(f"usd_layer must be one of {', '.join(LAYERS)}, got {usd_layer!r}", params="usd_layer")
    if usd_layer == "over" and template is None:
        raise UsageError("usd_layer over writes the animation as a layer over the USD file it was read from; "
                         "this motion was not read from a USD file", params="usd_layer")


def is_package(path: str | Path) -> bool:
    return Path(path).suffix.lower() == ".usdz"


def default_layer(path: str | Path, label=None) -> str:
    """The name of a ``.usdz`` package's default layer (its first file), or a :class:`FormatError`."""
    from pxr import Sdf

    label = label if label is not None else path
    with open(path, "rb") as f:
        if f.read(2) != b"PK":
            raise FormatError("not a .usdz package (not a zip archive)", label)
    z = Sdf.ZipFile.Open(str(path))
    names = list(z.GetFileNames()) if z else []
    if not names:
        raise FormatError("a .usdz package with no files, so no USD layer", label)
    if Path(names[0]).suffix.lower() not in (".usda", ".usdc", ".usd"):
        raise FormatError(f"a .usdz package without a USD layer first (its first file is {names[0]!r}; a "
                          "package's default layer comes first)", label)
    return names[0]


def read_usdz(path: str | Path, label=None):
    """The motion of a ``.usdz`` package's default layer (:func:`keyfill.io.usd_curves.read_motion`)."""
    from keyfill.io import usd_curves

    default_layer(path, label)
    return usd_curves.read_motion(path, label)


def write_usdz(motion: Motion, path: str | Path, name: str | None = None, **options) -> None:
    """Write ``motion`` as a ``.usdz`` package: :func:`write` (``options``: template, usd_layer, sparse, ...)
    into ``<name>.usdc``, packaged with its dependencies. Not atomic by itself."""
    from pxr import Sdf, UsdUtils

    from keyfill.files import quiet_stderr
    from keyfill.io.usd import _identifier

    options.pop("relative", None)  # the package's own paths are made by the packager
    inner = _identifier(name or "Animation") + ".usdc"
    with tempfile.TemporaryDirectory(prefix="keyfill-usdz-") as tmp:
        layer_path = Path(tmp) / inner
        write(motion, layer_path, name=name, relative=False, **options)
        with quiet_stderr():  # the packager's own warnings (a texture it cannot find) are not keyfill's
            ok = UsdUtils.CreateNewUsdzPackage(Sdf.AssetPath(str(layer_path)), str(path))
    if not ok:
        raise OutputError(path, "USD could not package the layer as .usdz")


# --- keeping the stage -----------------------------------------------------------------------------------


def _relative(p: str) -> bool:
    """Whether an authored asset path is relative to the layer that holds it (not absolute, no scheme, no
    expression)."""
    return bool(p) and not p.startswith(("/", "`", "\\")) and not _SCHEME.match(p)


class _Paths:
    """Asset paths of a source layer made absolute (anchored where the source is) and, when written, relative
    to the output's folder again."""

    def __init__(self, source: Path):
        self.source = source.resolve()
        self.inner = default_layer(source) if is_package(source) else None
        self.anchored: set[str] = set()

    def anchor(self, p: str) -> str:
        if not _relative(p):
            return p
        if self.inner is not None:  # inside the package: the package-relative path
            from pxr import Ar

            inside = posixpath.normpath(posixpath.join(posixpath.dirname(self.inner), p))
            out = Ar.JoinPackageRelativePath(str(self.source), inside)
        else:
            out = _identifier(p, self.source)
        if out != p:
            self.anchored.add(out)
        return out

    def relocate(self, folder: Path | None):
        """The callback that writes each path :meth:`anchor` made absolute relative to ``folder`` (None: left
        absolute), or as the source had it where that resolves to the same file from ``folder``."""
        from pxr import Ar

        def relocate(p: str) -> str:
            if folder is None or p not in self.anchored:
                return p
            outer, inner = Ar.SplitPackageRelativePathOuter(p)
            rel = os.path.relpath(outer, folder)
            rel = rel if rel.startswith("..") else "./" + rel
            return Ar.JoinPackageRelativePath(rel, inner) if inner else rel

        return relocate


def _identifier(p: str, anchor: Path) -> str:
    from pxr import Ar

    return Ar.GetResolver().CreateIdentifier(p, Ar.ResolvedPath(str(anchor)))


def _private_copy(source: Path, label):
    """An anonymous copy of the source's root layer (a package's default layer), editable without touching
    the file or a layer another caller holds. The layers the source composes are checked first, as the reader
    checks them (each a regular file: :func:`keyfill.io.usd_layers.composed_layers`); a text layer is parsed
    once, for that check, and copied from it (its values shared until the copy drops them)."""
    from pxr import Sdf, Tf

    from keyfill.io.usd_layers import composed_layers

    try:
        held = composed_layers(source, label)
        root = held[0][1] if held else None
        if root is not None and (is_package(source) or root.GetFileFormat().formatId == "usda"):
            # a package's layer refuses edits of its asset paths; a text layer would be parsed again
            layer = Sdf.Layer.CreateAnonymous(Path(default_layer(source) if is_package(source) else source).suffix)
            layer.TransferContent(root)
        else:
            layer = Sdf.Layer.OpenAsAnonymous(str(source))  # .usdc: memory-mapped, values read when asked
    except Tf.ErrorException:
        layer = None
    if layer is None:
        raise FormatError("not a readable USD file", label)
    return layer


def _source_names(skel, joints: list[str], label) -> tuple[list[str], np.ndarray]:
    """The joint names and parents of the source's Skeleton, as the reader gives them."""
    from pxr import UsdSkel, Vt

    from keyfill.io.usd import CUSTOM_KEY
    from keyfill.io.usd_custom import SKELETON, checked

    topo = UsdSkel.Topology(Vt.TokenArray(joints))
    if not topo.Validate()[0]:
        raise FormatError("the Skeleton's joints are not a valid hierarchy", label)
    custom = checked(skel.GetPrim().GetCustomDataByKey(CUSTOM_KEY), SKELETON, label)
    names = list(custom.get("names", []))
    if len(names) != len(joints):
        names = [p.rsplit("/", 1)[-1] for p in joints]
    return names, np.array(topo.GetParentIndices(), dtype=np.int64)


def _first_time(root_layer, anim) -> float:
    """The time code of frame 0, as the reader finds it: the source's ``startTimeCode``, or without one its
    animation's first sample, and no later than that sample."""
    times = [t for a in (anim.GetTranslationsAttr(), anim.GetRotationsAttr()) for t in a.GetTimeSamples()[:1]]
    first = min(times) if times else None
    start = root_layer.startTimeCode if root_layer.HasStartTimeCode() else (first if first is not None else 0.0)
    return start if first is None else min(start, first)


def _spec(prim_spec, name: str, type_name, uniform: bool = False):
    """The attribute spec ``name`` of ``prim_spec``, made (an ``over``'s) where the layer has none."""
    from pxr import Sdf

    spec = prim_spec.attributes.get(name)
    if spec is None:
        spec = Sdf.AttributeSpec(prim_spec, name, type_name,
                                 Sdf.VariabilityUniform if uniform else Sdf.VariabilityVarying)
    return spec


def _custom(motion: Motion, composed: dict | None, frames: int) -> dict:
    """The motion's ``customData["keyfill"]``, with each field the source has and the motion does not given
    its meaning of "nothing" (USD merges dictionaries key by key, so a field left out would show through)."""
    from pxr import Vt

    from keyfill.io.usd import custom_of

    custom = custom_of(motion)
    composed = composed or {}
    if "keys" in composed and "keys" not in custom:
        custom["keys"] = Vt.IntArray(list(range(frames)))
    if ("keyMask" in composed or "keyGiven" in composed) and "keyMask" not in custom:
        custom["keyGiven"] = "pose"
        custom["keyMask"] = Vt.IntArray([1] * (len(custom["keys"]) * motion.num_joints))
    return custom


@dataclass(eq=False)
class Template:
    """A USD file's stage ready for a motion to be written into it (:func:`write_kept`): the root layer as a
    private copy (or, ``over``, a new layer over the file), with its animation's old translation and rotation
    samples dropped, and what the writer needs of the source.

    Open one with :func:`open_template` before reading the motion from the same file, so that the source's
    samples are never held beside the motion's arrays; :func:`write_kept` uses it once (a second write opens
    the file again).
    """

    source: Path  #: the file
    label: object  #: how errors name it
    over: bool  #: a layer over the file (``usd_layer="over"``) rather than its copy
    layer: object  #: the ``Sdf.Layer`` written (anonymous)
    source_layer: object  #: the file's root layer as USD gives it (the copy itself unless ``over``)
    paths: _Paths  #: the asset paths anchored where the source is
    skel_path: object  #: the ``Sdf.Path`` of the Skeleton the reader picks
    anim_path: object  #: the ``Sdf.Path`` of its SkelAnimation
    joints: list  #: the Skeleton's joint paths
    names: list  #: its joint names, as the reader gives them
    parents: np.ndarray  #: ``(J,)`` parent indices, -1 for a root
    start: float  #: the time code of frame 0
    composed_custom: object  #: the Skeleton's composed ``customData["keyfill"]`` (None where it has none)
    anim_joints: list  #: the SkelAnimation's joint paths
    new_scales: bool  #: whether its scales are written again (one default ``(1, 1, 1)`` per joint)
    used: bool = False


def open_template(template: str | Path, over: bool = False, label=None) -> Template:
    """Open the USD file ``template`` for :func:`write_kept` (see :class:`Template`); a :class:`FormatError`
    naming ``label`` (default: the path) where it is not a USD file with a skeleton and its animation."""
    from pxr import Sdf, Tf, Usd, UsdSkel, UsdUtils

    from keyfill.io import usd

    source = Path(template)
    label = source if label is None else label
    paths = _Paths(source)
    if over:
        layer = Sdf.Layer.CreateAnonymous(".usda")
        source_layer = Sdf.Layer.FindOrOpen(str(paths.source))
        if source_layer is None:
            raise FormatError("not a readable USD file", label)
        layer.subLayerPaths.append(str(paths.source))
        paths.anchored.add(str(paths.source))
    else:
        layer = source_layer = _private_copy(source, label)
        UsdUtils.ModifyAssetPaths(layer, paths.anchor)
    try:
        stage = Usd.Stage.Open(layer)
        skel = usd._find_skeleton(stage, UsdSkel, label)
        anim = usd._find_animation(stage, skel, UsdSkel, label)
        joints = usd._tokens(skel.GetJointsAttr(), label)
        names, parents = _source_names(skel, joints, label)
        anim_joints = usd._tokens(anim.GetJointsAttr(), label)
        scales = anim.GetScalesAttr()
        scale_default = scales.Get() if scales.HasAuthoredValue() else None
        new_scales = scales.GetNumTimeSamples() > 0 or (scale_default is not None and len(scale_default) != len(joints))
        kept = Template(source, label, over, layer, source_layer, paths, skel.GetPath(), anim.GetPath(), joints,
                        names, parents, _first_time(source_layer, anim),
                        skel.GetPrim().GetCustomDataByKey(usd.CUSTOM_KEY), anim_joints,
                        new_scales or (scale_default is not None and anim_joints != joints))
        del stage  # edits go to the layer: no change notices to a stage
    except Tf.ErrorException as e:
        raise FormatError(f"USD cannot compose this file: {' '.join(str(e).split())[-300:]}", label) from None
    with Sdf.ChangeBlock():  # the old samples go as a whole, now: they are never held beside the new ones
        for name in ("translations", "rotations"):
            spec = layer.GetAttributeAtPath(kept.anim_path.AppendProperty(name))
            if spec is not None:
                spec.ClearInfo("timeSamples")
    return kept


def template_for(source: str | Path | None, output_format: str, usd_layer: str | None) -> Template | None:
    """The :class:`Template` :func:`keyfill.io.save` will write an ``output_format`` file into, opened now,
    before the motion is read from ``source`` (see the module docstring, "Long takes"); None where the output
    keeps no stage of it (not USD from USD, ``usd_layer`` "over" or "new") or the file cannot be opened so
    (the reader then says why, in its own words)."""
    from keyfill import io

    fmt = io.SUFFIXES.get(Path(source).suffix.lower()) if source is not None and str(source) != io.STDIO else None
    if fmt is None or io.FORMATS[fmt].family != "usd" or io.FORMATS[output_format].family != "usd":
        return None
    if usd_layer not in (None, "stage"):
        return None
    try:
        return open_template(source)
    except Exception:  # noqa: BLE001 - a file USD cannot open so: the reader's error is the one to give
        return None


def write_kept(motion: Motion, path: str | Path, template: str | Path | Template, over: bool = False,
               sparse: bool = False, relative: bool = True) -> None:
    """Write ``motion`` into the stage of the USD file ``template`` (see the module docstring): its path, or a
    :class:`Template` opened from it (and not yet used, with the same ``over``)."""
    from pxr import Gf, Sdf, UsdGeom, UsdUtils, Vt

    from keyfill.io import usd

    limits.check_values(motion)
    kept = template if isinstance(template, Template) else None
    if kept is None or kept.used or kept.over != over:
        kept = open_template(kept.source if kept is not None else template, over,
                             kept.label if kept is not None else None)
    kept.used = True
    layer, source_layer, joints = kept.layer, kept.source_layer, kept.joints
    sk = motion.skeleton
    if tuple(kept.names) != tuple(sk.names) or not np.array_equal(kept.parents, sk.parents):
        raise UsageError(f"{kept.label}: its Skeleton's joints are not those of the motion, so its stage (meshes "
                         "bound to that Skeleton) cannot be kept; write a new file (usd_layer new), or read "
                         "the motion from this file", params="usd_layer")
    frames = usd.written_frames(motion, sparse)
    start = kept.start

    with Sdf.ChangeBlock():
        if over:
            if source_layer.HasDefaultPrim():
                layer.defaultPrim = source_layer.defaultPrim
            for key in (UsdGeom.Tokens.upAxis, UsdGeom.Tokens.metersPerUnit):
                if source_layer.pseudoRoot.HasInfo(key):
                    layer.pseudoRoot.SetInfo(key, source_layer.pseudoRoot.GetInfo(key))
        if over or layer.timeCodesPerSecond != motion.fps:
            layer.timeCodesPerSecond = layer.framesPerSecond = motion.fps
        layer.startTimeCode = start
        layer.endTimeCode = start + max(motion.num_frames - 1, 0)
        skel_spec = Sdf.CreatePrimInLayer(layer, kept.skel_path)
        custom = dict(skel_spec.customData)
        custom[usd.CUSTOM_KEY] = _custom(motion, kept.composed_custom, motion.num_frames)
        skel_spec.customData = custom
        anim_spec = Sdf.CreatePrimInLayer(layer, kept.anim_path)
        if kept.anim_joints != joints:
            _spec(anim_spec, "joints", Sdf.ValueTypeNames.TokenArray, uniform=True).default = Vt.TokenArray(joints)
        if kept.new_scales:
            s_spec = _spec(anim_spec, "scales", Sdf.ValueTypeNames.Half3Array)
            s_spec.ClearInfo("timeSamples")
            s_spec.default = Vt.Vec3hArray([Gf.Vec3h(1, 1, 1)] * len(joints))
        specs = []
        for attr, type_name in (("translations", Sdf.ValueTypeNames.Float3Array),
                                ("rotations", Sdf.ValueTypeNames.QuatfArray)):
            spec = _spec(anim_spec, attr, type_name)
            spec.ClearInfo("default")  # (its samples went when the template was opened)
            specs.append(spec.path)
    usd.write_samples(layer, specs[0], specs[1], motion, frames, start)
    UsdUtils.ModifyAssetPaths(layer, kept.paths.relocate(Path(path).resolve().parent if relative else None))
    layer.Export(str(path))


def check_option(usd_layer: str | None, output_format: str, source: str | Path | None) -> None:
    """Before any work: ``usd_layer`` (None: not given) is one of :data:`LAYERS`, the output (of format
    ``output_format``) is USD, and ``"over"`` has a USD ``source`` file to write over. Errors name
    ``usd_layer``."""
    from keyfill import io

    if usd_layer is None:
        return
    check_layer(usd_layer, "given")
    if io.FORMATS[output_format].family != "usd":
        raise UsageError(f"usd_layer chooses what a USD output keeps of a USD input; this output is {output_format}",
                         params="usd_layer")
    fmt = io.SUFFIXES.get(Path(source).suffix.lower()) if source is not None and str(source) != io.STDIO else None
    if usd_layer == "over" and (fmt is None or io.FORMATS[fmt].family != "usd"):
        raise UsageError(f"usd_layer over writes a layer over the USD file read; {source} is not a USD file "
                         f"({io.listing(io.suffixes('usd'))})", params="usd_layer")
