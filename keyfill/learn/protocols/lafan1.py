"""The LaFAN1 in-betweening benchmark (Harvey et al. 2020), applicable to any BVH corpus.

The protocol, as the reference code runs it:

1. Clips are split by file name into a training and a test set.
2. Windows: training statistics from windows of 50 frames at offset 20; test
   windows of 65 frames at offset 40 (see :meth:`Corpus.windows`).
3. Each window is normalised (:func:`keyfill.learn.windows.align_windows`): the root's mean
   horizontal (XZ for Y-up) position over the window is subtracted, and the
   window is turned about the up axis so that the root's facing direction on
   frame 9, its local facing axis (``+Y`` in the reference) projected on the
   ground, points along +X.
4. Statistics (:func:`statistics`): mean and standard deviation of every global
   joint coordinate over the training windows; the constant bone offsets.
5. For a transition length ``n``, frames 0-9 (context) and ``10 + n`` (target)
   are given; a method fills frames ``10 .. 9 + n``. Global positions come from
   forward kinematics of the root position and the constant offsets.
6. Scores (:mod:`keyfill.learn.protocols.metrics`) over the transition frames only: L2Q,
   L2P (positions normalised by the training statistics) and NPSS.

Baselines: zero-velocity (frame 9 repeated), interpolation (LERP of the root,
shortest-path SLERP of local quaternions with weights
``linspace(0, 1, n + 2)[1:-1]``), keyfill's cubic spline through all the
given frames, and ``velocity``: the interpolation plus the velocity of the given
frames next to the gap, fading over a few frames (a transformer pre-fill).

A method is a function ``(skeleton, quats (B, T, J, 4), root (B, T, 3), keys)
-> (quats, root)`` over windows of ``T = 11 + n`` frames whose unknown frames are
NaN (so a method cannot see them); it returns all ``T`` frames.
:func:`score_keys` scores any other key layout (in-filling, blending) the
same way.
"""

from __future__ import annotations

import fnmatch
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from keyfill.errors import DataError, UsageError
from keyfill.learn.corpus import Corpus, load_corpus
from keyfill.learn.protocols import metrics
from keyfill.learn.windows import align_windows, global_pose, window_motion
from keyfill.motion import Skeleton

N_PAST = 10  #: context frames
N_FUTURE = 10  #: frames after the transition in the reference's windows (only the first is given)
STATS_WINDOW, STATS_OFFSET = 50, 20
TEST_WINDOW, TEST_OFFSET = 65, 40
LENGTHS = (5, 15, 30, 45)
LAFAN1_TEST_PATTERNS = ("*subject5*",)  #: LaFAN1's test split: subject 5


