"""Reading and writing motion files: ``load(path) -> Motion``, ``save(motion, path)``.

:data:`FORMATS` is the one table of file formats: each :class:`Format` names its
reader ``read(path, label=None) -> Motion`` (``label`` names the file in error
messages), its writer ``write(motion, path, **options)``, its suffixes and a
description. The command-line choices, the suffixes a batch picks from a
folder, and every message that lists formats read it. The format comes from
the suffix or from ``format=`` (required for ``-`` as standard output; standard input without it is
recognised by its first bytes, :func:`sniff`).
BVH is :mod:`keyfill.io.bvh`; USD is :mod:`keyfill.io.usd` (UsdSkel), read
through :func:`keyfill.io.usd_curves.read_motion` so that a keyfill curves file
gives its Bezier curves baked at every frame; glTF 2.0 is :mod:`keyfill.io.gltf`; FBX is
:mod:`keyfill.io.fbx`, read only (its ``writer`` is None: an output named ``.fbx`` is refused before any work).
Saving is atomic: the file appears complete or not at all (see
:func:`keyfill.files.atomic_output`).
"""

from __future__ import annotations

import importlib
import os
import shutil
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

from keyfill.errors import DataError, FormatError, NoSuchFile, UsageError
from keyfill.files import atomic_output
from keyfill.motion import Motion


@dataclass(frozen=True)
class Format:
    """One file format: ``reader`` and ``writer`` as ``"module:function"`` (imported on first use)."""

    name: str
    family: str
    reader: str
    #: None for a format keyfill reads but does not write (FBX)
    writer: str | None
    suffixes: tuple[str, ...]
    description: str
    #: suffix of a second file the writer puts beside the output (a ``.gltf``'s ``.bin``), or None
    sidecar: str | None = None
    #: the writer takes ``template=``: a file of the same family whose content beyond the motion it keeps (a
    #: glTF's meshes; a BVH's own Euler values at the frames whose rotations are unchanged)
    template: bool = False
    #: the bytes a file of this format starts with (after white space), for :func:`sniff`; None: not sniffed so
    magic: bytes | None = None
    #: the file records its units (USD ``metersPerUnit``, glTF meters); BVH does not (assumed cm)
    units: bool = True
    #: the writer takes ``name=``, what to call the animation (a glTF animation, a USD SkelAnimation prim)
    named: bool = True
    #: the file records its up axis (USD ``upAxis``; glTF is Y-up, or says otherwise in its extras); BVH does not
    #: (assumed Y)
    axes: bool = True
    #: the writer takes ``relative=``: False where the output has no folder (standard output), so that the asset
    #: paths it keeps from a template are written absolute instead of relative to the output's folder
    asset_paths: bool = False
    #: ``"module:function"``, ``function(path) -> list of words`` ("2 meshes", "1 material"): what a file of this
    #: format holds beyond the motion, for the note that an output of another family does not carry it
    contents: str | None = None


_USD = {"family": "usd", "reader": "keyfill.io.usd_curves:read_motion", "writer": "keyfill.io.usd_stage:write",
        "template": True, "asset_paths": True}
_GLTF = {"family": "gltf", "reader": "keyfill.io.gltf:read", "writer": "keyfill.io.gltf_write:write", "template": True,
         "contents": "keyfill.io.carried:gltf"}
#: format name -> :class:`Format`, in the order messages list them
FORMATS = {f.name: f for f in (
    Format("bvh", "bvh", "keyfill.io.bvh:read", "keyfill.io.bvh:write", (".bvh",), "BVH motion capture text",
           magic=b"HIERARCHY", units=False, template=True, named=False, axes=False),
    Format("usda", suffixes=(".usda",), description="USD text (UsdSkel)", magic=b"#usda", **_USD),
    Format("usdc", suffixes=(".usdc",), description="USD binary crate (UsdSkel)", magic=b"PXR-USDC", **_USD),
    Format("usd", suffixes=(".usd",), description="USD, text or crate (written as crate)", **_USD),
    Format("usdz", suffixes=(".usdz",), description="USD package: a zip of a crate layer and its files (textures)",
           magic=b"PK\x03\x04", **{**_USD, "reader": "keyfill.io.usd_stage:read_usdz",
                                     "writer": "keyfill.io.usd_stage:write_usdz"}),
    Format("glb", suffixes=(".glb",), description="glTF 2.0 binary (skin + animation)", magic=b"glTF",
           **_GLTF),
    Format("gltf", suffixes=(".gltf",), description="glTF 2.0 JSON with a .bin beside it (embedded on standard output)",
           sidecar=".bin", **_GLTF),
    Format("fbx", "fbx", "keyfill.io.fbx:read", None, (".fbx",), "FBX, binary or ASCII (read only; the fbx extra)",
           magic=b"Kaydara FBX Binary", template=False, named=False),
)}
#: suffix (lower case, with the dot) -> format name
SUFFIXES = {s: f.name for f in FORMATS.values() for s in f.suffixes}
STDIO = "-"
#: bytes of a written file copied to standard output at a time
STDOUT_CHUNK = 1 << 22


