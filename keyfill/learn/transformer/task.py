"""Training the motion-completion transformer (section 4.3 of Duan et al. 2021).

One model learns every key layout at once: each batch draws a layout
(:func:`sample_layout`) shared by its windows:

* ``inbetween``: 10 context frames, ``n`` unknown frames, one target key, then
  a few ignored frames (the LaFAN1 task; ``n`` from 5 up to what the window holds);
* ``infill``: a key every ``k`` frames (2 <= k <= 15);
* ``blend``: a head and a tail of given frames (5-15 each) around a gap of 5-40.

The gap lengths ``n`` of ``inbetween`` and ``blend`` are uniform over their
range, or with ``gap_sampling: "log-uniform"`` drawn with probability
proportional to ``1 / n``, which trains short transitions about twice as often.

Windows (65 frames at offset 20 by default) come from the training clips of a
:class:`~keyfill.learn.corpus.Corpus`; half of them are mirrored left-right
where the skeleton allows; each is put in the model's canonical
frame for its layout, the unknown frames are pre-filled, and the losses of
:func:`keyfill.learn.transformer.network.losses` (plus, with ``foot_weight`` or ``smooth_weight``, the
realism terms of :mod:`keyfill.learn.transformer.realism`) are minimised with Adam. The learning
rate warms up linearly over the first epochs, then decays by a constant factor
every few epochs (the paper: 50 warm-up epochs, x0.75 every 200 of 1,000).

After every epoch the model is scored with the LaFAN1 protocol on held-out
validation clips (a seeded fraction of the training files), a line is added to
the JSONL log and a checkpoint is written, from which ``resume`` continues with
the same result as an uninterrupted run. Randomness comes from ``seed`` only:
the batches of epoch ``e`` from ``numpy.random.default_rng([seed, e])``, the
weights and dropout from torch's generator seeded inside
``torch.random.fork_rng`` (the caller's global state is left as it was).
"""

from __future__ import annotations

import dataclasses
import glob
import math
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from keyfill import interpolate
from keyfill.errors import DataError, ModelError, UsageError
from keyfill.files import read_json_object
from keyfill.learn.augment import perturb_posture, posture_joints, retime
from keyfill.learn.corpus import Corpus, find_mirror
from keyfill.learn.modelfile import load_state, torch_device
from keyfill.learn.protocols import lafan1
from keyfill.learn.training import Option, TrainingSpec, TrainingTask, check_outputs, side_files
from keyfill.learn.training import train as run_training
from keyfill.learn.transformer.config import ModelConfig
from keyfill.learn.transformer.features import apply_transform, canonical_transform, frame_kinds
from keyfill.learn.transformer.model import KIND, CompletionModel, load, new_model
from keyfill.learn.transformer.network import losses, widen_input
from keyfill.learn.transformer.realism import column_swap, contact_windows, realism_losses
from keyfill.learn.transformer.starts import draw_batch
from keyfill.learn.transformer.starts import load as load_starts
from keyfill.learn.windows import align_windows, global_pose
from keyfill.limits import check_number

LAYOUTS = ("inbetween", "infill", "blend")
GAP_SAMPLING = ("uniform", "log-uniform")
#: training settings added after the first checkpoints were written, with the value that behaves as before: at
#: that value they are left out of what --resume compares and of the settings a model records, so an older
#: checkpoint still resumes and an older run retrains to the same files (as
#: :data:`keyfill.learn.transformer.model.LATER_ARCHITECTURE` for the model's settings)
LATER_TRAINING = {"gap_sampling": "uniform", "relative_loss": False, "posture_angle": 0.0, "slowest_tempo": 1.0,
                  "matched_starts": None, "matched_share": 0.0}


