"""BVH files: read any hierarchy and channel layout, write it back as it came.

Reading parses the hierarchy by tokens (names may hold ``:`` and other
punctuation; tabs, CRLF and trailing spaces are fine) and the motion block in
bulk with numpy: one vectorised pass counts the values on every line (so a bad
line is named by its number), one C-level pass converts them. Each joint keeps
its own channel list and Euler order; angles are intrinsic in channel order.

Position channels give the joint's local translation (replacing the OFFSET's
component on that axis), as Blender, MotionBuilder and bvhio read them.

Writing keeps each joint's channel order, the hierarchy order and the End
Sites, writes numbers with 12 significant digits (round trips to 1e-12
relative; never ``%f``; near gimbal lock, a middle angle of about +-90
degrees, the first and third angles are only defined to about
1e-16 / cos(middle) degrees, so rewriting a written file can move their
last digit), and keeps Euler curves continuous: no 360-degree
jumps and no flips between the two Euler solutions of a rotation. Given the
BVH file the motion came from (``template``), frames whose rotations are
unchanged keep that file's own channel values, and the frames between them
are unwrapped towards them (:func:`follow_template`).
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

from keyfill import limits, progress
from keyfill.errors import DataError, FormatError
from keyfill.io.bvh_channels import channel_blocks, channels_to_pose, output_layout, pose_to_channels
from keyfill.io.bvh_follow import follow
from keyfill.io.bvh_values import Layout, value_chunks
from keyfill.motion import Motion, Skeleton, check_channels

NUMBER_FORMAT = "%.12g"
_MOTION_RE = re.compile(rb"^[ \t]*MOTION[ \t]*\r?$", re.MULTILINE)


# --- reading -----------------------------------------------------------------


class _TokenStream:
    """Whitespace-separated tokens of the hierarchy, each with its 1-based line number."""

    def __init__(self, lines: list[str], path):
        self.path = path
        self.lines = lines
        self.items = [(tok, n + 1) for n, line in enumerate(lines) for tok in line.split()]
        self.pos = 0

    def error(self, message: str, line: int | None = None) -> FormatError:
        if line is None:
            line = self.items[min(self.pos, len(self.items) - 1)][1] if self.items else 1
        return FormatError(message, self.path, line)

    def peek(self) -> str | None:
        return self.items[self.pos][0] if self.pos < len(self.items) else None

    def next(self, expected: str) -> tuple[str, int]:
        if self.pos >= len(self.items):
            last = self.items[-1][1] if self.items else 1
            raise FormatError(f"hierarchy ends early: expected {expected}", self.path, last)
        item = self.items[self.pos]
        self.pos += 1
        return item

    def expect(self, word: str) -> int:
        tok, line = self.next(repr(word))
        if tok != word:
            raise FormatError(f"expected {word!r}, found {tok!r}", self.path, line)
        return line

    def rest_of_line(self, line: int) -> list[str]:
        out = []
        while self.pos < len(self.items) and self.items[self.pos][1] == line:
            out.append(self.items[self.pos][0])
            self.pos += 1
        return out

    def numbers(self, count: int, what: str) -> np.ndarray:
        vals = []
        for _ in range(count):
            tok, line = self.next(what)
            if not limits.is_number(tok):
                raise FormatError(f"expected a number in {what}, found {tok!r}", self.path, line)
            v = float(tok)
            if not abs(v) <= limits.max_abs():
                raise FormatError(
                    f"{what} holds {tok!r}, which is not a finite number of at most {limits.max_abs():g}",
                    self.path,
                    line,
                )
            vals.append(v)
        return np.array(vals)


class _Hierarchy:
    def __init__(self):
        self.names: list[str] = []
        self.parents: list[int] = []
        self.offsets: list[np.ndarray] = []
        self.channels: list[tuple[str, ...]] = []
        self.end_sites: list[tuple[int, np.ndarray]] = []
        self.index: dict[str, int] = {}
        self.lines: list[int] = []


def _open_joint(ts: _TokenStream, h: _Hierarchy, parent: int, keyword_line: int) -> int:
    """Read a joint's name and opening brace; register it and return its index."""
    parts = ts.rest_of_line(keyword_line)
    opened = bool(parts) and parts[-1] == "{"
    if opened:
        parts = parts[:-1]
    if not parts:
        raise ts.error("a joint needs a name", keyword_line)
    name = " ".join(parts)
    if name in h.index:
        raise ts.error(f"joint name {name!r} appears twice", keyword_line)
    if len(h.names) >= limits.max_joints():
        raise ts.error(
            f"more than {limits.max_joints()} joints (set KEYFILL_MAX_JOINTS to read more)", keyword_line
        )
    if not opened:
        ts.expect("{")
    j = len(h.names)
    h.index[name] = j
    h.names.append(name)
    h.parents.append(parent)
    h.offsets.append(None)
    h.channels.append(())
    h.lines.append(keyword_line)
    return j


