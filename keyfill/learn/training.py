"""The one training loop of every learned method, data-parallel with ``torch.distributed``.

A method supplies a :class:`TrainingTask`: its networks, optimisers, learning
rates, the batches of an epoch, one step, validation and how to write the
model folder. :func:`train` owns everything else, once for all methods:

* the output check before any work (:func:`check_outputs`);
* torch's global random state: the loop runs inside ``torch.random.fork_rng``
  with the global generator seeded by ``seed`` (the caller's state is left as
  it was), and hands the task a ``torch.Generator`` seeded by ``seed`` to build
  its networks from;
* each optimiser update (:class:`Updater`): zero the gradients, the
  divergence check, backward, gradient averaging across processes, gradient
  norm clipping, the optimiser step;
* the JSONL log (one row per epoch: the task's named losses weighted by batch
  rows, its validation scores, the learning rates, wall and CPU seconds),
  written from the first finished epoch on (an interrupt before it leaves no
  empty log);
* checkpoints tagged with the task's kind (networks, optimisers, the task's
  own random state, the log so far), written every ``checkpoint_every`` epochs
  and at the end, and ``resume`` from them, refused with one line naming the
  first difference when the kind, configuration or data differ (the files
  themselves: :mod:`keyfill.learn.checkpoints`);
* progress bars, progress lines where no bar is drawn (epoch, step, loss, time
  left; every :data:`LINE_EVERY_S` seconds) and a per-epoch report callback;
* data-parallel training: started by ``torchrun`` (``RANK`` / ``WORLD_SIZE``
  in the environment), each process builds the same networks, draws the same
  *global* batches and trains on its :meth:`TrainingTask.shard` of each;
  gradients are averaged with one ``all_reduce`` per update, weighted by the
  rows of each shard, so for a loss that is a mean over rows and a step that
  draws nothing random, N processes take the step one process would take on
  the whole batch (docs/learned_methods.md says which tasks differ). Rank 0 alone validates and writes the log, checkpoints
  and the model. gloo on CPU, nccl on CUDA.

Gradients are averaged explicitly rather than through
``DistributedDataParallel``'s wrapper because the tasks call their networks
in ways the wrapper does not see (the ARNN steps its recurrent cell frame by
frame outside ``forward``; a GAN alternates two networks and two optimisers in
one step); one coalesced ``all_reduce`` per update is what the wrapper would
do for these small models.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from keyfill.errors import KeyfillError, UsageError
from keyfill.learn.checkpoints import LossLog, check_resume, read_checkpoint, write_checkpoint
from keyfill.learn.library.guard import write_corpus_index
from keyfill.limits import check_seed
from keyfill.progress import Ticker

#: seconds between the progress lines of ``progress_lines`` (off a terminal: a line at least every 30 s)
LINE_EVERY_S = 20.0


class TrainingDiverged(KeyfillError):
    """A loss became NaN or infinite."""


class TrainingTask:
    """What a learned method gives the loop. Subclasses override the methods below.

    Attributes:
        kind: the model kind, written into checkpoints (and, by :meth:`save`, the model folder).
        epochs: passes over the training data.
        checkpoint_every: epochs between checkpoints (one is always written after the last epoch).
        clip: gradient norm clipping per optimiser (0: none).
    """

    kind: str = ""
    epochs: int = 1
    checkpoint_every: int = 1
    clip: float = 0.0

    def config(self) -> dict:
        """JSON-ready settings that a ``resume`` must match exactly (leave out what may change, e.g. epochs)."""
        return {}

    def fingerprint(self) -> str:
        """A short hash of the training data ("" when not checked on resume)."""
        return ""

    def build(self, generator) -> dict[str, Any]:
        """The networks by name (``torch.nn.Module``), built from ``generator`` (seeded by the loop)."""
        raise NotImplementedError

    def optimizers(self, nets: dict) -> dict[str, Any]:
        """The optimisers by name (``torch.optim.Optimizer``), e.g. ``{"net": Adam(...)}``."""
        raise NotImplementedError

    def learning_rates(self, epoch: int, step: int, steps: int) -> dict[str, float] | None:
        """The rate of each optimiser for ``step`` of ``steps`` in 0-based ``epoch`` (None: leave them)."""
        return None

    def begin(self, rank: int, world: int, device: str) -> None:
        """Called once before :meth:`build` with this process's rank, the process count and its torch device."""

    def steps(self, epoch: int) -> int | None:
        """Steps in ``epoch``, for the progress bar (None: unknown)."""
        return None

    def batches(self, epoch: int) -> Iterable:
        """The *global* batches of 0-based ``epoch``; every per-batch random draw happens here, so that
        all processes see the same batches."""
        raise NotImplementedError

    def shard(self, batch, rank: int, world: int):
        """This process's part of a global batch (``world > 1`` only)."""
        raise NotImplementedError

    def step(self, batch, update: Updater) -> tuple[dict[str, float], int]:
        """Train on one batch: call ``update(name, loss)`` once per optimiser, in the order needed.

        Returns the named losses to log (plain floats) and the step's weight in the epoch's mean
        (its rows, or 1 when every step has as many).
        """
        raise NotImplementedError

    def validate(self, epoch: int) -> dict[str, float]:
        """Held-out scores after 0-based ``epoch`` (run on rank 0 only; networks in eval mode)."""
        return {}

    def log_row(self, epoch: int, losses: dict[str, float], validation: dict[str, float]) -> dict:
        """The log row of an epoch, without ``epoch``, learning rates and seconds (added by the loop)."""
        return {**{f"loss_{k}": v for k, v in losses.items()}, **validation}

    def state_dict(self) -> dict:
        """The task's own state for a checkpoint (e.g. a random generator's state): tensors, numbers, strings."""
        return {}

    def load_state_dict(self, state: dict) -> None:
        """Restore :meth:`state_dict`."""

    def save(self, output: Path, nets: dict, history: list[dict]) -> Any:
        """Write the model folder ``output`` after the last epoch; the return value is passed on."""
        raise NotImplementedError