@dataclass(frozen=True)
class TrainConfig:
    """Training settings (a ``--config`` JSON file has ``"model"`` and ``"training"`` objects).

    Attributes:
        epochs: passes over the training windows.
        batch_size: windows per step.
        lr: the peak learning rate (Adam).
        warmup_epochs: linear warm-up from 0 to ``lr``.
        decay_every, decay: multiply the rate by ``decay`` every ``decay_every`` epochs.
        weight_decay: Adam's L2 penalty.
        window, window_offset: training windows cut from the clips.
        layouts: probability of each key layout per batch.
        gap_sampling: how transition lengths are drawn, "uniform" or "log-uniform" (see the module).
        relative_loss: minimise each batch's loss divided by the pre-fill's loss on that batch (a ratio, as
            the benchmark scores), so that short gaps, whose absolute errors are several times smaller than
            long ones', pull as hard on the weights; the logged losses stay absolute.
        val_fraction: share of the training clips held out for validation.
        val_lengths: transition lengths scored after each epoch.
        grad_clip: clip the gradient norm (0: off).
        mirror: mirror half of the windows left-right, where the skeleton allows
            (:func:`keyfill.learn.corpus.find_mirror`).
        posture_angle: style augmentation: turn each torso joint of every window by a constant random
            rotation of up to this many radians (:func:`keyfill.learn.augment.perturb_posture`; 0: off).
        slowest_tempo: style augmentation: play half of the windows slower, at a speed from this to 1
            (:func:`keyfill.learn.augment.retime`; 1: off).
        matched_starts, matched_share: a start set (:mod:`keyfill.learn.transformer.starts`; None: off) and the
            share of batches drawn from it, which start the network from a match instead of the pre-fill.
    """

    epochs: int = 40
    batch_size: int = 64
    lr: float = 5e-4
    warmup_epochs: float = 2.0
    decay_every: float = 8.0
    decay: float = 0.75
    weight_decay: float = 0.0
    window: int = 65
    window_offset: int = 20
    layouts: dict = field(default_factory=lambda: {"inbetween": 0.6, "infill": 0.2, "blend": 0.2})
    gap_sampling: str = "uniform"
    relative_loss: bool = False
    val_fraction: float = 0.05
    val_lengths: tuple = (5, 15, 30, 45)
    grad_clip: float = 1.0
    mirror: bool = True
    posture_angle: float = 0.0
    slowest_tempo: float = 1.0
    matched_starts: str | None = None
    matched_share: float = 0.0

    def recorded(self) -> dict:
        """The settings a model file and a checkpoint record: all but later ones at their old value."""
        return {k: v for k, v in dataclasses.asdict(self).items() if LATER_TRAINING.get(k, ...) != v}

    def __post_init__(self):
        for name, (whole, low, high, low_ok) in _TRAIN_NUMBERS.items():
            check_number(f"training setting {name!r}", getattr(self, name), low, high, whole=whole, low_ok=low_ok)
        if not isinstance(self.layouts, dict) or not self.layouts:
            raise UsageError(f"layouts must name at least one of {', '.join(LAYOUTS)} with its share")
        bad = set(self.layouts) - set(LAYOUTS)
        if bad:
            raise UsageError(f"unknown key layout {min(bad)!r}; layouts are {', '.join(LAYOUTS)}")
        for name, share in self.layouts.items():
            check_number(f"training setting 'layouts.{name}'", share, 0, 1e6)
        if not sum(self.layouts.values()) > 0:
            raise UsageError("the layouts' shares must not all be 0")
        longest = self.window - lafan1.N_PAST - 1
        if not self.val_lengths:
            raise UsageError("val_lengths must list at least one transition length")
        for length in self.val_lengths:
            check_number("training setting 'val_lengths'", length, 1, longest, whole=True)
        if self.gap_sampling not in GAP_SAMPLING:
            raise UsageError(f"unknown gap_sampling {self.gap_sampling!r}; it is one of {', '.join(GAP_SAMPLING)}")
        for name in ("relative_loss", "mirror"):
            if not isinstance(getattr(self, name), bool):
                raise UsageError(f"{name} must be true or false, not {getattr(self, name)!r}")
        if self.matched_starts is not None and not isinstance(self.matched_starts, str):
            raise UsageError(f"matched_starts must be a file name, not {self.matched_starts!r}")
        if self.matched_share > 0 and self.matched_starts is None:
            raise UsageError("matched_share draws batches from matched_starts: name a start set")


#: each number of the training section: (whole number?, lowest, highest, lowest allowed?); validation
#: transitions must also fit a training window after its 10 context frames and target key
_TRAIN_NUMBERS = {
    "epochs": (True, 1, 1_000_000, True), "batch_size": (True, 1, 1_000_000, True),
    "window": (True, 2 * lafan1.N_PAST + 1, 100_000, True), "window_offset": (True, 1, 100_000, True),
    "lr": (False, 0, 10, True), "warmup_epochs": (False, 0, 1e6, True), "decay_every": (False, 0, 1e6, False),
    "decay": (False, 0, 1, False), "weight_decay": (False, 0, 1e3, True), "val_fraction": (False, 0, 0.9, True),
    "grad_clip": (False, 0, 1e6, True), "posture_angle": (False, 0, math.pi, True),
    "slowest_tempo": (False, 0, 1, False), "matched_share": (False, 0, 1, True),
}


