"""Training the motion-completion transformer (section 4.3 of Duan et al. 2021).

One model learns every key layout at once: each batch draws a layout
(:func:`sample_layout`) shared by its windows:

* ``inbetween``: 10 context frames, ``n`` unknown frames, one target key, then
  a few ignored frames (the LaFAN1 task; ``n`` from 5 up to what the window holds);
* ``infill``: a key every ``k`` frames (2 <= k <= 15);
* ``blend``: a head and a tail of given frames (5-15 each) around a gap of 5-40.

Windows (65 frames at offset 20 by default) come from the training clips of a
:class:`~keyfill.learn.corpus.Corpus`; half of them are mirrored left-right
where the skeleton allows; each is put in the model's canonical
frame for its layout, the unknown frames are pre-filled, and the losses of
:func:`keyfill.learn.transformer.losses` are minimised with Adam. The learning
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
import fnmatch
import glob
import json
import math
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from keyfill.errors import DataError, ModelError, UsageError
from keyfill.learn import benchmark
from keyfill.learn.corpus import Corpus, find_mirror
from keyfill.learn.transformer import (
    CompletionModel,
    ModelConfig,
    apply_transform,
    canonical_transform,
    frame_kinds,
    losses,
    new_model,
    torch_device,
)

LAYOUTS = ("inbetween", "infill", "blend")


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
        val_fraction: share of the training clips held out for validation.
        val_lengths: transition lengths scored after each epoch.
        grad_clip: clip the gradient norm (0: off).
        mirror: mirror half of the windows left-right, where the skeleton allows
            (:func:`keyfill.learn.corpus.find_mirror`).
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
    val_fraction: float = 0.05
    val_lengths: tuple = (5, 15, 30, 45)
    grad_clip: float = 1.0
    mirror: bool = True

    def __post_init__(self):
        bad = set(self.layouts) - set(LAYOUTS)
        if bad:
            raise UsageError(f"unknown key layout {min(bad)!r}; layouts are {', '.join(LAYOUTS)}")
        if self.window < 2 * benchmark.N_PAST + 1:
            raise UsageError(f"training windows of {self.window} frames are too short (at least 21)")
        if self.epochs < 1 or self.batch_size < 1:
            raise UsageError("epochs and batch size must be positive")


def read_config(path: str | os.PathLike | None) -> tuple[ModelConfig, TrainConfig]:
    """``(ModelConfig, TrainConfig)`` from a JSON file ``{"model": {...}, "training": {...}}`` (or defaults)."""
    if path is None:
        return ModelConfig(), TrainConfig()
    try:
        data = json.loads(Path(path).read_text())
    except OSError as e:
        raise UsageError(f"{path}: cannot read the config ({e.strerror})") from None
    except json.JSONDecodeError as e:
        raise UsageError(f"{path}:{e.lineno}: not valid JSON ({e.msg})") from None
    unknown = set(data) - {"model", "training"}
    if unknown:
        raise UsageError(f"{path}: unknown section {min(unknown)!r}; sections are 'model' and 'training'")
    try:
        model = ModelConfig(**data.get("model", {}))
        train = TrainConfig(**{k: tuple(v) if k == "val_lengths" else v for k, v in data.get("training", {}).items()})
    except TypeError as e:
        raise UsageError(f"{path}: {e}") from None
    return model, train


def select_clips(corpus: Corpus, include=(), exclude=()) -> Corpus:
    """The clips whose file name matches one of ``include`` (all when empty) and none of ``exclude``."""
    names = [Path(f).name for f in corpus.files]
    keep = [
        i for i, n in enumerate(names)
        if (not include or any(fnmatch.fnmatch(n, p) for p in include)) and not any(fnmatch.fnmatch(n, p) for p in exclude)
    ]
    if not keep:
        raise DataError(f"no clip is left after --include {list(include)} and --exclude {list(exclude)}")
    return corpus.subset(keep) if len(keep) < len(names) else corpus


# --- layouts and batches ---------------------------------------------------------------


def sample_layout(rng: np.random.Generator, layouts: dict, max_frames: int) -> tuple[str, int, np.ndarray]:
    """Draw ``(name, frames T, keys)`` of one key layout that fits ``max_frames``."""
    names = list(layouts)
    p = np.asarray([layouts[n] for n in names], dtype=np.float64)
    name = names[int(rng.choice(len(names), p=p / p.sum()))]
    past = benchmark.N_PAST
    if name == "inbetween":
        n = int(rng.integers(5, max_frames - past - 1 + 1))
        extra = int(rng.integers(0, min(5, max_frames - past - 1 - n) + 1))
        keys = np.append(np.arange(past), past + n)
        return name, past + n + 1 + extra, keys
    if name == "infill":
        k = int(rng.integers(2, 16))
        m = int(rng.integers(2, (max_frames - 1) // k + 1))
        return name, m * k + 1, np.arange(0, m * k + 1, k)
    head, tail = int(rng.integers(5, 16)), int(rng.integers(5, 16))
    gap = int(rng.integers(5, min(40, max_frames - head - tail) + 1))
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
    pq, pr = benchmark.interpolation(None, q, r, keys)
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
    validation: benchmark.Protocol | None
    info: dict


def split_corpus(corpus: Corpus, cfg: TrainConfig, seed: int, facing_axis: str) -> Split:
    """Hold out ``val_fraction`` of the clips (seeded) and cut the training windows."""
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
            validation = benchmark.prepare(merged, names, facing_axis=facing_axis)
        except DataError:
            validation = None  # validation clips too short for the protocol's windows
    info = {
        "train_clips": len(train),
        "validation_clips": int(n_val),
        "train_windows": len(q),
        "clips_too_short": int(skipped),
    }
    return Split(q.astype(np.float32), r.astype(np.float32), validation, info)


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
) -> CompletionModel:
    """Train a transformer on ``corpus`` and write it to the model folder ``output``.

    Beside ``output`` it keeps ``<output>.checkpoint.pt`` (the checkpoint after
    the last finished epoch, read with ``torch.load(weights_only=True)``) and
    ``<output>.log.jsonl`` (one JSON line per epoch: losses, learning rate,
    validation L2Q / L2P / NPSS, seconds), as ``keyfill train arnn`` does.

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
    """
    import torch

    device = torch_device(device)
    output = Path(output)
    ckpt_path, log_path = side_files(output)
    _check_output(output)
    if model_cfg.max_frames < cfg.window:
        raise UsageError(f"the model's max_frames ({model_cfg.max_frames}) is shorter than the training window ({cfg.window})")
    data = split_corpus(corpus, cfg, seed, model_cfg.facing_axis)
    up = corpus.skeleton.up_axis
    aq, ar = benchmark.align_windows(data.quats, data.root, model_cfg.facing_axis, up)
    _, gpos = benchmark.global_pose(aq, ar, corpus.skeleton.offsets, corpus.skeleton.parents)
    flat = gpos.reshape(-1, gpos.shape[-2] * 3)
    mirror = None
    if cfg.mirror:
        sample = np.random.default_rng([seed, 104729]).choice(len(corpus.quats), min(len(corpus.quats), 20000), replace=False)
        mirror = find_mirror(corpus.skeleton, corpus.quats[np.sort(sample)])
    info = {"seed": seed, "corpus_clips": len(corpus), **data.info, "mirrored": mirror is not None}
    if data.validation is not None:
        info["validation_windows"] = data.validation.info["test_windows"]
    if started is not None:
        started(info)

    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        model = new_model(corpus.skeleton, model_cfg, flat.mean(0), flat.std(0), corpus.folded, info)
        model.to(device)
        net = model.network
        opt = torch.optim.Adam(net.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
        start_epoch, history = 0, []
        if resume:
            start_epoch, history = _load_checkpoint(ckpt_path, net, opt, model_cfg, cfg, seed)
        elif log_path.exists():
            log_path.unlink()
        n = len(data.quats)
        steps = max(n // cfg.batch_size, 1)
        for epoch in range(start_epoch, cfg.epochs):
            t0 = time.perf_counter()
            rng = np.random.default_rng([seed, epoch])
            torch.manual_seed(int(rng.integers(2**62)))
            order = rng.permutation(n)
            net.train()
            sums: dict[str, float] = {}
            bar = progress(total=steps, desc=f"epoch {epoch + 1}/{cfg.epochs}") if progress else None
            for step in range(steps):
                lr = learning_rate(cfg, epoch + step / steps)
                for g in opt.param_groups:
                    g["lr"] = lr
                _, T, keys = sample_layout(rng, cfg.layouts, cfg.window)
                idx = order[step * cfg.batch_size : (step + 1) * cfg.batch_size]
                wq, wr = data.quats[idx, :T], data.root[idx, :T]
                if mirror is not None:
                    flip = rng.random(len(idx)) < 0.5
                    wq, wr = wq.astype(np.float64), wr.astype(np.float64)
                    wq[flip], wr[flip] = mirror(wq[flip], wr[flip])
                x, y, gq, gr, kinds = make_batch(model, wq, wr, keys, T)
                out = losses(model.features, net(x, kinds), y, gq, gr, kinds, model_cfg)
                opt.zero_grad(set_to_none=True)
                out["total"].backward()
                if cfg.grad_clip > 0:
                    torch.nn.utils.clip_grad_norm_(net.parameters(), cfg.grad_clip)
                opt.step()
                if not math.isfinite(float(out["total"].detach())):
                    raise ModelError(f"training diverged at epoch {epoch + 1}, step {step + 1} (loss is not finite); lower the learning rate")
                for k, v in out.items():
                    sums[k] = sums.get(k, 0.0) + float(v.detach())
                if bar is not None:
                    bar.update(1)
                    bar.set_postfix(loss=f"{sums['total'] / (step + 1):.4f}")
            if bar is not None:
                bar.close()
            record = {"epoch": epoch + 1, "lr": lr, **{f"loss_{k}": v / steps for k, v in sums.items()}}
            net.eval()
            if data.validation is not None:
                res = benchmark.evaluate({"model": model.benchmark_method(), "interpolation": benchmark.interpolation},
                                         data.validation.test, data.validation.stats, cfg.val_lengths)
                for n_, scores in res["model"].items():
                    for m, v in scores.items():
                        record[f"val_{m}_{n_}"] = v
                        record[f"val_{m}_{n_}_vs_interp"] = v / res["interpolation"][n_][m]
            record["seconds"] = time.perf_counter() - t0
            history.append(record)
            _append_log(log_path, record)
            _save_checkpoint(ckpt_path, net, opt, model_cfg, cfg, seed, epoch + 1, history)
            if report is not None:
                report(record)
    final = {k: v for k, v in (history[-1] if history else {}).items() if k != "seconds"}  # files stay reproducible
    model.info.update({"epochs": cfg.epochs, "training": dataclasses.asdict(cfg), "final": final})
    model.save(output)
    return model


def side_files(output: str | os.PathLike) -> tuple[Path, Path]:
    """``(checkpoint, log)`` kept beside the model folder ``output``: ``OUTPUT.checkpoint.pt``, ``OUTPUT.log.jsonl``."""
    output = Path(output)
    return output.with_name(output.name + ".checkpoint.pt"), output.with_name(output.name + ".log.jsonl")


def _check_output(output: Path) -> None:
    """Refuse an output that could not be written, before training rather than after."""
    from keyfill.learn.modelfile import CONFIG

    if not output.parent.is_dir():
        raise UsageError(f"{output}: the output folder {str(output.parent)!r} does not exist")
    if output.exists() and not (output / CONFIG).is_file():
        raise UsageError(f"{output}: exists and is not a keyfill model; refusing to replace it")


def _append_log(path: Path, record: dict) -> None:
    with open(path, "a") as fh:
        fh.write(json.dumps(record, sort_keys=True) + "\n")


def _save_checkpoint(path: Path, net, opt, model_cfg, cfg, seed, epoch, history) -> None:
    import torch

    from keyfill.files import atomic_output

    state = {
        "format": "keyfill-transformer-checkpoint",
        "epoch": epoch,
        "seed": seed,
        "config": json.dumps({"model": dataclasses.asdict(model_cfg), "training": dataclasses.asdict(cfg)}),
        "history": json.dumps(history),
        "network": net.state_dict(),
        "optimizer": opt.state_dict(),
    }
    with atomic_output(path) as tmp:
        torch.save(state, tmp)


def _load_checkpoint(path: Path, net, opt, model_cfg, cfg, seed) -> tuple[int, list]:
    import torch

    if not path.is_file():
        raise UsageError(f"--resume: no checkpoint {path}")
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as e:  # noqa: BLE001 - torch raises many types for damaged or foreign files
        raise ModelError(f"{path}: cannot resume from it ({' '.join(str(e).split())[:200]})") from None
    if not isinstance(state, dict) or state.get("format") != "keyfill-transformer-checkpoint":
        raise ModelError(f"{path}: cannot resume from it (not a keyfill transformer checkpoint)")
    saved = json.loads(state["config"])
    now = json.loads(json.dumps({"model": dataclasses.asdict(model_cfg), "training": dataclasses.asdict(cfg)}))
    for part in ("model", "training"):
        for k, v in saved[part].items():
            if k != "epochs" and now[part].get(k) != v:
                raise UsageError(f"--resume: the checkpoint was trained with {part} {k}={v!r}, now {now[part].get(k)!r}")
    if state["seed"] != seed:
        raise UsageError(f"--resume: the checkpoint was trained with --seed {state['seed']}, now {seed}")
    net.load_state_dict(state["network"])
    opt.load_state_dict(state["optimizer"])
    return int(state["epoch"]), json.loads(state["history"])
