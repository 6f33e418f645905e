"""Training the lamp networks: the loss of Eq. 4, the curriculum of section 7.2, Adam as in 7.3.

Loss (Eq. 4), on standardised variables::

    L = key_weight * omega * KEY + MSE over the predicted frames 1 .. T-1

where ``KEY`` is the squared error at the keys ``K >= 1`` given to the
network. The paper's ``key_weight`` is 100; keyfill's default is 10: with 100
the held-out frame loss rose by a quarter while omega ramped up (0.19 -> 0.24
on the validation split), buying key errors of 0.003 instead of 0.006 that
exact keys remove at inference anyway (docs/arnn.md has the tables). The
paper writes ``KEY`` as a sum over the keys; ``key_loss="sum"`` does
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
import math
import os
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import torch

from keyfill.errors import DataError, UsageError
from keyfill.learn.arnn import network
from keyfill.learn.arnn.features import Batch, delete_keys, make_batch
from keyfill.learn.arnn.model import KIND, model_config
from keyfill.learn.lamp_data import LampSequence, Normalizer, read_sequences, split
from keyfill.learn.training import Option, TrainingSpec, TrainingTask, check_outputs
from keyfill.learn.training import train as run_training
from keyfill.limits import max_frames

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
    key_weight: float = 10.0
    clip: float = 1.0
    seed: int = 0
    checkpoint_every: int = 50
    sizes: dict = field(default_factory=dict)

    def check(self) -> Settings:
        """``self``, or a :class:`UsageError` naming the setting (its field, in ``params``) that cannot work."""
        if self.arch not in network.ARCHITECTURES:
            raise UsageError(f"unknown architecture {self.arch!r}; choose one of {', '.join(network.ARCHITECTURES)}")
        for name in ("epochs", "batch_size", "checkpoint_every"):
            if getattr(self, name) < 1:
                raise UsageError(f"{name} must be at least 1, got {getattr(self, name)}", params=name)
        if not self.lr > 0 or not math.isfinite(self.lr):
            raise UsageError(f"lr must be a positive number, got {self.lr}", params="lr")
        if not self.key_weight >= 0 or not math.isfinite(self.key_weight):
            raise UsageError(f"key_weight must be 0 or more, got {self.key_weight}", params="key_weight")
        if self.key_loss not in ("mean", "sum"):
            raise UsageError(f"key_loss must be mean or sum, not {self.key_loss!r}", params="key_loss")
        if not 0 <= self.max_deleted <= max_frames():  # a sequence has fewer keys than frames
            raise UsageError(f"max_deleted must be 0 to {max_frames():,}, got {self.max_deleted}", params="max_deleted")
        if not (self.clip >= 0 and math.isfinite(self.clip)):
            raise UsageError(f"clip must be 0 (no clipping) or a positive number, got {self.clip}", params="clip")
        return self


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


def _fingerprint(batch: Batch) -> str:
    h = hashlib.sha256()
    for t in (batch.frames, batch.is_key, batch.lengths):
        h.update(t.numpy().tobytes())
    return h.hexdigest()[:16]


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


class ArnnTask(TrainingTask):
    """The lamp networks as a task of the one training loop (:mod:`keyfill.learn.training`).

    Every random draw (the initial weights, batch order, key deletion, teacher
    forcing, dropout) comes from the generator the loop builds the network
    from, in that order, so one process gives the same bytes as before the
    loop existed. With N processes, dropout draws from a per-process generator
    seeded by ``(seed, rank, epoch)`` instead, so the shared batch draws stay
    in step across processes.
    """

    kind = KIND

    def __init__(self, train_set: list[LampSequence], val_set: list[LampSequence], settings: Settings,
                 source: str = ""):
        settings.check()
        if not train_set:
            raise DataError("no training sequences")
        if not val_set:
            raise DataError("no held-out sequences to watch training with")
        self.settings = settings
        self.epochs = settings.epochs
        self.checkpoint_every = settings.checkpoint_every
        self.clip = settings.clip
        self.source = source
        self.n_train, self.n_val = len(train_set), len(val_set)
        self.normalizer = Normalizer.fit(train_set)
        self.data = make_batch(train_set, self.normalizer)
        self.val = make_batch(val_set + val_set, self.normalizer)
        self.val.is_key[len(val_set):] = delete_keys(self.val.is_key[len(val_set):], self.val.valid[len(val_set):],
                                                     torch.Generator().manual_seed(12345), max_deleted=2,
                                                     min_deleted=1)
        self.schedule = Schedule(settings.epochs, settings.curriculum)
        self.rank, self.world = 0, 1

    def config(self) -> dict:
        return asdict(self.settings)

    def fingerprint(self) -> str:
        return _fingerprint(self.data)

    def begin(self, rank: int, world: int, device: str) -> None:
        if device != "cpu":
            raise UsageError("the lamp networks train on the CPU (device cpu)", params="device")
        self.rank, self.world = rank, world

    def build(self, generator):
        self.gen = generator
        self.net = network.build(self.settings.arch, generator, **self.settings.sizes)
        return {"net": self.net}

    def optimizers(self, nets):
        return {"net": torch.optim.Adam(nets["net"].parameters(), lr=self.settings.lr, betas=(0.9, 0.999), eps=1e-8)}

    def learning_rates(self, epoch, step, steps):
        return {"net": self.settings.lr * self.schedule.lr_scale(epoch)}

    def steps(self, epoch):
        return math.ceil(self.n_train / self.settings.batch_size)

    def batches(self, epoch):
        """``(batch, keys after deletion, teacher-forced?)`` of each step, in the order of the paper's curriculum."""
        tf = self.schedule.teacher_forcing(epoch)
        self.dropout = self.gen if self.world == 1 else \
            torch.Generator().manual_seed(int(np.random.SeedSequence([self.settings.seed, self.rank, epoch]).generate_state(1)[0]))
        order = torch.randperm(self.n_train, generator=self.gen)
        for i in range(0, self.n_train, self.settings.batch_size):
            b = self.data.select(order[i: i + self.settings.batch_size])
            is_key = delete_keys(b.is_key, b.valid, self.gen, self.settings.max_deleted)
            yield b, is_key, bool(torch.rand((), generator=self.gen) < tf)

    def shard(self, batch, rank, world):
        b, is_key, teacher = batch
        rows = torch.arange(rank, len(b), world)
        return _Shard(b.select(rows), is_key[rows], teacher)

    def step(self, batch, update):
        b, is_key, teacher = batch
        omega = self.schedule.omega(update.epoch)
        pred = network.run(self.net, b.frames, is_key, teacher=teacher, generator=self.dropout)
        key_sum, frame_mse, key_mse = loss_terms(pred, b.frames, is_key, b.valid)
        key_term = key_sum if self.settings.key_loss == "sum" else key_mse
        loss = self.settings.key_weight * omega * key_term + frame_mse
        update("net", loss)
        return {"objective": loss.item(), "key": key_mse.item(), "frame": frame_mse.item()}, len(b)

    def validate(self, epoch):
        return validate(self.net, self.val, self.n_val)

    def log_row(self, epoch, losses, validation):
        return {
            "teacher_forcing": round(self.schedule.teacher_forcing(epoch), 6),
            "omega": round(self.schedule.omega(epoch), 6),
            **{f"train_{k}": v for k, v in losses.items()},
            "train_total": losses["key"] + losses["frame"],
            **{f"val_{k}": v for k, v in validation.items()},
        }

    def state_dict(self):
        return {"generator": self.gen.get_state()}

    def load_state_dict(self, state):
        self.gen.set_state(state["generator"])

    def save(self, output, nets, history):
        from keyfill.learn.modelfile import save_model

        final = history[-1] if history else {}
        seconds = final.get("seconds", 0.0)
        cpu = final.get("cpu_seconds", 0.0)
        training = {
            "settings": asdict(self.settings),
            "data": self.source,
            "train_sequences": self.n_train,
            "val_sequences": self.n_val,
            "epochs": self.settings.epochs,
            "seconds": round(seconds, 1),
            "cpu_seconds": round(cpu, 1),
            "threads": torch.get_num_threads(),
            "val": {k[4:]: v for k, v in final.items() if k.startswith("val_")},
        }
        config = model_config(self.net, self.normalizer, self.settings.sizes, training)
        path = save_model(output, KIND, self.net.state_dict(), config)
        return Result(path, self.settings.epochs, seconds, cpu, training["val"], network.num_weights(self.net), None)