def read_config(path: str | os.PathLike | None) -> tuple[ModelConfig, TrainConfig]:
    """``(ModelConfig, TrainConfig)`` from a JSON file ``{"model": {...}, "training": {...}}`` (or defaults)."""
    if path is None:
        return ModelConfig(), TrainConfig()
    data = read_json_object(path)
    unknown = set(data) - {"model", "training"}
    if unknown:
        raise UsageError(f"{path}: unknown section {min(unknown)!r}; sections are 'model' and 'training'")
    try:
        model = ModelConfig(**data.get("model", {}))
        train = TrainConfig(**{k: tuple(v) if k == "val_lengths" else v for k, v in data.get("training", {}).items()})
    except (TypeError, ModelError, UsageError) as e:
        raise UsageError(f"{path}: {e}", params=getattr(e, "params", ())) from None
    return model, train


def initial_model(path: str | os.PathLike, corpus: Corpus) -> CompletionModel:
    """The transformer model folder a run starts from (the ``init`` parameter, ``--init``); refused when it serves
    another skeleton or its corpus was folded differently (a :class:`UsageError` naming ``init``)."""
    model = load(path)
    diff = model.skeleton.difference(corpus.skeleton, atol=1e-2 * float(np.abs(corpus.skeleton.offsets).max()))
    if diff is not None:
        raise UsageError(f"init {path}: the model serves another skeleton than the training clips: {diff}",
                         params="init")
    if model.folded != corpus.folded:
        raise UsageError(f"init {path}: the model's corpus {'folded' if model.folded else 'kept'} the top joint, "
                         f"the training clips {'fold' if corpus.folded else 'keep'} it", params="init")
    return model


# --- layouts and batches ---------------------------------------------------------------


def draw_gap(rng: np.random.Generator, low: int, high: int, sampling: str) -> int:
    """A transition length in ``[low, high]`` frames: uniform, or with probability proportional to ``1 / n``."""
    if sampling == "uniform":
        return int(rng.integers(low, high + 1))
    p = 1.0 / np.arange(low, high + 1)
    return low + int(rng.choice(len(p), p=p / p.sum()))