def listing(items, last: str = "or") -> str:
    """``"a, b or c"``: the words of ``items`` for a message."""
    items = list(items)
    return items[0] if len(items) == 1 else f"{', '.join(items[:-1])} {last} {items[-1]}"


def names(family: str | None = None) -> list[str]:
    """Format names (of one ``family``: ``"bvh"``, ``"usd"``, ``"gltf"``), in table order."""
    return [f.name for f in FORMATS.values() if family is None or f.family == family]


def suffixes(family: str | None = None) -> list[str]:
    """Suffixes (``".usda"``) of the formats (of one ``family``), in table order."""
    return [s for name in names(family) for s in FORMATS[name].suffixes]


def writable() -> list[str]:
    """The names of the formats keyfill writes (those with a ``writer``), in table order."""
    return [f.name for f in FORMATS.values() if f.writer is not None]


def _refuse_read_only(path, fmt: str) -> None:
    if FORMATS[fmt].writer is None:
        where = "standard output" if str(path) == STDIO else str(path)
        raise UsageError(f"{where}: {fmt.upper()} is read-only in keyfill; write one of {listing(writable())}")


def format_of(path: str | os.PathLike, format: str | None = None, reading: bool = False) -> str:
    """The format name for ``path``: ``format`` when given, else from the suffix.

    ``-`` needs ``format``; ``reading`` says whether ``-`` is standard input
    (for the error). An output (not ``reading``) whose suffix is another
    format's than ``format`` is refused: the file would not read back as what
    its name says. Errors name the parameter ``format`` (in ``params``).
    """
    if format is not None:
        fmt = format.lower().lstrip(".")
        if fmt not in FORMATS:
            raise UsageError(f"unknown format {format!r}; expected one of {', '.join(FORMATS)}")
        named = SUFFIXES.get(Path(path).suffix.lower()) if str(path) != STDIO else None
        if not reading and named is not None and named != fmt:
            raise UsageError(f"{path}: format {fmt} contradicts the suffix {Path(path).suffix!r} (a {named} file); "
                             f"a {fmt} output is named {listing(FORMATS[fmt].suffixes)}", params="format")
        if not reading:
            _refuse_read_only(path, fmt)
        return fmt
    if str(path) == STDIO:
        raise UsageError(f"{'reading' if reading else 'writing'} '-' needs format "
                         f"({listing(FORMATS if reading else writable())})",
                         params="format")
    suffix = Path(path).suffix.lower()
    if suffix not in SUFFIXES:
        raise UsageError(f"{path}: unknown file type {Path(path).suffix or '(no suffix)'!r}; "
                         f"expected {listing(SUFFIXES)}")
    if not reading:
        _refuse_read_only(path, SUFFIXES[suffix])
    return SUFFIXES[suffix]


def check_bvh_layout(layout: str, fmt: str) -> None:
    """Refuse a BVH ``layout`` that is not one of :data:`~keyfill.io.bvh_channels.LAYOUTS`, or that is given for
    an output of format ``fmt`` other than BVH (it would change nothing); the error names ``bvh_layout``."""
    from keyfill.io.bvh_channels import LAYOUTS

    if layout not in LAYOUTS:
        raise UsageError(f"unknown BVH layout {layout!r}; expected {listing(LAYOUTS)}", params="bvh_layout")
    if FORMATS[fmt].family != "bvh":
        raise UsageError(f"bvh_layout lays out BVH outputs; this output is {fmt}", params="bvh_layout")