def _parse_joint(ts: _TokenStream, h: _Hierarchy, keyword_line: int) -> None:
    """Parse a ROOT and everything under it, with an explicit stack (any depth, no recursion)."""
    stack = [_open_joint(ts, h, -1, keyword_line)]
    while stack:
        j = stack[-1]
        name = h.names[j]
        tok, line = ts.next(f"'}}' closing joint {name!r}")
        if tok == "OFFSET":
            h.offsets[j] = ts.numbers(3, f"the OFFSET of {name!r}")
        elif tok == "CHANNELS":
            ctok, cline = ts.next("a channel count")
            n = int(ctok) if ctok.isascii() and ctok.isdigit() and len(ctok) < 4 else -1
            if n < 0:
                raise ts.error(f"CHANNELS of {name!r} needs a count, found {ctok!r}", cline)
            if n in (4, 5) or not 0 <= n <= 6:
                raise ts.error(f"joint {name!r} has {n} channels; a BVH joint has 0, 1, 2, 3 or 6", cline)
            names = [ts.next(f"{n} channel names for {name!r}")[0] for _ in range(n)]
            try:
                h.channels[j] = check_channels(names)
            except ValueError as e:
                raise ts.error(f"joint {name!r}: {e}", cline) from None
        elif tok in ("JOINT", "ROOT"):
            if tok == "ROOT":
                raise ts.error(f"ROOT inside joint {name!r}; a ROOT starts a new hierarchy", line)
            stack.append(_open_joint(ts, h, j, line))
        elif tok == "End":
            ts.expect("Site")
            ts.expect("{")
            ts.expect("OFFSET")
            h.end_sites.append((j, ts.numbers(3, f"the End Site OFFSET of {name!r}")))
            ts.expect("}")
        elif tok == "}":
            if h.offsets[j] is None:
                raise ts.error(f"joint {name!r} has no OFFSET", h.lines[j])
            stack.pop()
        else:
            raise ts.error(f"unexpected {tok!r} in joint {name!r}", line)


def _header_value(lines: list[str], start: int, label: str, path) -> tuple[str, int]:
    """Find ``label`` (e.g. ``"Frames:"``) on the first non-empty line from ``start``; return its value."""
    n = start
    while n < len(lines) and not lines[n].strip():
        n += 1
    if n >= len(lines):
        raise FormatError(f"motion ends early: expected '{label}'", path, len(lines))
    text = lines[n].strip()
    if not text.replace(" ", "").replace("\t", "").lower().startswith(label.replace(" ", "").lower()):
        raise FormatError(f"expected '{label}', found {text[:40]!r}", path, n + 1)
    value = text.split(":", 1)[1].strip()
    return value, n


def _decode(raw: bytes) -> str:
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError:
        return raw.decode("latin-1")


def _snap_fps(frame_time: float) -> float:
    """``1 / frame_time``, snapped to a whole rate when the file rounded ``1/n`` (e.g. .0333333)."""
    fps = 1.0 / frame_time
    whole = round(fps)
    if whole > 0 and abs(frame_time - 1.0 / whole) < 5e-7:
        return float(whole)
    return fps


def parse(raw: bytes | str, path=None) -> Motion:
    """Parse BVH text (bytes or str) into a :class:`Motion`; ``path`` only labels errors.

    The channel values are turned into the pose a chunk at a time, so reading needs little memory
    beyond the text and the motion's own arrays.
    """
    return _pose(_layout(raw, path))


def _pose(layout: Layout) -> Motion:
    """The :class:`Motion` of a BVH file's ``layout``, its values turned into the pose a chunk at a time."""
    sk, F = layout.skeleton, layout.num_frames
    rot, pos = np.empty((F, sk.num_joints, 4)), np.empty((F, sk.num_joints, 3))
    try:
        for row, values in value_chunks(layout):
            rot[row : row + len(values)], pos[row : row + len(values)] = channels_to_pose(values, sk)
        return Motion(sk, layout.fps, rot, pos)
    except DataError as e:
        raise FormatError(str(e), layout.label) from None