def sample_layout(rng: np.random.Generator, layouts: dict, max_frames: int,
                  gap_sampling: str = "uniform") -> tuple[str, int, np.ndarray]:
    """Draw ``(name, frames T, keys)`` of one key layout that fits ``max_frames``."""
    names = list(layouts)
    p = np.asarray([layouts[n] for n in names], dtype=np.float64)
    name = names[int(rng.choice(len(names), p=p / p.sum()))]
    past = lafan1.N_PAST
    if name == "inbetween":
        n = draw_gap(rng, 5, max_frames - past - 1, gap_sampling)
        extra = int(rng.integers(0, min(5, max_frames - past - 1 - n) + 1))
        keys = np.append(np.arange(past), past + n)
        return name, past + n + 1 + extra, keys
    if name == "infill":
        k = int(rng.integers(2, 16))
        m = int(rng.integers(2, (max_frames - 1) // k + 1))
        return name, m * k + 1, np.arange(0, m * k + 1, k)
    head, tail = int(rng.integers(5, 16)), int(rng.integers(5, 16))
    gap = draw_gap(rng, 5, min(40, max_frames - head - tail), gap_sampling)
    T = head + gap + tail
    return name, T, np.concatenate([np.arange(head), np.arange(head + gap, T)])


def make_batch(model: CompletionModel, quats: np.ndarray, root: np.ndarray, keys: np.ndarray, T: int):
    """Tensors for one step: ``(inputs, targets, gt_quats, gt_root, kinds)``.

    ``quats (B, >=T, J, 4)`` and ``root`` are raw windows; they are cut to ``T``
    frames and put in the canonical frame of ``keys``.
    """
    import torch

    q, r = quats[:, :T].astype(np.float64), root[:, :T].astype(np.float64)
    turn, shift = canonical_transform(q, r, keys, model.config.facing_axis, model.skeleton.up_axis)
    q, r = apply_transform(q, r, turn, shift)
    pq, pr = model.config.fill(q, r, keys)
    dev = model.device

    def t(a):
        return torch.as_tensor(a, dtype=torch.float32, device=dev)

    gq, gr = t(q), t(r)
    x = model.features.encode(t(pq), t(pr))
    y = model.features.encode(gq, gr)
    kinds = torch.as_tensor(frame_kinds(T, keys), device=dev).expand(len(q), T)
    return x, y, gq, gr, kinds


def learning_rate(cfg: TrainConfig, epoch_float: float) -> float:
    """The scheduled learning rate at a fractional epoch."""
    if cfg.warmup_epochs > 0 and epoch_float < cfg.warmup_epochs:
        return cfg.lr * epoch_float / cfg.warmup_epochs
    return cfg.lr * cfg.decay ** math.floor(epoch_float / cfg.decay_every)


# --- the loop ----------------------------------------------------------------------------


@dataclass
class Split:
    """The training windows of one run and its validation protocol (None without validation clips)."""

    quats: np.ndarray
    root: np.ndarray
    validation: lafan1.Protocol | None
    info: dict
    contacts: np.ndarray | None = None  #: (W, window, n) bool contact labels of the windows, when asked for
    contact_joints: np.ndarray | None = None  #: (n,) their joints


def split_corpus(corpus: Corpus, cfg: TrainConfig, seed: int, facing_axis: str, contacts: bool = False) -> Split:
    """Hold out ``val_fraction`` of the clips (seeded) and cut the training windows (with ``contacts``, also
    their foot contact labels, :func:`keyfill.learn.transformer.realism.contact_windows`)."""
    rng = np.random.default_rng([seed, 7919])
    C = len(corpus)
    n_val = round(cfg.val_fraction * C) if C > 1 else 0
    order = rng.permutation(C)
    val_idx, train_idx = np.sort(order[:n_val]), np.sort(order[n_val:])
    train = corpus.subset(train_idx)
    q, r, _, skipped = train.windows(cfg.window, cfg.window_offset)
    if len(q) == 0:
        raise DataError(f"no training clip has more than {cfg.window} frames (the training window)")
    validation = None
    if n_val:
        val = corpus.subset(val_idx)
        names = [glob.escape(Path(f).name) for f in val.files]
        merged = corpus.subset(np.concatenate([train_idx, val_idx]))
        try:
            validation = lafan1.prepare(merged, names, facing_axis=facing_axis)
        except DataError:
            validation = None  # validation clips too short for the protocol's windows
    info = {
        "train_clips": len(train),
        "validation_clips": int(n_val),
        "train_windows": len(q),
        "clips_too_short": int(skipped),
    }
    split = Split(q.astype(np.float32), r.astype(np.float32), validation, info)
    if contacts:
        split.contacts, split.contact_joints = contact_windows(train, cfg.window, cfg.window_offset)
        info["contact_columns"] = int(split.contact_joints.size)
    return split


class TransformerTask(TrainingTask):
    """The transformer as a task of the one training loop (:mod:`keyfill.learn.training`).

    The batches of epoch ``e`` draw from ``numpy.random.default_rng([seed, e])``
    (layouts, order, mirroring) and reseed torch's global generator for the
    epoch's dropout; the loop runs inside ``torch.random.fork_rng``, so the
    caller's state is untouched. A resumed run therefore needs no random state
    from the checkpoint.
    """

    kind = KIND
    checkpoint_every = 1

    def __init__(self, corpus: Corpus, model_cfg: ModelConfig, cfg: TrainConfig, seed: int = 0,
                 init: str | os.PathLike | None = None):
        if model_cfg.max_frames < cfg.window:
            raise UsageError(f"the model's max_frames ({model_cfg.max_frames}) is shorter than the training window "
                             f"({cfg.window})")
        self.corpus, self.model_cfg, self.cfg, self.seed = corpus, model_cfg, cfg, seed
        self.epochs = cfg.epochs
        self.clip = cfg.grad_clip
        self.data = split_corpus(corpus, cfg, seed, model_cfg.facing_axis, contacts=model_cfg.foot_weight > 0)
        self.mirror = None
        if cfg.mirror:
            sample = np.random.default_rng([seed, 104729]).choice(len(corpus.quats), min(len(corpus.quats), 20000),
                                                                  replace=False)
            self.mirror = find_mirror(corpus.skeleton, corpus.quats[np.sort(sample)])
        self.posture = posture_joints(corpus.skeleton) if cfg.posture_angle > 0 else None
        self.starts = (load_starts(cfg.matched_starts, corpus.skeleton.num_joints)  # {spacing: windows}
                       if cfg.matched_starts is not None and cfg.matched_share > 0 else None)
        self.contact_swap = None  # the columns of a mirrored window's contact labels
        if self.mirror is not None and self.data.contacts is not None:
            self.contact_swap = column_swap(self.mirror, self.data.contact_joints)
        self.info = {"seed": seed, "corpus_clips": len(corpus), **self.data.info, "mirrored": self.mirror is not None}
        self.init = None if init is None else initial_model(init, corpus)
        if self.init is not None:
            from keyfill.learn.modelfile import model_folder
            from keyfill.learn.onnx import weights_digest

            self.info["init"] = {"model": Path(init).name, "weights_sha256": weights_digest(model_folder(init))}
        if self.data.validation is not None:
            self.info["validation_windows"] = self.data.validation.info["test_windows"]
        self.device = "cpu"

    def config(self) -> dict:
        model = {f"model.{k}": v for k, v in self.model_cfg.recorded().items()}
        training = {f"training.{k}": v for k, v in self.cfg.recorded().items() if k != "epochs"}
        return {**model, **training, **({"init": self.info["init"]} if self.init is not None else {})}

    def fingerprint(self) -> str:
        import hashlib

        h = hashlib.sha256(repr((self.data.quats.shape, self.data.root.shape)).encode())
        h.update(np.ascontiguousarray(self.data.quats[:, ::7]).tobytes())
        h.update(np.ascontiguousarray(self.data.root).tobytes())
        return h.hexdigest()[:16]

    def begin(self, rank: int, world: int, device: str) -> None:
        self.device = torch_device(device)

    def build(self, generator):
        up = self.corpus.skeleton.up_axis
        aq, ar = align_windows(self.data.quats, self.data.root, self.model_cfg.facing_axis, up, lafan1.N_PAST - 1)
        _, gpos = global_pose(aq, ar, self.corpus.skeleton.offsets, self.corpus.skeleton.parents)
        flat = gpos.reshape(-1, gpos.shape[-2] * 3)
        mean, std = (flat.mean(0), flat.std(0)) if self.init is None else (self.init.features.pos_mean,
                                                                           self.init.features.pos_std)
        self.model = new_model(self.corpus.skeleton, self.model_cfg, mean, std, self.corpus.folded, self.info)
        if self.init is not None:
            start = widen_input(self.init.network.state_dict(), self.model.features.size, self.init.config,
                                self.model_cfg)
            if self.model_cfg.key_distances and not self.init.config.key_distances:
                # the new embeddings keep their zeros: the run starts as the model it tunes
                start.update({k: v for k, v in self.model.network.state_dict().items()
                              if k.split(".")[0] in ("since_key", "until_key")})
            load_state(self.model.network, start, self.info["init"]["model"])
        self.model.to(self.device)
        return {"network": self.model.network}

    def optimizers(self, nets):
        import torch

        return {"network": torch.optim.Adam(nets["network"].parameters(), lr=self.cfg.lr,
                                            weight_decay=self.cfg.weight_decay)}

    def steps(self, epoch: int) -> int:
        return max(len(self.data.quats) // self.cfg.batch_size, 1)

    def learning_rates(self, epoch, step, steps):
        return {"network": learning_rate(self.cfg, epoch + step / steps)}

    def batches(self, epoch):
        """``(inputs, targets, gt_quats, gt_root, kinds[, contacts])`` of each step: one key layout per batch
        (``contacts (B, T, n)`` bool: the true windows' foot contacts, with ``foot_weight``); windows mirrored,
        then retimed and their postures turned where the settings ask (:mod:`keyfill.learn.augment`)."""
        import torch

        cfg = self.cfg
        rng = np.random.default_rng([self.seed, epoch])
        torch.manual_seed(int(rng.integers(2**62)))
        order = rng.permutation(len(self.data.quats))
        for step in range(self.steps(epoch)):
            if self.starts is not None and rng.random() < cfg.matched_share:
                yield draw_batch(rng, self.starts, cfg.batch_size, self.mirror, self.model)
                continue
            _, T, keys = sample_layout(rng, cfg.layouts, cfg.window, cfg.gap_sampling)
            idx = order[step * cfg.batch_size: (step + 1) * cfg.batch_size]
            n = cfg.window if cfg.slowest_tempo < 1 else T  # retiming draws on the whole window
            wq, wr = self.data.quats[idx, :n], self.data.root[idx, :n]
            wc = None if self.data.contacts is None else self.data.contacts[idx, :n]
            if self.mirror is not None:
                flip = rng.random(len(idx)) < 0.5
                wq, wr = wq.astype(np.float64), wr.astype(np.float64)
                wq[flip], wr[flip] = self.mirror(wq[flip], wr[flip])
                if wc is not None:
                    wc[flip] = wc[flip][..., self.contact_swap]
            if cfg.slowest_tempo < 1:
                wq, wr, wc = retime(rng, wq, wr, cfg.slowest_tempo, wc)
            if self.posture is not None:
                wq = perturb_posture(rng, wq, self.posture, cfg.posture_angle)
            batch = make_batch(self.model, wq, wr, keys, T)
            yield batch if wc is None else batch + (torch.as_tensor(wc[:, :T], device=self.model.device),)

    def shard(self, batch, rank, world):
        return tuple(t[rank::world] for t in batch)

    def losses(self, pred, batch) -> dict:
        """The named losses of output ``pred`` on ``batch``: the network's, plus the realism terms whose weight
        is not 0, each added to ``"total"`` with its weight."""
        y, gq, gr, kinds = batch[1:5]
        cfg, sk = self.model_cfg, self.corpus.skeleton
        out = losses(self.model.features, pred, y, gq, gr, kinds, cfg)
        extra = realism_losses(self.model.features, pred, gq, gr, kinds, cfg,
                               contact=batch[5] if len(batch) > 5 else None, joints=self.data.contact_joints,
                               fps=self.corpus.fps, up="XYZ".index(sk.up_axis),
                               meters_per_unit=sk.meters_per_unit)
        for name, value in extra.items():
            out[name] = value
            out["total"] = out["total"] + getattr(cfg, f"{name}_weight") * value
        return out

    def step(self, batch, update):
        x, kinds = batch[0], batch[4]
        out = self.losses(self.model.network(x, kinds), batch)
        if self.cfg.relative_loss:
            import torch

            with torch.no_grad():  # the pre-filled input x scored as if it were the output
                prefill = self.losses(x, batch)["total"]
            update("network", out["total"] / prefill.clamp(min=1e-8))
        else:
            update("network", out["total"])
        return {k: float(v.detach()) for k, v in out.items()}, 1  # every step is a whole batch: equal weights

    def validate(self, epoch):
        record = {}
        if self.data.validation is not None:
            res = lafan1.evaluate({"model": self.model.benchmark_method(), "interpolation": interpolate.linear_windows},
                                     self.data.validation.test, self.data.validation.stats, self.cfg.val_lengths)
            for n_, scores in res["model"].items():
                for m, v in scores.items():
                    record[f"val_{m}_{n_}"] = v
                    record[f"val_{m}_{n_}_vs_interp"] = v / res["interpolation"][n_][m]
        return record

    def save(self, output, nets, history):
        final = {k: v for k, v in (history[-1] if history else {}).items()
                 if k not in ("seconds", "cpu_seconds")}  # files stay reproducible
        self.model.info.update({"epochs": self.cfg.epochs, "training": self.cfg.recorded(), "final": final})
        self.model.save(output)
        return self.model


def train(
    corpus: Corpus,
    output: str | os.PathLike,
    model_cfg: ModelConfig,
    cfg: TrainConfig,
    seed: int = 0,
    device: str = "cpu",
    resume: bool = False,
    progress: Callable | None = None,
    report: Callable[[dict], None] | None = None,
    started: Callable[[dict], None] | None = None,
    init: str | os.PathLike | None = None,
) -> CompletionModel:
    """Train a transformer on ``corpus`` and write it to the model folder ``output``.

    Beside ``output`` it keeps ``<output>.checkpoint.pt`` (the checkpoint after
    the last finished epoch) and ``<output>.log.jsonl`` (one JSON line per
    epoch: losses, learning rate, validation L2Q / L2P / NPSS, seconds); see
    :func:`keyfill.learn.training.train`.

    Args:
        corpus: the training clips (validation clips are held out of them).
        output: model folder to write (:mod:`keyfill.learn.modelfile`); an
            existing model there is replaced, anything else is refused before
            training starts.
        model_cfg, cfg: architecture and training settings.
        seed: the only source of randomness.
        device: torch device (``"cpu"``, ``"cuda"``).
        resume: continue from the checkpoint beside ``output``.
        progress: ``progress(total=..., desc=...)`` -> a tqdm-like bar (optional).
        report: called with each epoch's log record (optional).
        started: called once with the data summary before the first step (optional).
        init: a transformer model folder whose weights and normalisation the run starts from (fine-tuning).
    """
    torch_device(device)
    checkpoint, log = side_files(output)
    check_outputs(output, checkpoint, log)
    task = TransformerTask(corpus, model_cfg, cfg, seed, init=init)
    if started is not None:
        started(task.info)
    outcome = run_training(task, output, seed=seed, checkpoint=checkpoint, log=log, resume=resume, device=device,
                           progress=progress, on_epoch=report)
    return outcome.model if outcome.model is not None else task.model


# --- keyfill train transformer -------------------------------------------------------------------------


def _make_task(common, options: dict, progress) -> TransformerTask:
    """The task of ``keyfill train transformer``: the BVH clips in DATA, chosen by --include / --exclude."""
    from keyfill.learn.corpus import load_corpus

    model_cfg, train_cfg = read_config(options["config"])
    if common.epochs is not None:
        train_cfg = dataclasses.replace(train_cfg, epochs=common.epochs)
    if common.checkpoint_every is not None:
        raise UsageError("the transformer writes a checkpoint after every epoch; checkpoint_every does not apply",
                         params="checkpoint_every")
    corpus = load_corpus(common.data, fold=options["fold_root"],
                         progress=lambda f: progress(f, desc="reading clips", unit="file"))
    return TransformerTask(corpus.select(options["include"], options["exclude"]), model_cfg, train_cfg,
                           common.seed, init=options["init"])


def _started(task: TransformerTask) -> str:
    info = task.info
    return (f"training on {info['train_windows']} windows of {info['train_clips']} clips "
            f"({info['clips_too_short']} clips shorter than a window skipped), "
            f"validating on {info['validation_clips']} clips; mirroring {'on' if info['mirrored'] else 'off'}")


def _epoch_line(row: dict) -> str:
    vals = " ".join(f"L2P@{n} {row[f'val_L2P_{n}_vs_interp']:.3f}" for n in lafan1.LENGTHS
                    if f"val_L2P_{n}_vs_interp" in row)
    return f"epoch {row['epoch']}: loss {row['loss_total']:.4f}" + (f", vs interpolation {vals}" if vals else "")


def _finished(task: TransformerTask, outcome) -> tuple[dict, str]:
    model = outcome.model
    summary = {"output": str(outcome.output), "checkpoint": str(outcome.checkpoint), "log": str(outcome.log),
               **model.info}
    return summary, f"wrote {outcome.output} (checkpoint {outcome.checkpoint}, log {outcome.log})"


TRAINING = TrainingSpec(
    help="""Train a motion-completion transformer on the BVH clips in DATA.

    One model learns in-betweening (10 context frames and a target key),
    in-filling (a key every k frames) and blending (a given head and tail).
    After every epoch it is scored on held-out clips with the LaFAN1 protocol
    and a checkpoint is written; --resume continues an interrupted run.

    \b
    Examples:
      keyfill train transformer bandai2/data --exclude '*_normal_*' -o models/bandai2-transformer
      keyfill train transformer clips/ -o models/small --config small.json --epochs 3 --seed 1
      keyfill train transformer clips/ -o models/small --config small.json --epochs 3 --seed 1 --resume
      keyfill train transformer clips/ -o models/tuned --init models/small --config tune.json
    """,
    options=(
        Option("config", None, 'JSON file {"model": {...}, "training": {...}} overriding the defaults '
               "(see docs/transformer.md).", type="file"),
        Option("init", None, "Start from the weights of this transformer model folder (fine-tuning): same "
               "skeleton and network size; its normalisation statistics are kept.", metavar="MODEL"),
        Option("include", (), "Train only on files matching one of these patterns.", multiple=True, metavar="GLOB"),
        Option("exclude", (), "Leave out files matching these patterns (e.g. a test style).", multiple=True,
               metavar="GLOB"),
        Option("fold_root", None, "Fold a static top joint (like Bandai's joint_Root) into the hips. "
               "Default: when it is static.", flag=True),
    ),
    make_task=_make_task,
    started=_started,
    finished=_finished,
    epoch_line=_epoch_line,
)