@dataclass(frozen=True)
class Option:
    """One method-specific option of ``keyfill train METHOD``: plain data that the CLI turns into a click option.

    Attributes:
        name: the Python name; the option is ``--name`` with ``_`` as ``-``.
        default: the default value (None: not given).
        help: the help text.
        type: ``int``, ``float``, ``str`` or ``"file"`` (an existing file); ignored with ``choices`` or ``flag``.
        choices: the allowed values.
        flag: a boolean ``--name/--no-name`` (with ``default`` True or False) or, with ``default`` None,
            a tri-state whose absence means "decide from the data".
        multiple: repeatable; the value is a tuple.
        metavar: the value's name in the help.
    """

    name: str
    default: Any = None
    help: str = ""
    type: Any = str
    choices: tuple[str, ...] | None = None
    flag: bool = False
    multiple: bool = False
    metavar: str | None = None


@dataclass(frozen=True)
class Common:
    """The options every ``keyfill train METHOD`` has, as given (None: the method's default)."""

    data: tuple[str, ...]
    output: str
    seed: int = 0
    epochs: int | None = None
    checkpoint_every: int | None = None
    device: str = "cpu"

    def __post_init__(self):
        check_seed(self.seed)  # before the data is read


@dataclass(frozen=True)
class TrainingSpec:
    """How ``keyfill train METHOD`` trains a method (a learned method's training module defines ``TRAINING``).

    Attributes:
        help: the command's help text (what DATA is, what training does, examples).
        options: the method's own options (:class:`Option`).
        make_task: ``make_task(common, options, progress) -> TrainingTask``; reads the data and checks the options.
        started: ``started(task) -> str``: one line saying what is about to be trained.
        finished: ``finished(task, outcome) -> (summary dict, line)``: the ``--json`` summary and one line.
        threads: default torch CPU threads (None: torch's default); results are reproducible per thread count.
        epoch_line: ``epoch_line(row) -> str`` printed after each epoch, or None.
    """

    help: str
    options: tuple[Option, ...]
    make_task: Callable
    started: Callable
    finished: Callable
    threads: int | None = None
    epoch_line: Callable | None = None