def _function(target: str):
    module, name = target.split(":")
    return getattr(importlib.import_module(module), name)


def sniff(data: bytes) -> str | None:
    """The format of a file's first bytes ``data``, from the ``magic`` of :data:`FORMATS`, or None.

    BVH starts with ``HIERARCHY`` (after white space or a byte-order mark), USD text with ``#usda``, a USD
    crate with ``PXR-USDC``, binary glTF with ``glTF``, and glTF JSON is an object with an ``"asset"`` key.
    """
    import json

    text = data.lstrip(b"\xef\xbb\xbf \t\r\n")
    for f in FORMATS.values():
        if f.magic and text.startswith(f.magic):
            return f.name
    if text.startswith(b"{"):
        try:
            doc = json.loads(data.decode("utf-8-sig"))
        except (UnicodeDecodeError, ValueError):
            return None
        if isinstance(doc, dict) and "asset" in doc:
            return "gltf"
    return None


def load(path: str | os.PathLike, format: str | None = None, meters_per_unit: float | None = None,
         up_axis: str | None = None) -> Motion:
    """Read a motion file (``"-"``: standard input, in ``format`` or else the one :func:`sniff` finds).

    ``meters_per_unit`` states the units of a format that records none (BVH, :attr:`Format.units`); without
    it such a file is assumed in centimetres (0.01). A format that records its units ignores it.
    ``up_axis`` (``"Y"`` or ``"Z"``, any case) states the up axis of a format that records none (BVH,
    :attr:`Format.axes`; Blender exports Z-up BVH); without it such a file is assumed Y-up. The values are
    kept as they are: the axis becomes the skeleton's :attr:`~keyfill.motion.Skeleton.up_axis`, which USD
    records and glTF turns into its Y-up. A format that records its up axis ignores it.
    """
    return load_format(path, format, meters_per_unit, up_axis)[0]


def load_format(path: str | os.PathLike, format: str | None = None, meters_per_unit: float | None = None,
                up_axis: str | None = None) -> tuple[Motion, str]:
    """:func:`load`, and the name of the format the file was read as (sniffed for standard input)."""
    if meters_per_unit is not None and not (0 < meters_per_unit < float("inf")):
        raise UsageError(f"meters_per_unit must be a positive number, got {meters_per_unit!r}",
                         params="meters_per_unit")
    up = None if up_axis is None else str(up_axis).upper()
    if up is not None and up not in ("X", "Y", "Z"):
        raise UsageError(f"up_axis must be X, Y or Z, got {up_axis!r}", params="up_axis")
    if up == "X":
        raise UsageError("up_axis X is not supported: keyfill's skeletons, like USD's upAxis, are Y-up or Z-up",
                         params="up_axis")
    fmt, motion = _read(path, format)
    if meters_per_unit is not None and not FORMATS[fmt].units:
        motion = motion.replace(skeleton=motion.skeleton.replace(meters_per_unit=float(meters_per_unit)))
    if up is not None and not FORMATS[fmt].axes:
        motion = motion.replace(skeleton=motion.skeleton.replace(up_axis=up))
    return motion, fmt


def _read(path, format):
    if str(path) == STDIO:
        try:
            data = sys.stdin.buffer.read()
        except (OSError, AttributeError) as e:
            raise FormatError(f"cannot read standard input ({e})", "<stdin>") from None
        if format is None:
            format = sniff(data)
            if format is None:
                # the word of the input's format parameter, as the CLI spells it
                raise UsageError(f"cannot tell the format of standard input from its first bytes; give in_format "
                                 f"({listing(FORMATS)})", params="in_format")
        fmt = format_of(path, format, reading=True)
        read = _function(FORMATS[fmt].reader)
        with tempfile.TemporaryDirectory() as tmp:
            p = Path(tmp) / ("stdin" + FORMATS[fmt].suffixes[0])
            p.write_bytes(data)
            return fmt, read(p, label="<stdin>")
    fmt = format_of(path, format, reading=True)
    read = _function(FORMATS[fmt].reader)
    p = Path(path)
    if not p.is_file():
        raise NoSuchFile(p, "no such file" if not p.exists() else "not a file")
    return fmt, read(p)