class _Shard(tuple):
    """A process's rows of a batch: ``(batch, keys, teacher-forced?)``; its length is its rows."""

    def __new__(cls, b, is_key, teacher):
        return super().__new__(cls, (b, is_key, teacher))

    def __len__(self) -> int:
        return len(self[0])


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
    progress: Callable | None = None,
) -> Result:
    """Train a network on ``train_set`` and write the model folder ``output`` (through :func:`keyfill.learn.training.train`).

    Args:
        train_set, val_set: sequences with every frame and their keys (``val_set`` is only watched).
        settings: see :class:`Settings`.
        checkpoint: checkpoint file, written every ``settings.checkpoint_every`` epochs
            (and read with ``resume``).
        log: JSONL file, one row of losses per epoch.
        on_epoch: called with each log row (e.g. to update a progress bar).
        source: a note on where the data came from, kept in the model config.

    Raises :class:`~keyfill.learn.training.TrainingDiverged` (keeping the last good checkpoint) when a loss is
    not finite.
    """
    settings.check()
    check_outputs(output, checkpoint, log)
    task = ArnnTask(train_set, val_set, settings, source)
    outcome = run_training(task, output, seed=settings.seed, checkpoint=checkpoint, log=log, resume=resume,
                           progress=progress, on_epoch=on_epoch)
    result = outcome.model
    if result is not None:
        result.log = outcome.log
    return result