@dataclass
class Context:
    """Where this process stands in a (possibly distributed) run."""

    rank: int = 0
    world: int = 1
    device: str = "cpu"
    started_group: bool = False

    @property
    def main(self) -> bool:
        return self.rank == 0


def distributed_context(device: str = "cpu") -> Context:
    """The process's rank and count from ``torchrun``'s environment; joins the process group when ``WORLD_SIZE > 1``.

    The backend is nccl for CUDA devices and gloo otherwise. Each CUDA process uses
    the device of its ``LOCAL_RANK``.
    """
    world = int(os.environ.get("WORLD_SIZE", "1"))
    if world <= 1:
        return Context(device=device)
    import torch.distributed as dist

    rank = int(os.environ.get("RANK", "0"))
    if device.startswith("cuda"):
        device = f"cuda:{int(os.environ.get('LOCAL_RANK', '0'))}"
    started = False
    if not dist.is_initialized():
        dist.init_process_group(backend="nccl" if device.startswith("cuda") else "gloo")
        started = True
    return Context(rank=rank, world=world, device=device, started_group=started)


def _diverged(epoch: int, what: str, last_good) -> TrainingDiverged:
    where = (f"the last good checkpoint, {last_good[0]} (epoch {last_good[1]}), is kept: resume continues from it, "
             f"with a lower lr" if last_good else "no checkpoint had been written yet; try a lower lr")
    return TrainingDiverged(f"training diverged at epoch {epoch + 1}: {what}; {where}", params=("resume", "lr"))


class Updater:
    """One optimiser update, as a task's :meth:`~TrainingTask.step` asks for it: ``update(name, loss)``."""

    def __init__(self, optimizers: dict, clip: float, ctx: Context):
        self.optimizers = optimizers
        self.clip = clip
        self.ctx = ctx
        self.weight = 1.0  # this process's rows / all rows of the global batch (data-parallel only)
        self.epoch = 0
        self.last_good = None

    def __call__(self, name: str, loss) -> None:
        import torch

        opt = self.optimizers[name]
        finite = bool(torch.isfinite(loss.detach()).all())
        if self.ctx.world > 1:
            import torch.distributed as dist

            flag = torch.tensor([1.0 if finite else 0.0], device=loss.device)
            dist.all_reduce(flag, op=dist.ReduceOp.MIN)
            finite = bool(flag.item() == 1.0)
        if not finite:
            own = loss.detach().reshape(-1)[0].item()
            what = f"the loss is {own}" if not math.isfinite(own) else "the loss is not finite in another process"
            raise _diverged(self.epoch, what, self.last_good)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        params = [p for g in opt.param_groups for p in g["params"]]
        if self.ctx.world > 1:
            self._average(params)
        if self.clip > 0:
            torch.nn.utils.clip_grad_norm_(params, self.clip)
        opt.step()

    def _average(self, params) -> None:
        """Sum each process's gradient times its share of the rows: the gradient of the whole batch's mean loss."""
        import torch
        import torch.distributed as dist
        from torch._utils import _flatten_dense_tensors, _unflatten_dense_tensors

        grads = [p.grad if p.grad is not None else torch.zeros_like(p) for p in params]
        flat = _flatten_dense_tensors(grads) * self.weight
        dist.all_reduce(flat)
        for p, g in zip(params, _unflatten_dense_tensors(flat, grads)):
            p.grad = g


@dataclass
class Outcome:
    """What :func:`train` did: the task's :meth:`~TrainingTask.save` result (rank 0; None elsewhere) and the run."""

    model: Any
    output: Path
    epochs: int
    seconds: float
    cpu_seconds: float
    history: list[dict] = field(default_factory=list)
    checkpoint: Path | None = None
    log: Path | None = None
    world: int = 1