Method = Callable[[Skeleton, np.ndarray, np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]

@dataclass(frozen=True)
class Statistics:
    """Training statistics of the protocol.

    Attributes:
        x_mean: ``(J * 3,)`` mean of every global joint coordinate.
        x_std: ``(J * 3,)`` its standard deviation.
    """

    x_mean: np.ndarray
    x_std: np.ndarray

    def to_dict(self) -> dict:
        return {"x_mean": self.x_mean.tolist(), "x_std": self.x_std.tolist()}


def statistics(quats: np.ndarray, root: np.ndarray, skeleton: Skeleton) -> Statistics:
    """Mean and standard deviation of global joint coordinates over aligned windows ``(W, T, ...)``."""
    if len(quats) == 0:
        raise DataError("no training windows for the statistics")
    _, gpos = global_pose(quats, root, skeleton.offsets, skeleton.parents)
    flat = gpos.reshape(-1, gpos.shape[-2] * 3)
    return Statistics(flat.mean(axis=0), flat.std(axis=0))


@dataclass(frozen=True, eq=False)
class TestSet:
    """Aligned test windows of one skeleton.

    Attributes:
        skeleton: names, parents and the constant ``offsets``.
        quats: ``(W, T, J, 4)`` local quaternions.
        root: ``(W, T, 3)`` root positions.
        files: the clip file of each window.
        fps: frames per second.
    """

    skeleton: Skeleton
    quats: np.ndarray
    root: np.ndarray
    files: tuple[str, ...] = ()
    fps: float = 30.0


#: the protocol's names for baselines (the LaFAN1 paper's word for ``linear``), as its tables label them
LABELS = {"linear": "interpolation"}


def resolve_method(name_or_path: str, device: str = "cpu") -> tuple[str, Method]:
    """``(label, method)`` for a baseline's name, a learned method's name (its shipped model) or a model folder."""
    from keyfill.learn import registry

    if name_or_path in registry.METHODS or name_or_path in registry.ALIASES:
        m = registry.get(name_or_path)
        if not m.learned:
            return LABELS.get(m.name, m.name), m.windows()
    elif not Path(name_or_path).exists():
        raise UsageError(f"{name_or_path!r} is neither a method ({', '.join(sorted(registry.METHODS))}) "
                         f"nor a model folder")
    label, _, model = registry.load_model(name_or_path, device)
    return Path(label).name, model.benchmark_method()


# --- scoring -----------------------------------------------------------------------------


def evaluate(
    methods: dict[str, Method],
    test: TestSet,
    stats: Statistics,
    lengths: Sequence[int] = LENGTHS,
) -> dict[str, dict[int, dict[str, float]]]:
    """Score ``methods`` on ``test`` at each transition length (the LaFAN1 task).

    Returns ``{method: {n: {"L2Q": ..., "L2P": ..., "NPSS": ...}}}``.

    Raises:
        UsageError: a length the test windows cannot hold (``n + 20`` frames
        are needed, as in the reference, and at least one frame).
    """
    T = test.quats.shape[1]
    for n in lengths:
        if n < 1 or n + N_PAST + N_FUTURE > T:
            raise UsageError(
                f"transition length {n} does not fit: the protocol's test windows have {T} frames, "
                f"which hold transitions of 1 to {T - N_PAST - N_FUTURE} frames (10 context + n + 10)"
            )
    out: dict[str, dict[int, dict[str, float]]] = {name: {} for name in methods}
    for n in lengths:
        res = score_keys(methods, test, stats, np.append(np.arange(N_PAST), N_PAST + n))
        for name in methods:
            out[name][n] = res[name]
    return out


def score_keys(methods: dict[str, Method], test: TestSet, stats: Statistics, keys) -> dict[str, dict[str, float]]:
    """Score ``methods`` on any key layout: the test windows cut to ``keys[-1] + 1`` frames.

    Every frame between the first and the last key that is not a key is hidden
    (NaN) from the methods and scored. Returns ``{method: {"L2Q", "L2P", "NPSS",
    "skate", "jitter"[, "skate_locked", "jitter_locked"]}}``: the protocol's three metrics on the hidden frames,
    and foot skating (cm/s) and jitter (m/s^3) of :mod:`keyfill.learn.protocols.metrics` over
    the hidden frames and the two frames on each side (:func:`realism_span`), of the raw output and, for a
    humanoid test skeleton, of the output with its feet locked (:func:`locked_windows`).
    """
    keys = np.asarray(keys, dtype=np.int64)
    if len(test.quats) == 0:
        raise DataError("the test set has no windows")
    if keys[-1] >= test.quats.shape[1]:
        raise UsageError(f"key {keys[-1]} is beyond the {test.quats.shape[1]}-frame test windows")
    skel = test.skeleton
    T = int(keys[-1]) + 1
    hidden = np.setdiff1d(np.arange(keys[0], T), keys)
    gt_q, gt_r = test.quats[:, :T], test.root[:, :T]
    given_q, given_r = gt_q.copy(), gt_r.copy()
    given_q[:, hidden] = np.nan
    given_r[:, hidden] = np.nan
    g_q, g_p = global_pose(gt_q[:, hidden], gt_r[:, hidden], skel.offsets, skel.parents)
    span = realism_span(hidden, T)
    _, ground = global_pose(gt_q, gt_r, skel.offsets, skel.parents)
    rig = _rig(skel)
    out = {}
    for name, method in methods.items():
        p_q, p_r = method(skel, given_q, given_r, keys)
        if p_q.shape != gt_q.shape or p_r.shape != gt_r.shape:
            raise ValueError(f"method {name!r} returned shapes {p_q.shape}, {p_r.shape}")
        pr_q, pr_p = global_pose(p_q[:, hidden], p_r[:, hidden], skel.offsets, skel.parents)
        out[name] = {
            "L2Q": metrics.l2q(g_q, pr_q),
            "L2P": metrics.l2p(g_p, pr_p, stats.x_mean, stats.x_std),
            "NPSS": metrics.npss(g_q, pr_q),
            **realism_scores(test, p_q[:, span], p_r[:, span], ground),
        }
        if rig is not None:  # the same output with its feet locked, as `keyfill complete --feet lock` writes it
            l_q, l_r = locked_windows(test, rig, p_q, p_r, keys)
            locked = realism_scores(test, l_q[:, span], l_r[:, span], ground)
            out[name].update({"skate_locked": locked["skate"], "jitter_locked": locked["jitter"]})
    return out


def _rig(skeleton: Skeleton):
    """The humanoid rig of the test skeleton, or None when it has no legs to lock (then no locked scores)."""
    from keyfill.characters.retarget import make_rig

    try:
        return make_rig(skeleton)
    except DataError:
        return None


def locked_windows(test: TestSet, rig, quats: np.ndarray, root: np.ndarray, keys) -> tuple[np.ndarray, np.ndarray]:
    """Windows ``quats (N, T, J, 4)``, ``root (N, T, 3)`` with their feet locked between ``keys``
    (:func:`keyfill.characters.feet.lock_feet`, window by window)."""
    from keyfill.characters.feet import lock_feet

    out_q, out_r = np.empty_like(quats), np.empty_like(root)
    for b in range(len(quats)):
        locked, _ = lock_feet(window_motion(test.skeleton, quats[b], root[b], test.fps), rig, keys)
        out_q[b], out_r[b] = locked.rotations, locked.positions[:, 0]
    return out_q, out_r


def realism_span(hidden: np.ndarray, num_frames: int) -> np.ndarray:
    """The frames realism is measured on: the hidden ones and two on each side (third differences reach the keys)."""
    return np.arange(max(int(hidden[0]) - 2, 0), min(int(hidden[-1]) + 3, num_frames))


def realism_scores(test: TestSet, quats: np.ndarray, root: np.ndarray, reference: np.ndarray) -> dict[str, float]:
    """Foot skating (cm/s) and jitter (m/s^3) of windows ``quats (N, T, J, 4)``, ``root (N, T, 3)``.

    ``reference`` holds global positions ``(N, T', J, 3)`` of the ground truth, whose lowest foot heights are
    the floor.
    """
    skel = test.skeleton
    _, pos = global_pose(quats, root, skel.offsets, skel.parents)
    return {
        "skate": metrics.foot_skating(pos, metrics.foot_joints(skel), skel.up_axis, test.fps, skel.meters_per_unit,
                                      reference),
        "jitter": metrics.jitter(pos, test.fps, skel.meters_per_unit),
    }


# --- the protocol from BVH files ----------------------------------------------------


def _matches(name: str, patterns: Sequence[str]) -> bool:
    return any(fnmatch.fnmatch(name, p) for p in patterns)


@dataclass
class Protocol:
    """The prepared LaFAN1 protocol: aligned test windows, training statistics, a summary."""

    test: TestSet
    stats: Statistics
    info: dict = field(default_factory=dict)


def split(corpus: Corpus, test_patterns: Sequence[str], train_patterns: Sequence[str] = ()) -> tuple[Corpus, Corpus]:
    """``(train, test)`` clips by file-name patterns (test: any of ``test_patterns``).

    Training clips are those matching ``train_patterns`` or, when none are
    given, all clips that are not test clips.
    """
    names = [Path(f).name for f in corpus.files]
    test_idx = [i for i, n in enumerate(names) if _matches(n, test_patterns)]
    if train_patterns:
        train_idx = [i for i, n in enumerate(names) if _matches(n, train_patterns)]
        both = sorted(set(train_idx) & set(test_idx))
        if both:
            raise UsageError(f"{names[both[0]]} matches both a training and a test pattern")
    else:
        train_idx = [i for i in range(len(names)) if i not in set(test_idx)]
    if not test_idx:
        raise DataError(f"no clip matches the test pattern {', '.join(test_patterns)}")
    if not train_idx:
        raise DataError("no clips left for training statistics")
    return corpus.subset(train_idx), corpus.subset(test_idx)


def prepare(
    corpus: Corpus,
    test_patterns: Sequence[str],
    train_patterns: Sequence[str] = (),
    facing_axis: str = "+Y",
) -> Protocol:
    """Split ``corpus``, cut and align the windows, and compute the statistics."""
    train, test = split(corpus, test_patterns, train_patterns)
    up = corpus.skeleton.up_axis
    tq, tr, _, t_skip = train.windows(STATS_WINDOW, STATS_OFFSET)
    if len(tq) == 0:
        raise DataError(f"no training clip is longer than {STATS_WINDOW} frames, the protocol's statistics window")
    tq, tr = align_windows(tq, tr, facing_axis, up)
    stats = statistics(tq, tr, corpus.skeleton)
    q, r, clip_of, s_skip = test.windows(TEST_WINDOW, TEST_OFFSET)
    if len(q) == 0:
        raise DataError(f"no test clip is longer than {TEST_WINDOW} frames, the protocol's test window")
    q, r = align_windows(q, r, facing_axis, up)
    info = {
        "train_clips": len(train),
        "test_clips": len(test),
        "train_windows": len(tq),
        "test_windows": len(q),
        "train_clips_too_short": t_skip,
        "test_clips_too_short": s_skip,
        "folded_root": corpus.folded,
        "facing_axis": facing_axis,
    }
    files = tuple(test.files[c] for c in clip_of)
    return Protocol(TestSet(corpus.skeleton, q, r, files, corpus.fps), stats, info)


def lafan1(
    paths: Sequence[str | Path],
    test_patterns: Sequence[str],
    train_patterns: Sequence[str] = (),
    fold: bool | None = None,
    facing_axis: str = "+Y",
    cache: bool = True,
    progress=None,
) -> Protocol:
    """Prepare the LaFAN1 protocol from folders of BVH files (see :func:`prepare`)."""
    corpus = load_corpus(paths, fold=fold, cache=cache, progress=progress)
    return prepare(corpus, test_patterns, train_patterns, facing_axis)


def format_table(results: dict[str, dict[int, dict[str, float]]], reference: str | None = "interpolation") -> str:
    """The familiar table: one row per method, L2Q / L2P / NPSS at each transition length.

    With ``reference`` among several methods, a second block gives every other
    method's scores divided by the reference's.
    """
    lengths = sorted({n for r in results.values() for n in r})
    names = list(results)
    width = max(len(n) for n in names + ["relative to " + str(reference)])
    cell = {"L2Q": 7, "L2P": 7, "NPSS": 8}
    digits = {"L2Q": 4, "L2P": 4, "NPSS": 5}

    def block(metric, values):
        return " ".join(f"{v:{cell[metric]}.{digits[metric]}f}" for v in values)

    def header(label, fill):
        return f"{label:{width}} " + "  ".join(
            " ".join(f"{fill(m, n):>{cell[m]}}" for n in lengths) for m in ("L2Q", "L2P", "NPSS"))

    lines = [
        f"{'':{width}} " + "  ".join(f"{m:<{(cell[m] + 1) * len(lengths) - 1}}" for m in ("L2Q", "L2P", "NPSS")),
        header("transition length", lambda m, n: n) if width >= 17 else header("length", lambda m, n: n),
    ]
    for name in names:
        lines.append(f"{name:{width}} " + "  ".join(block(m, [results[name][n][m] for n in lengths])
                                                    for m in ("L2Q", "L2P", "NPSS")))
    if reference in results and len(names) > 1:
        lines.append(f"relative to {reference}")
        for name in names:
            if name != reference:
                lines.append(f"{name:{width}} " + "  ".join(
                    block(m, [results[name][n][m] / results[reference][n][m] for n in lengths])
                    for m in ("L2Q", "L2P", "NPSS")))
    return "\n".join(lines)


def run(
    method_or_model: str,
    data: Sequence[str | Path],
    test_patterns: Sequence[str] = (),
    train_patterns: Sequence[str] = (),
    lengths: Sequence[int] = LENGTHS,
    fold: bool | None = None,
    facing_axis: str = "+Y",
    baselines: bool = True,
    device: str = "cpu",
    progress=None,
):
    """The LaFAN1 protocol as ``keyfill evaluate`` runs it: an :class:`~keyfill.learn.protocols.Evaluation`.

    ``method_or_model`` is a baseline (zero-velocity, linear, interpolation, cubic, velocity), a learned method's
    name (its shipped model) or a model folder; the baselines zero-velocity and interpolation are scored
    beside it unless ``baselines`` is False.
    """
    from keyfill.learn.protocols import Evaluation

    label, method = resolve_method(method_or_model, device)
    methods = {label: method}
    if baselines:
        for name in ("zero-velocity", "linear"):
            methods.setdefault(*resolve_method(name))
    proto = lafan1(data, test_patterns or LAFAN1_TEST_PATTERNS, train_patterns,
                   fold=fold if fold is not None else getattr(method, "folded", None),
                   facing_axis=facing_axis, progress=progress)
    results = evaluate(methods, proto.test, proto.stats, lengths)
    info = {**proto.info, "truth": truth_realism(proto.test, lengths)}
    lines = [(f"lafan1: {info['test_windows']} test windows from {info['test_clips']} clips, "
              f"statistics from {info['train_windows']} windows of {info['train_clips']} clips")]
    if info.get("test_clips_too_short", 0) + info.get("train_clips_too_short", 0):
        lines.append(f"skipped {info['test_clips_too_short']} test and {info['train_clips_too_short']} training "
                     f"clips shorter than a window")
    table = format_table(results) + "\n\n" + format_realism(results, info["truth"])
    return Evaluation("lafan1", method_or_model, info,
                      {m: {str(n): v for n, v in r.items()} for m, r in results.items()}, lines, table)


def truth_realism(test: TestSet, lengths: Sequence[int] = LENGTHS) -> dict[int, dict[str, float]]:
    """Foot skating and jitter of the ground truth over the frames :func:`score_keys` measures at each length."""
    out = {}
    for n in lengths:
        T = N_PAST + n + 1
        span = realism_span(np.arange(N_PAST, N_PAST + n), T)
        _, ground = global_pose(test.quats[:, :T], test.root[:, :T], test.skeleton.offsets, test.skeleton.parents)
        out[n] = realism_scores(test, test.quats[:, span], test.root[:, span], ground)
    return out


def format_realism(results: dict[str, dict[int, dict[str, float]]], truth: dict[int, dict[str, float]]) -> str:
    """Foot skating (cm/s) and jitter (m/s^3) over the transitions: one row per method and the ground truth."""
    lengths = sorted(truth)
    rows = {**results, "ground truth": truth}
    width = max(len(n) for n in [*rows, "transition length"])
    labels = {"skate": "foot skating (cm/s)", "jitter": "jitter (m/s^3)"}
    if all("skate_locked" in r[n] for r in results.values() for n in lengths):
        labels.update({"skate_locked": "skating, feet locked", "jitter_locked": "jitter, feet locked"})
    # cells wide enough that each block holds its label
    cell = max(7, -(-(max(len(v) for v in labels.values()) + 1) // len(lengths)) - 1)
    block = (cell + 1) * len(lengths) - 1

    def cells(fmt):
        return "  ".join(" ".join(fmt(m, n) for n in lengths) for m in labels)

    lines = [(f"{'':{width}} " + "  ".join(f"{labels[m]:<{block}}" for m in labels)).rstrip(),
             f"{'transition length':{width}} " + cells(lambda m, n: f"{n:>{cell}}")]
    for name, r in rows.items():
        lines.append(f"{name:{width}} " + cells(lambda m, n, r=r: f"{r[n][m]:{cell}.2f}" if m in r[n]
                                                else f"{'-':>{cell}}"))
    return "\n".join(lines)