def parse_values(raw: bytes | str, path=None) -> tuple[Skeleton, float, np.ndarray]:
    """``(skeleton, fps, (F, C) channel values as the file writes them)`` of BVH text; ``path`` labels errors."""
    layout = _layout(raw, path)
    values = np.empty((layout.num_frames, layout.num_channels))
    for row, chunk in value_chunks(layout):
        values[row : row + len(chunk)] = chunk
    return layout.skeleton, layout.fps, values


#: bytes of a file read for its header at a time (the header is read until MOTION and its two lines)
HEAD_BYTES = 1 << 20


def _read_head(path: Path) -> tuple[bytes, int]:
    """``(the start of the file up to at least 4 KiB past its MOTION line, or all of it, the file's size)``."""
    with open(path, "rb") as f:
        size = os.fstat(f.fileno()).st_size
        head = b""
        while True:
            more = f.read(HEAD_BYTES)
            head += more
            m = _MOTION_RE.search(head)
            if not more or (m is not None and len(head) >= m.end() + 4096):
                return head, size


def _layout(raw: bytes | str, path=None, file: Path | None = None, size: int | None = None) -> Layout:
    """The header of BVH text (bytes or str) and where its motion block starts; ``path`` labels errors.

    ``file``: the file ``raw`` is the start of (:func:`_read_head`), ``size`` its size in bytes; the
    motion block is then streamed from it.
    """
    if isinstance(raw, str):
        raw = raw.encode("utf-8")
    size = len(raw) if size is None else size
    label = path if path is not None else "<bvh>"
    if not raw or raw.isspace():  # isspace() stops at the first other byte; strip() would copy
        raise FormatError("the file is empty", label)
    m = _MOTION_RE.search(raw)
    if m is None:
        head = _decode(raw).splitlines()
        ts = _TokenStream(head, label)
        if ts.peek() != "HIERARCHY":
            raise FormatError("not a BVH file: it does not start with HIERARCHY", label, 1)
        raise FormatError("no MOTION section: the file ends early", label, max(len(head), 1))
    header_lines = _decode(raw[: m.start()]).splitlines()
    ts = _TokenStream(header_lines, label)
    if ts.peek() != "HIERARCHY":
        raise FormatError("not a BVH file: it does not start with HIERARCHY", label, ts.items[0][1] if ts.items else 1)
    ts.next("HIERARCHY")
    h = _Hierarchy()
    while ts.peek() is not None:
        tok, line = ts.next("ROOT")
        if tok != "ROOT":
            raise ts.error(f"expected ROOT, found {tok!r}", line)
        _parse_joint(ts, h, line)
    if not h.names:
        raise FormatError("the hierarchy has no joints", label, len(header_lines))

    motion_line = len(header_lines)  # 0-based index of the MOTION line
    # Locate 'Frames:' and 'Frame Time:' allowing blank lines between them.
    lines_text = _decode(raw[m.end() : m.end() + 4096]).split("\n")
    frames_val, i_frames = _header_value(lines_text, 1, "Frames:", label)
    ft_val, i_ft = _header_value(lines_text, i_frames + 1, "Frame Time:", label)
    frames_line_no = motion_line + i_frames + 1
    ft_line_no = motion_line + i_ft + 1
    if not (frames_val.isascii() and frames_val.isdigit()):
        raise FormatError(f"'Frames:' needs a non-negative whole number, found {frames_val!r}", label, frames_line_no)
    num_frames = int(frames_val)
    if not limits.is_number(ft_val):
        raise FormatError(f"'Frame Time:' needs a number, found {ft_val!r}", label, ft_line_no)
    frame_time = float(ft_val)
    if not (np.isfinite(frame_time) and frame_time > 0):
        raise FormatError(f"'Frame Time:' must be positive, found {ft_val}", label, ft_line_no)
    if not 1.0 / limits.MAX_FPS <= frame_time <= 1.0 / limits.MIN_FPS:
        raise FormatError(
            f"'Frame Time: {ft_val}' is a frame rate outside {limits.MIN_FPS:g} to {limits.MAX_FPS:g} fps", label, ft_line_no
        )
    problem = limits.check_size(num_frames, len(h.names), size)
    if problem:
        raise FormatError(problem, label, frames_line_no)

    # Byte offset of the first data line: skip i_ft + 1 lines after MOTION.
    data_start = m.end()
    for _ in range(i_ft + 1):
        nl = raw.find(b"\n", data_start)
        data_start = len(raw) if nl < 0 else nl + 1
    first_data_line = motion_line + i_ft + 2  # 1-based file line of the first data line

    num_channels = sum(len(c) for c in h.channels)
    try:
        skeleton = Skeleton(
            names=tuple(h.names),
            parents=np.array(h.parents),
            offsets=np.array(h.offsets),
            channels=tuple(h.channels),
            end_sites=tuple(h.end_sites),
        )
    except DataError as e:
        raise FormatError(str(e), label) from None
    return Layout(raw, file, label, skeleton, _snap_fps(frame_time), num_frames, num_channels, size, data_start,
                   first_data_line, frames_line_no)