def side_files(output: str | os.PathLike) -> tuple[Path, Path]:
    """The default ``(checkpoint, log)`` beside the model folder ``output``: ``OUTPUT.checkpoint.pt``, ``OUTPUT.log.jsonl``."""
    output = Path(str(output).rstrip("/") or str(output))
    return output.with_name(output.name + ".checkpoint.pt"), output.with_name(output.name + ".log.jsonl")


def check_outputs(output, checkpoint=None, log=None) -> None:
    """Refuse outputs that could not be written, before training rather than after."""
    from keyfill.learn.modelfile import CONFIG

    for path in (output, checkpoint, log):
        if path is not None:
            parent = Path(path).parent
            if not parent.is_dir():
                raise UsageError(f"{path}: the output folder {str(parent)!r} does not exist")
    if Path(output).exists() and not (Path(output) / CONFIG).is_file():
        raise UsageError(f"{output}: exists and is not a keyfill model; refusing to replace it")
    for path in (checkpoint, log):
        if path is not None and Path(path).is_dir():
            raise UsageError(f"{path}: is a folder, not a file")


def train(
    task: TrainingTask,
    output: str | os.PathLike,
    *,
    seed: int = 0,
    checkpoint: str | os.PathLike | None = None,
    log: str | os.PathLike | None = None,
    resume: bool = False,
    device: str = "cpu",
    progress: Callable | None = None,
    on_epoch: Callable[[dict], None] | None = None,
    progress_lines: Callable[[str], None] | None = None,
) -> Outcome:
    """Train ``task`` and write its model folder ``output``.

    Args:
        task: the method's :class:`TrainingTask`.
        output: model folder to write (an existing model there is replaced; anything else is refused).
        seed: seeds the generator the networks are built from and torch's global generator (inside ``fork_rng``).
        checkpoint, log: checkpoint file and JSONL log (None: not written; :func:`side_files` gives the defaults).
        resume: continue from ``checkpoint``; refused when the kind, configuration, seed or data differ.
        device: torch device (``"cpu"``, ``"cuda"``); under ``torchrun`` each CUDA process takes its local rank's.
        progress: ``progress(total=..., desc=..., unit=...)`` -> a tqdm-like bar, or None.
        on_epoch: called with each log row (rank 0).
        progress_lines: called every :data:`LINE_EVERY_S` seconds with one line (rank 0): the epoch, the step,
            the epoch's running loss, the time so far and about how long is left (:class:`keyfill.progress.Ticker`);
            for where no bar is drawn (the CLI passes it when stderr is not a terminal).

    Raises :class:`TrainingDiverged` (keeping the last good checkpoint) when a loss is not finite.
    """
    import torch

    from keyfill.learn.modelfile import torch_device

    check_seed(seed)
    torch_device(device)  # a device keyfill can train on here (not meta, xla, a missing GPU), before any work
    ctx = distributed_context(device)
    try:
        check_outputs(output, checkpoint, log)
        if resume and (checkpoint is None or not Path(checkpoint).is_file()):
            raise UsageError(f"resume: no checkpoint {checkpoint}", params="resume")
        ticker = Ticker(progress_lines, LINE_EVERY_S) if progress_lines is not None and ctx.main else None
        with torch.random.fork_rng(devices=[]), ticker or contextlib.nullcontext():
            torch.manual_seed(seed)
            return _run(task, Path(output), seed, checkpoint, log, resume, ctx, progress, on_epoch, ticker)
    finally:
        if ctx.started_group:
            import torch.distributed as dist

            dist.destroy_process_group()