def _note_left_behind(source: Path, words: list[str], spec: Format) -> None:
    """One note that what ``source`` holds beyond the motion (``words``) is not in the output."""
    if words:
        from keyfill import progress

        family = {"usd": "USD", "gltf": "glTF", "bvh": "BVH"}.get(spec.family, spec.family)
        progress.note(f"{source.name}: its {listing(words, 'and')} are not carried into {family} (only the "
                      "skeleton and its animation are)")


def save(motion: Motion, path: str | os.PathLike, format: str | None = None, source: str | os.PathLike | None = None,
         bvh_layout: str | None = None, **options) -> None:
    """Write ``motion`` atomically (``"-"``: standard output, with ``format``).

    ``source``: the file ``motion`` came from; when it is of the output's
    family and the format keeps a :attr:`Format.template`, what it holds
    beyond the motion is kept (a glTF character's meshes and materials, a USD
    shot's stage: see :mod:`keyfill.io.usd_stage`, and ``usd_layer=``); when it
    is of another family, a :func:`keyfill.progress.note` says what it held
    that the output does not carry (:attr:`Format.contents`).
    ``options`` go to the format's writer (e.g. ``sparse=True`` for USD key
    files); ``template=`` a :class:`keyfill.io.usd_stage.Template` opened from
    ``source`` before the motion was read (:func:`keyfill.io.usd_stage.open_template`:
    a long take's USD samples are then never held beside its arrays) is used
    in place of ``source`` where the stage is kept. A :attr:`Format.named` format's animation is named after the output
    file's stem (on standard output the source's, if any). A format with a :attr:`Format.sidecar`
    writes that file beside the output, atomically too: its writer gets
    ``sidecar=(temporary path, final file name)``, or ``sidecar=None`` on
    standard output, where it embeds what the sidecar would hold.
    ``bvh_layout``: the channel layout of a BVH output (``auto``, ``source`` or ``full``:
    :data:`keyfill.io.bvh_channels.LAYOUTS`; None: ``auto``); a :class:`UsageError` for other outputs.
    """
    fmt = format_of(path, format)
    spec = FORMATS[fmt]
    if bvh_layout is not None:
        check_bvh_layout(bvh_layout, fmt)
        options["layout"] = bvh_layout
    write = _function(spec.writer)
    source_suffix = Path(source).suffix.lower() if source is not None and str(source) != STDIO else None
    came_from = FORMATS[SUFFIXES[source_suffix]] if source_suffix in SUFFIXES else None
    opened = options.pop("template", None)
    if spec.template and came_from is not None and came_from.family == spec.family:
        options["template"] = opened if opened is not None else Path(source)
    elif came_from is not None and came_from.family != spec.family and came_from.contents:
        _note_left_behind(Path(source), _function(came_from.contents)(Path(source)), spec)
    if spec.asset_paths and str(path) == STDIO:
        options["relative"] = False
    if spec.named:
        named_after = source if str(path) == STDIO else path
        options.setdefault("name", None if named_after is None or str(named_after) == STDIO else Path(named_after).stem)
    try:
        _write(write, motion, path, spec, options)
    except DataError as e:  # what the output cannot hold: the line names the output (never its temporary file)
        where = "standard output" if str(path) == STDIO else str(path)
        raise DataError(f"{where}: {e}", params=e.params) from None


def _write(write, motion: Motion, path, spec: Format, options: dict) -> None:
    """:func:`save`'s writing: to standard output through a temporary file, or atomically beside ``path``."""
    if str(path) == STDIO:
        if spec.sidecar:
            options["sidecar"] = None
        with tempfile.TemporaryDirectory() as tmp:
            out = Path(tmp) / ("stdout" + spec.suffixes[0])
            write(motion, out, **options)
            sys.stdout.flush()
            with open(out, "rb") as f:
                shutil.copyfileobj(f, sys.stdout.buffer, STDOUT_CHUNK)  # a long take is not held whole
            sys.stdout.buffer.flush()
        return
    if spec.sidecar:
        side = Path(path).with_suffix(spec.sidecar)
        # the sidecar is renamed into place first, so the output never appears without it
        with atomic_output(path) as tmp, atomic_output(side) as tmp_side:
            write(motion, tmp, sidecar=(tmp_side, side.name), **options)
        return
    with atomic_output(path) as tmp:
        write(motion, tmp, **options)
