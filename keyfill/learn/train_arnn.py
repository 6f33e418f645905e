"""Training the lamp networks: the loss of Eq. 4, the curriculum of section 7.2, Adam as in 7.3.

Loss (Eq. 4), on standardised variables::

    L = 100 * omega * KEY + MSE over the predicted frames 1 .. T-1

where ``KEY`` is the squared error at the keys ``K >= 1`` given to the
network. The paper writes it as a sum over the keys; ``key_loss="sum"`` does
exactly that (summed over keys and variables per sequence, averaged over the
batch). The default, ``key_loss="mean"``, averages over keys and variables
instead, so the weight of a key does not grow with the number of keys and
variables: with the literal sum (54 terms for 9 keys) the key term outweighs
the frame term about 5000 to 1 per value once omega reaches 1, and the
networks learned to rush to the next key pose and wait there (frame loss 0.60
against 0.39 with the mean on a 60-sequence tuning set; see docs/arnn.md).

Curriculum (:class:`Schedule`): in the first half of training, scheduled
sampling with a teacher-forcing ratio that falls from 1 to 0 along an inverse
sigmoid, while omega = 0; in the second half omega rises from 0 to 1 along a
sigmoid (reaching 1 at 85 % of the epochs, then holding, so the network
consolidates the full loss; section 10 suggests such extra training). Without
curriculum the network always runs free and omega is 1. Each time a sequence
is used, 0-2 of its interior keys are deleted at random (section 5). Adam
starts at the paper's learning rate and, in the final phase (after omega
reaches 1; without curriculum, the second half), decays linearly to a tenth
of it, so the final weights settle instead of jittering with the last batches.

Teacher forcing is decided per batch, so a teacher-forced batch runs the GRUs
fused over whole sequences and only free-running batches step frame by frame.
Everything random (batch order, key deletion, teacher forcing, dropout, the
initial weights) draws from one ``torch.Generator`` seeded by ``seed``; with
the same data, settings, seed and thread count the model is the same bytes,
also after ``resume``. Checkpoints (every ``checkpoint_every`` epochs) hold the
weights, the optimiser, the generator state and the epoch; the log (JSONL, one
row per epoch) holds the losses on the training batches and on a held-out
split with all keys and with 1-2 keys deleted, and the wall and CPU seconds so far.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
import torch

from keyfill.errors import DataError, KeyfillError, UsageError
from keyfill.learn import arnn
from keyfill.learn.lamp_features import Batch, LampSequence, Normalizer, delete_keys, make_batch

#: weight of the key loss in Eq. 4
KEY_WEIGHT = 100.0
#: fractions of the epochs: teacher forcing decays over [0, TF_END); omega rises over [OMEGA_START, OMEGA_END]
TF_END, OMEGA_START, OMEGA_END = 0.5, 0.5, 0.85
#: steepness of the sigmoids (the logistic's argument runs from -STEEPNESS/2 to +STEEPNESS/2 over a phase)
STEEPNESS = 10.0


def sigmoid_ramp(x: float | np.ndarray) -> float | np.ndarray:
    """A logistic curve rescaled to rise from exactly 0 at ``x <= 0`` to exactly 1 at ``x >= 1``."""
    x = np.clip(x, 0.0, 1.0)
    lo, hi = 1 / (1 + math.exp(STEEPNESS / 2)), 1 / (1 + math.exp(-STEEPNESS / 2))
    return (1 / (1 + np.exp(-STEEPNESS * (x - 0.5))) - lo) / (hi - lo)


@dataclass(frozen=True)
class Schedule:
    """The curriculum of section 7.2 over ``epochs`` epochs (Figure 7)."""

    epochs: int
    curriculum: bool = True

    def teacher_forcing(self, epoch: int) -> float:
        """Probability that a batch of ``epoch`` (0-based) is teacher-forced: 1 -> 0 over the first half."""
        if not self.curriculum:
            return 0.0
        return float(1.0 - sigmoid_ramp(epoch / (TF_END * self.epochs)))

    def omega(self, epoch: int) -> float:
        """Key importance weight of ``epoch``: 0 in the first half, a sigmoid up to 1 in the second."""
        if not self.curriculum:
            return 1.0
        start, end = OMEGA_START * self.epochs, OMEGA_END * self.epochs
        return float(sigmoid_ramp((epoch - start) / max(end - start, 1e-9)))

    def lr_scale(self, epoch: int) -> float:
        """Factor on the initial learning rate: 1, then a linear decay to 0.1 once omega has reached 1."""
        start = OMEGA_END * self.epochs if self.curriculum else TF_END * self.epochs
        return float(1.0 - 0.9 * np.clip((epoch - start) / max(self.epochs - 1 - start, 1e-9), 0.0, 1.0))


@dataclass(frozen=True)
class Settings:
    """Training settings (all recorded in the model's config and the checkpoint)."""

    arch: str = "arnn"
    epochs: int = 400
    batch_size: int = 16
    lr: float = 1e-3
    curriculum: bool = True
    max_deleted: int = 2
    key_loss: str = "mean"
    clip: float = 1.0
    seed: int = 0
    checkpoint_every: int = 50
    sizes: dict = field(default_factory=dict)

    def check(self) -> "Settings":
        if self.arch not in arnn.ARCHITECTURES:
            raise UsageError(f"unknown architecture {self.arch!r}; choose one of {', '.join(arnn.ARCHITECTURES)}")
        for name in ("epochs", "batch_size", "checkpoint_every"):
            if getattr(self, name) < 1:
                raise UsageError(f"--{name.replace('_', '-')} must be at least 1, got {getattr(self, name)}")
        if not self.lr > 0 or not math.isfinite(self.lr):
            raise UsageError(f"--lr must be a positive number, got {self.lr}")
        if self.key_loss not in ("mean", "sum"):
            raise UsageError(f"--key-loss must be mean or sum, not {self.key_loss!r}")
        if self.max_deleted < 0:
            raise UsageError(f"--max-deleted must be 0 or more, got {self.max_deleted}")
        return self


@dataclass(frozen=True)
class Losses:
    """Losses on standardised variables, as in the paper's tables.

    ``key``: mean squared error at the keys given to the network (except the
    first, which is the starting frame), per key and variable; ``frame``: mean
    squared error over every predicted frame; ``total = key + frame``.
    """

    key: float
    frame: float

    @property
    def total(self) -> float:
        return self.key + self.frame


def loss_terms(pred: torch.Tensor, frames: torch.Tensor, is_key: torch.Tensor, valid: torch.Tensor):
    """The two terms of Eq. 4 and the table losses.

    Args:
        pred: ``(B, T-1, 6)`` predicted frames 1 .. T-1; frames, is_key, valid: the batch (``(B, T, ...)``).

    Returns:
        ``(key_sum, frame_mse, key_mse)``: the per-sequence key sum of squares (batch mean),
        the frame mean squared error and the key mean squared error.
    """
    err = ((pred - frames[:, 1:]) ** 2).sum(dim=-1)  # (B, T-1)
    keys = (is_key[:, 1:] & valid[:, 1:]).to(err.dtype)
    frames_mask = valid[:, 1:].to(err.dtype)
    d = frames.shape[-1]
    key_sum = (err * keys).sum() / err.shape[0]
    frame_mse = (err * frames_mask).sum() / (frames_mask.sum() * d)
    key_mse = (err * keys).sum() / (keys.sum().clamp(min=1) * d)
    return key_sum, frame_mse, key_mse


def split(sequences: list, test_fraction: float = 0.2, val_fraction: float = 0.1) -> dict[str, list]:
    """Fixed split by position: the last 20 % is ``test``, the 10 % before it ``val``, the rest ``train``.

    For the 300 sequences of ``keyfill simulate --count 300`` this is the
    paper's 240 training / 60 test sequences, with 30 of the 240 held out to
    watch training.
    """
    n = len(sequences)
    if n < 3:
        raise DataError(f"{n} sequences cannot be split into training, held-out and test parts (need 3 or more)")
    n_test = max(1, round(test_fraction * n))
    n_val = max(1, round(val_fraction * n))
    n_train = n - n_test - n_val
    if n_train < 1:
        raise DataError(f"{n} sequences leave none for training")
    return {
        "train": sequences[:n_train],
        "val": sequences[n_train: n_train + n_val],
        "test": sequences[n_train + n_val:],
    }


def _fingerprint(batch: Batch) -> str:
    h = hashlib.sha256()
    for t in (batch.frames, batch.is_key, batch.lengths):
        h.update(t.numpy().tobytes())
    return h.hexdigest()[:16]


class TrainingDiverged(KeyfillError):
    """The loss became NaN or infinite."""


@dataclass
class Result:
    """What :func:`train` did."""

    path: Path
    epochs: int
    seconds: float
    cpu_seconds: float
    val: dict
    weights: int
    log: Path | None


def train(
    train_set: list[LampSequence],
    val_set: list[LampSequence],
    settings: Settings,
    output: str | os.PathLike,
    checkpoint: str | os.PathLike | None = None,
    log: str | os.PathLike | None = None,
    resume: bool = False,
    on_epoch: Callable[[dict], None] | None = None,
    source: str = "",
) -> Result:
    """Train a network on ``train_set`` and write the model folder ``output``.

    Args:
        train_set, val_set: sequences with every frame and their keys (``val_set`` is only watched).
        settings: see :class:`Settings`.
        checkpoint: checkpoint file, written every ``settings.checkpoint_every`` epochs
            (and read with ``resume``).
        log: JSONL file, one row of losses per epoch.
        on_epoch: called with each log row (e.g. to update a progress bar).
        source: a note on where the data came from, kept in the model config.

    Raises :class:`TrainingDiverged` (keeping the last good checkpoint) when a loss is not finite.
    """
    settings.check()
    _check_outputs(output, checkpoint, log)
    if not train_set:
        raise DataError("no training sequences")
    if not val_set:
        raise DataError("no held-out sequences to watch training with")
    normalizer = Normalizer.fit(train_set)
    data = make_batch(train_set, normalizer)
    val = make_batch(val_set + val_set, normalizer)
    val_deleted = delete_keys(val.is_key[len(val_set):], val.valid[len(val_set):],
                              torch.Generator().manual_seed(12345), max_deleted=2, min_deleted=1)
    val.is_key[len(val_set):] = val_deleted
    fingerprint = _fingerprint(data)

    gen = torch.Generator().manual_seed(settings.seed)
    net = arnn.build(settings.arch, gen, **settings.sizes)
    opt = torch.optim.Adam(net.parameters(), lr=settings.lr, betas=(0.9, 0.999), eps=1e-8)
    schedule = Schedule(settings.epochs, settings.curriculum)
    start, rows, seconds, cpu = 0, [], 0.0, 0.0
    last_good = None

    if resume:
        if checkpoint is None or not Path(checkpoint).is_file():
            raise UsageError(f"--resume: no checkpoint at {checkpoint}")
        state = read_checkpoint(checkpoint)
        if state["settings"] != json.dumps(asdict(settings), sort_keys=True):
            raise UsageError(f"{checkpoint}: was made with other settings ({state['settings']}); "
                             f"give the same options to resume")
        if state["data"] != fingerprint:
            raise UsageError(f"{checkpoint}: was made with other training data")
        from keyfill.learn.modelfile import load_state

        load_state(net, state["net"], checkpoint)
        opt.load_state_dict(state["optim"])
        gen.set_state(state["generator"])
        start, seconds, cpu = int(state["epoch"]), float(state["seconds"]), float(state["cpu_seconds"])
        rows = _read_log(log, start) if log is not None else []
        last_good = (checkpoint, start)

    if log is not None:
        _write_log(log, rows)
    N = len(train_set)
    for epoch in range(start, settings.epochs):
        t0, c0 = time.perf_counter(), time.process_time()
        tf, omega = schedule.teacher_forcing(epoch), schedule.omega(epoch)
        for group in opt.param_groups:
            group["lr"] = settings.lr * schedule.lr_scale(epoch)
        net.train()
        sums = np.zeros(3)
        order = torch.randperm(N, generator=gen)
        for i in range(0, N, settings.batch_size):
            b = data.select(order[i: i + settings.batch_size])
            is_key = delete_keys(b.is_key, b.valid, gen, settings.max_deleted)
            teacher = bool(torch.rand((), generator=gen) < tf)
            pred = arnn.run(net, b.frames, is_key, teacher=teacher, generator=gen)
            key_sum, frame_mse, key_mse = loss_terms(pred, b.frames, is_key, b.valid)
            key_term = key_sum if settings.key_loss == "sum" else key_mse
            loss = KEY_WEIGHT * omega * key_term + frame_mse
            if not torch.isfinite(loss):
                raise _diverged(epoch, f"the loss is {loss.item()}", last_good)
            opt.zero_grad(set_to_none=True)
            loss.backward()
            if settings.clip > 0:
                torch.nn.utils.clip_grad_norm_(net.parameters(), settings.clip)
            opt.step()
            n = len(b)
            sums += n * np.array([loss.item(), key_mse.item(), frame_mse.item()])
        sums /= N
        held_out = validate(net, val, len(val_set))
        seconds += time.perf_counter() - t0
        cpu += time.process_time() - c0
        row = {
            "epoch": epoch + 1,
            "teacher_forcing": round(tf, 6),
            "omega": round(omega, 6),
            "lr": settings.lr * schedule.lr_scale(epoch),
            "train_objective": sums[0],
            "train_key": sums[1],
            "train_frame": sums[2],
            "train_total": sums[1] + sums[2],
            **{f"val_{k}": v for k, v in held_out.items()},
            "seconds": round(seconds, 3),
            "cpu_seconds": round(cpu, 3),
        }
        if not all(math.isfinite(v) for v in row.values()):
            raise _diverged(epoch, "the held-out loss is not finite", last_good)
        rows.append(row)
        if log is not None:
            _append_log(log, row)
        if on_epoch is not None:
            on_epoch(row)
        if checkpoint is not None and ((epoch + 1) % settings.checkpoint_every == 0 or epoch + 1 == settings.epochs):
            write_checkpoint(checkpoint, net, opt, gen, epoch + 1, (seconds, cpu), settings, fingerprint)
            last_good = (checkpoint, epoch + 1)

    final = rows[-1] if rows else {}
    training = {
        "settings": asdict(settings),
        "data": source,
        "train_sequences": len(train_set),
        "val_sequences": len(val_set),
        "epochs": settings.epochs,
        "seconds": round(seconds, 1),
        "cpu_seconds": round(cpu, 1),
        "threads": torch.get_num_threads(),
        "val": {k[4:]: v for k, v in final.items() if k.startswith("val_")},
    }
    from keyfill.learn.modelfile import save_model

    config = arnn.model_config(net, normalizer, settings.sizes, training)
    path = save_model(output, arnn.KIND, net.state_dict(), config)
    return Result(path, settings.epochs, seconds, cpu, training["val"], arnn.num_weights(net),
                  Path(log) if log is not None else None)


def _check_outputs(output, checkpoint, log) -> None:
    """Refuse outputs that could not be written, before training rather than after."""
    from keyfill.learn.modelfile import CONFIG

    for path in (output, checkpoint, log):
        if path is not None:
            parent = Path(path).parent
            if not parent.is_dir():
                raise UsageError(f"{path}: the folder {str(parent)!r} does not exist")
    if Path(output).exists() and not (Path(output) / CONFIG).is_file():
        raise UsageError(f"{output}: exists and is not a keyfill model; refusing to replace it")


def _diverged(epoch: int, what: str, last_good) -> TrainingDiverged:
    where = (f"the last good checkpoint, {last_good[0]} (epoch {last_good[1]}), is kept: resume from it with "
             f"--resume and a lower --lr" if last_good else "no checkpoint had been written yet; try a lower --lr")
    return TrainingDiverged(f"training diverged at epoch {epoch + 1}: {what}; {where}")


def validate(net: arnn.Completer, val: Batch, n_all: int) -> dict:
    """Table losses of ``net`` (free-running, no dropout) on the held-out batch.

    The batch holds the held-out sequences twice: first with all keys, then
    with 1-2 keys deleted. Returns ``key``, ``frame``, ``total`` for each half
    (``deleted_key`` ... for the second).
    """
    net.eval()
    with torch.no_grad():
        pred = arnn.run(net, val.frames, val.is_key)
    out = {}
    for prefix, sl in (("", slice(0, n_all)), ("deleted_", slice(n_all, None))):
        _, frame, key = loss_terms(pred[sl], val.frames[sl], val.is_key[sl], val.valid[sl])
        out[prefix + "key"] = float(key)
        out[prefix + "frame"] = float(frame)
        out[prefix + "total"] = float(key) + float(frame)
    return out


# --- checkpoints and the log -------------------------------------------------------------------------


def write_checkpoint(path, net, opt, gen, epoch: int, seconds: tuple[float, float], settings: Settings,
                     data: str) -> None:
    """Atomically write a checkpoint (tensors, numbers and strings only: read back with ``weights_only=True``)."""
    from keyfill.files import atomic_output

    state = {
        "format": "keyfill-arnn-checkpoint",
        "net": net.state_dict(),
        "optim": opt.state_dict(),
        "generator": gen.get_state(),
        "epoch": epoch,
        "seconds": seconds[0],
        "cpu_seconds": seconds[1],
        "settings": json.dumps(asdict(settings), sort_keys=True),
        "data": data,
    }
    with atomic_output(path) as tmp:
        torch.save(state, tmp)


def read_checkpoint(path) -> dict:
    """A checkpoint written by :func:`write_checkpoint`; never unpickles objects (``weights_only=True``)."""
    from keyfill.errors import ModelError

    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as e:  # torch raises many types for damaged or foreign files
        raise ModelError(f"{path}: not a readable keyfill checkpoint ({' '.join(str(e).split())[:200]})") from None
    if not isinstance(state, dict) or state.get("format") != "keyfill-arnn-checkpoint":
        raise ModelError(f"{path}: not a keyfill ARNN checkpoint")
    return state


def _read_log(path, upto_epoch: int) -> list[dict]:
    if not Path(path).is_file():
        return []
    rows = [json.loads(line) for line in Path(path).read_text().splitlines() if line.strip()]
    return [r for r in rows if r.get("epoch", 0) <= upto_epoch]


def _write_log(path, rows: list[dict]) -> None:
    from keyfill.files import atomic_output

    with atomic_output(path) as tmp:
        tmp.write_text("".join(json.dumps(r) + "\n" for r in rows))


def _append_log(path, row: dict) -> None:
    with open(path, "a") as f:
        f.write(json.dumps(row) + "\n")