def _run(task, output, seed, checkpoint, log, resume, ctx: Context, progress, on_epoch, ticker) -> Outcome:
    import torch

    task.begin(ctx.rank, ctx.world, ctx.device)
    nets = task.build(torch.Generator().manual_seed(seed))
    for net in nets.values():
        net.to(ctx.device)
    optimizers = task.optimizers(nets)
    config = {"seed": seed, **task.config()}
    fingerprint = task.fingerprint()
    start, history, seconds, cpu = 0, [], 0.0, 0.0
    last_good = None
    if resume:
        state = read_checkpoint(checkpoint, task.kind)
        check_resume(checkpoint, state, config, fingerprint)
        for name, net in nets.items():
            from keyfill.learn.modelfile import load_state

            load_state(net, state["networks"][name], checkpoint)
        for name, opt in optimizers.items():
            opt.load_state_dict(state["optimizers"][name])
        task.load_state_dict(state["task"])
        start, seconds, cpu = int(state["epoch"]), float(state["seconds"]), float(state["cpu_seconds"])
        history = json.loads(state["history"])
        last_good = (checkpoint, start)
    if ctx.world > 1:
        _broadcast_parameters(nets)
    loss_log = LossLog(log) if ctx.main and log is not None else None
    update = Updater(optimizers, task.clip, ctx)
    update.last_good = last_good
    bar = progress(total=task.epochs, initial=start, desc="training", unit="epoch") if progress and ctx.main else None
    tell = _Teller(ticker, task.epochs, start)
    try:
        for epoch in range(start, task.epochs):
            t0, c0 = time.perf_counter(), time.process_time()
            update.epoch = epoch
            for net in nets.values():
                net.train()
            losses, lrs = _epoch(task, epoch, update, ctx, progress, tell)
            for net in nets.values():
                net.eval()
            tell(epoch, 1.0, "validating")
            validation = task.validate(epoch) if ctx.main else {}
            seconds += time.perf_counter() - t0
            cpu += time.process_time() - c0
            row = {"epoch": epoch + 1, **_lr_fields(lrs), **task.log_row(epoch, losses, validation),
                   "seconds": round(seconds, 3), "cpu_seconds": round(cpu, 3)}
            finite = all(not isinstance(v, float) or math.isfinite(v) for v in row.values())
            if not _all_agree(finite, ctx):
                raise _diverged(epoch, "the held-out loss is not finite", last_good)
            history.append(row)
            if ctx.main:
                if loss_log is not None:
                    loss_log.record(history)
                if bar is not None:
                    bar.set_postfix({k: f"{v:.4f}" for k, v in list(losses.items())[:3]}, refresh=False)
                    bar.update(1)
                if on_epoch is not None:
                    on_epoch(row)
            if checkpoint is not None and ((epoch + 1) % task.checkpoint_every == 0 or epoch + 1 == task.epochs):
                if ctx.main:
                    write_checkpoint(checkpoint, task, nets, optimizers, epoch + 1, seconds, cpu, config,
                                     fingerprint, history)
                last_good = update.last_good = (checkpoint, epoch + 1)
    finally:
        if bar is not None:
            bar.close()
    tell(task.epochs - 1, 1.0, "writing the model")
    model = task.save(output, nets, history) if ctx.main else None
    if ctx.main:  # beside the weights, the corpus's poses for the guard (docs/match.md)
        write_corpus_index(getattr(task, "corpus", None), output)
    return Outcome(model, output, task.epochs, seconds, cpu, history, Path(checkpoint) if checkpoint else None,
                   Path(log) if log else None, ctx.world)