def read(path: str | Path, label=None) -> Motion:
    """Read a BVH file; ``label`` (default: the path) names it in error messages.

    Streaming: the header is read first, then the motion lines a chunk at a time (about
    :data:`CHUNK_BYTES`), each turned into its frames of the pose at once; memory is the motion's
    arrays plus a chunk, whatever the file's length.
    """
    path = Path(path)
    head, size = _read_head(path)
    return _pose(_layout(head, label if label is not None else path, file=path, size=size))


def _template_chunks(template: Path):
    """``(skeleton, chunks)`` of the BVH file ``template``: its skeleton and the ``(first row, (n, C)
    channel values)`` of :func:`_value_chunks`, streamed from the file."""
    head, size = _read_head(template)
    layout = _layout(head, template, file=template, size=size)
    return layout.skeleton, value_chunks(layout)


# --- writing -----------------------------------------------------------------


def _fmt(values) -> str:
    return " ".join(NUMBER_FORMAT % v for v in values)


def _write_joint(sk: Skeleton, root: int, out: list[str], children: list[list[int]], ends) -> None:
    """The hierarchy text of ``root`` and its descendants (an explicit stack: any depth)."""
    stack: list[tuple[int, int, bool]] = [(root, 0, False)]
    while stack:
        j, depth, closing = stack.pop()
        ind = "\t" * depth
        if closing:
            for offset in ends.get(j, []):
                out.append(f"{ind}\tEnd Site")
                out.append(f"{ind}\t{{")
                out.append(f"{ind}\t\tOFFSET {_fmt(offset)}")
                out.append(f"{ind}\t}}")
            out.append(f"{ind}}}")
            continue
        out.append(f"{ind}{'ROOT' if sk.parents[j] < 0 else 'JOINT'} {sk.names[j]}")
        out.append(f"{ind}{{")
        out.append(f"{ind}\tOFFSET {_fmt(sk.offsets[j])}")
        chans = sk.channels[j]
        out.append(f"{ind}\tCHANNELS {len(chans)}{''.join(' ' + c for c in chans)}")
        stack.append((j, depth, True))
        stack.extend((k, depth + 1, False) for k in reversed(children[j]))


def _line_template(count: int, blocks) -> tuple[str, np.ndarray]:
    """The %-template of one motion line and the columns it takes, ``(C,)`` bool, of the values ``(F, C)``
    given as ``blocks`` of rows in order (``count``: C), gathered a block at a time.

    A channel whose values all print the same (e.g. the translation of a joint
    that only rotates) is printed once, into the template. Rounding to
    ``NUMBER_FORMAT`` is monotonic, so the column's minimum and maximum printing
    alike (with one sign bit, for -0) means every value does.
    """
    lo = hi = first = None
    one_sign = np.ones(count, bool)
    for block in blocks:
        if not len(block):
            continue
        if first is None:
            first, lo, hi = block[0].copy(), block.min(axis=0), block.max(axis=0)
        else:
            lo, hi = np.minimum(lo, block.min(axis=0)), np.maximum(hi, block.max(axis=0))
        one_sign &= np.all(np.signbit(block) == np.signbit(first), axis=0)
    if first is None:
        return " ".join([NUMBER_FORMAT] * count), np.ones(count, bool)
    low, high = [NUMBER_FORMAT % v for v in lo.tolist()], [NUMBER_FORMAT % v for v in hi.tolist()]
    varying = np.array([a != b for a, b in zip(low, high)], dtype=bool) | ~one_sign
    return " ".join(NUMBER_FORMAT if v else NUMBER_FORMAT % x for v, x in zip(varying, first.tolist())), varying