def validate(net: network.Completer, val: Batch, n_all: int) -> dict:
    """Table losses of ``net`` (free-running, no dropout) on the held-out batch.

    The batch holds the held-out sequences twice: first with all keys, then
    with 1-2 keys deleted. Returns ``key``, ``frame``, ``total`` for each half
    (``deleted_key`` ... for the second).
    """
    net.eval()
    with torch.no_grad():
        pred = network.run(net, val.frames, val.is_key)
    out = {}
    for prefix, sl in (("", slice(0, n_all)), ("deleted_", slice(n_all, None))):
        _, frame, key = loss_terms(pred[sl], val.frames[sl], val.is_key[sl], val.valid[sl])
        out[prefix + "key"] = float(key)
        out[prefix + "frame"] = float(frame)
        out[prefix + "total"] = float(key) + float(frame)
    return out


# --- keyfill train arnn --------------------------------------------------------------------------------


def _make_task(common, options: dict, progress) -> ArnnTask:
    """The task of ``keyfill train arnn``: DATA is one ``keyfill simulate`` folder, split by :func:`split`."""
    from dataclasses import replace


    if len(common.data) != 1:
        raise UsageError("keyfill train arnn takes one dataset folder made by 'keyfill simulate'")
    given = {"epochs": common.epochs, "checkpoint_every": common.checkpoint_every}
    settings = replace(Settings(), seed=common.seed, **options, **{k: v for k, v in given.items() if v is not None})
    settings.check()
    parts = split(read_sequences(common.data[0]))
    task = ArnnTask(parts["train"], parts["val"], settings, source=str(common.data[0]))
    task.n_test = len(parts["test"])
    return task


def _started(task: ArnnTask) -> str:
    return (f"training {task.settings.arch} on {task.n_train} sequences of {task.source} ({task.n_val} held out, "
            f"{task.n_test} left for testing), {task.epochs} epochs")


def _finished(task: ArnnTask, outcome) -> tuple[dict, str]:
    r = outcome.model
    summary = {"model": str(r.path), "arch": task.settings.arch, "epochs": r.epochs, "seconds": round(r.seconds, 1),
               "cpu_seconds": round(r.cpu_seconds, 1), "weights": r.weights, "held_out": r.val,
               "log": str(outcome.log), "checkpoint": str(outcome.checkpoint)}
    v = r.val
    line = (f"wrote {r.path}: {task.settings.arch}, {r.weights} weights, {r.epochs} epochs in {r.seconds / 60:.1f} min "
            f"({r.cpu_seconds / 60:.1f} min of CPU); held-out total loss {v['total']:.5f} (all keys), "
            f"{v['deleted_total']:.5f} (1-2 keys deleted); log {outcome.log}")
    return summary, line


TRAINING = TrainingSpec(
    help="""Train a lamp in-betweening network on the dataset folder DATA.

    DATA is a folder made by 'keyfill simulate'. Its sequences are split by
    position: the last 20 % are the test split (for 'keyfill evaluate'), the
    10 % before them are held out and scored every epoch in the log, the rest
    is trained on. Training follows Zhang & van de Panne 2018: the loss
    10 w (key error) + frame MSE (--key-weight; the paper's is 100), scheduled sampling and a sigmoid key
    weight w (--no-curriculum: none), 0-2 keys deleted at random each time a
    sequence is used, Adam. Defaults: 400 epochs, a checkpoint every 50. The
    same data, options, --seed and --threads give the same model bytes, also
    across --resume.

    \b
    Examples:
      keyfill train arnn data/hops -o models/lamp-arnn
      keyfill train arnn data/hops -o models/nomem --arch no-memory --epochs 300
      keyfill train arnn data/hops -o models/lamp-arnn --resume
    """,
    options=(
        Option("arch", Settings.arch, "Network: the ARNN, or section 9's no-memory or segregated comparison networks.",
               choices=network.ARCHITECTURES),
        Option("batch_size", Settings.batch_size, "Sequences per gradient step.", type=int),
        Option("lr", Settings.lr, "Adam learning rate.", type=float),
        Option("curriculum", Settings.curriculum, "Scheduled sampling then a rising key weight (section 7.2); "
               "without: free-running, weight 1.", flag=True),
        Option("max_deleted", Settings.max_deleted, "Delete 0 to this many interior keys of a sequence each time "
               "it is used.", type=int),
        Option("key_loss", Settings.key_loss, "Key term of the loss: mean squared key error, or the paper's literal "
               "sum over keys.", choices=("mean", "sum")),
        Option("key_weight", Settings.key_weight, "Weight of the key term once the curriculum's omega is 1 "
               "(the paper's is 100).", type=float),
        Option("clip", Settings.clip, "Clip the gradient norm to this (0: no clipping).", type=float),
    ),
    make_task=_make_task,
    started=_started,
    finished=_finished,
    threads=1,
)