def _epoch(task, epoch: int, update: Updater, ctx: Context, progress, tell: _Teller) \
        -> tuple[dict[str, float], dict[str, float]]:
    """Train one epoch: the row-weighted mean of each named loss over all processes, and the last learning rates."""
    steps = task.steps(epoch)
    tell(epoch, 0.0, "starting")
    bar = progress(total=steps, desc=f"epoch {epoch + 1}/{task.epochs}", unit="step", leave=False) \
        if progress and ctx.main and steps and steps > 1 else None
    sums: dict[str, float] = {}
    rows = 0
    lrs: dict[str, float] = {}
    try:
        for i, batch in enumerate(task.batches(epoch)):
            rates = task.learning_rates(epoch, i, steps or 1)
            if rates:
                for name, lr in rates.items():
                    for group in update.optimizers[name].param_groups:
                        group["lr"] = lr
                lrs = rates
            if ctx.world > 1:
                batch, weight = _shard(task, batch, ctx)
                update.weight = weight
            out, n = task.step(batch, update)
            for k, v in out.items():
                sums[k] = sums.get(k, 0.0) + n * v
            rows += n
            tell(epoch, (i + 1) / steps if steps else 0.0, f"step {i + 1}" + (f"/{steps}" if steps else ""),
                 {k: v / max(rows, 1) for k, v in sums.items()})
            if bar is not None:
                bar.update(1)
                first = next(iter(out), None)
                if first is not None:
                    bar.set_postfix({first: f"{sums[first] / max(rows, 1):.4f}"}, refresh=False)
    finally:
        if bar is not None:
            bar.close()
    if ctx.world > 1:
        sums, rows = _sum_over_processes(sums, rows)
    if not lrs:
        lrs = {name: opt.param_groups[0]["lr"] for name, opt in update.optimizers.items()}
    return {k: v / max(rows, 1) for k, v in sums.items()}, lrs


class _Teller:
    """Tells the loop's state to a :class:`~keyfill.progress.Ticker` (nothing without one): the epoch, the step,
    the epoch's running loss, and the fraction of this run's epochs done."""

    def __init__(self, ticker: Ticker | None, epochs: int, start: int):
        self.ticker, self.epochs, self.start = ticker, epochs, start
        self.loss = ""

    def __call__(self, epoch: int, part: float, doing: str, losses: dict[str, float] | None = None) -> None:
        """``part`` of 0-based ``epoch`` is done; ``doing`` says what now (``"step 3/40"``, ``"validating"``)."""
        if self.ticker is None:
            return
        if losses:
            name = "total" if "total" in losses else next(iter(losses))
            self.loss = f", loss {'' if name == 'total' else name + ' '}{losses[name]:.4g}"
        done = (epoch - self.start + part) / max(self.epochs - self.start, 1)
        self.ticker.set(done, f"training: epoch {epoch + 1}/{self.epochs}, {doing}{self.loss}")


def _shard(task, batch, ctx: Context):
    """This process's shard and its share of the global batch's rows."""
    import torch
    import torch.distributed as dist

    part = task.shard(batch, ctx.rank, ctx.world)
    n = torch.tensor([float(len(part))])
    total = n.clone()
    dist.all_reduce(total)
    if float(n) == 0:
        raise UsageError(f"a batch of {int(total.item())} rows cannot be shared by {ctx.world} processes; "
                         f"use a batch size of at least the process count")
    return part, float(n) / float(total)


def _sum_over_processes(sums: dict[str, float], rows: int) -> tuple[dict[str, float], int]:
    import torch
    import torch.distributed as dist

    names = sorted(sums)
    t = torch.tensor([sums[k] for k in names] + [float(rows)], dtype=torch.float64)
    dist.all_reduce(t)
    return dict(zip(names, t[:-1].tolist())), int(t[-1].item())


def _all_agree(flag: bool, ctx: Context) -> bool:
    """``flag`` of rank 0 (the one that validated), known to every process."""
    if ctx.world == 1:
        return flag
    import torch
    import torch.distributed as dist

    t = torch.tensor([1.0 if flag else 0.0])
    dist.broadcast(t, src=0)
    return bool(t.item() == 1.0)


def _broadcast_parameters(nets: dict) -> None:
    """Make every process start from rank 0's weights (they are equal by construction; this guarantees it)."""
    import torch.distributed as dist

    for net in nets.values():
        for t in list(net.parameters()) + list(net.buffers()):
            dist.broadcast(t.data, src=0)


def _lr_fields(lrs: dict[str, float]) -> dict[str, float]:
    if len(lrs) == 1:
        return {"lr": next(iter(lrs.values()))}
    return {f"lr_{k}": v for k, v in lrs.items()}