def follow_template(values: np.ndarray, motion: Motion, template: str | Path) -> np.ndarray:
    """``values`` (``(F, C)`` channels of ``motion``; changed in place and returned) with the numbers of the BVH
    file ``template`` where they hold the same rotations (:func:`keyfill.io.bvh_follow.follow`, streaming the
    file); a template that cannot be read changes nothing."""
    try:
        skeleton, chunks = _template_chunks(Path(template))
        return follow(values, motion, skeleton, chunks)
    except (OSError, FormatError):
        return values


def _pieces(motion: Motion, rows: int = 4096, template: str | Path | None = None, layout_hint: bool = False):
    """BVH text of ``motion`` in pieces: the header, then about ``rows`` motion lines at a time; ``layout_hint``:
    a motion its channels cannot hold names ``bvh_layout full`` as the way out."""
    sk = motion.skeleton
    limits.check_values(motion)
    for j, name in enumerate(sk.names):  # the reader joins a name's words with single spaces
        if name != " ".join(name.split()) or not name or name.split()[-1] == "{":
            raise DataError(f"joint {j} is named {name[:60]!r}, which a BVH file cannot hold (BVH names are words "
                            "separated by single spaces)")
    try:
        count, blocks = channel_blocks(motion)
    except DataError as e:
        if not layout_hint:
            raise
        raise DataError(f"{e}; bvh_layout full gives every joint three rotation channels, and position "
                        "channels to joints that move", params="bvh_layout") from None
    if template is not None:  # following a file's numbers takes every frame's values at once
        values = pose_to_channels(motion)
        values += 0.0  # no -0 of the arithmetic (a template's own -0 stays)
        values = follow_template(values, motion, template)
        line, varying = _line_template(count, [values])
        passes = [values]
    else:  # twice through the blocks: the columns' extremes, then the lines (no full-size array)

        def written():
            for _, block in blocks():
                block += 0.0  # no -0 of the arithmetic
                yield block

        line, varying = _line_template(count, written())
        passes = written()
    children: list[list[int]] = [[] for _ in range(sk.num_joints)]
    for j, p in enumerate(sk.parents):
        if p >= 0:
            children[p].append(j)
    ends: dict[int, list[np.ndarray]] = {}
    for j, off in sk.end_sites:
        ends.setdefault(j, []).append(off)
    out = ["HIERARCHY"]
    for j in range(sk.num_joints):
        if sk.parents[j] < 0:
            _write_joint(sk, j, out, children, ends)
    out.append("MOTION")
    out.append(f"Frames: {motion.num_frames}")
    out.append(f"Frame Time: {1.0 / motion.fps:.10g}")
    yield "\n".join(out) + "\n"
    if count:
        line += "\n"
        with progress.task("writing BVH", motion.num_frames, " frames") as update:
            for values in passes:
                for start in range(0, len(values), rows):
                    block = values[start : start + rows, varying].tolist()
                    yield "".join(line % tuple(row) for row in block)
                    update(len(block))
    else:
        yield "\n" * motion.num_frames


def dumps(motion: Motion) -> str:
    """BVH text of ``motion`` in its skeleton's channel layout."""
    return "".join(_pieces(motion))


def write(motion: Motion, path: str | Path, template: str | Path | None = None, layout: str = "auto") -> None:
    """Write ``motion`` to ``path`` as BVH (not atomic; see :func:`keyfill.io.save`).

    ``template``: the BVH file ``motion`` came from; frames whose rotations it
    holds unchanged keep its own channel values (:func:`follow_template`).
    ``layout`` (:data:`~keyfill.io.bvh_channels.LAYOUTS`): ``source`` writes
    each joint's own channels; ``full`` three rotation channels on every joint
    and three position channels on roots and translating joints, the layout
    every reader takes (Blender refuses fewer than three rotation channels);
    ``auto`` keeps the layout of a BVH ``template`` and of a skeleton already
    full, and writes the others (the lamp's, from USD or glTF) full.
    The motion lines are formatted and written a block at a time, so writing
    needs little memory beyond the motion's channel values.
    """
    laid_out = output_layout(motion, layout, from_bvh=template is not None)
    if laid_out is not motion:  # a template in another layout has no values to follow
        motion, template = laid_out, None
    with open(path, "w", encoding="utf-8", newline="\n") as f:
        f.writelines(_pieces(motion, template=template, layout_hint=layout != "full"))
