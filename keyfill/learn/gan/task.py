"""Training the generative tweening model: one task, two stages, for keyfill's training loop.

Section 3.7: the global path predictor is trained first on real clips; then it
is frozen and the local motion generator is trained against the discriminator.

* ``stage="path"``: networks ``{"path"}``; each step draws ``path_batch`` whole
  clips (:func:`keyfill.learn.gan.sampling.clip_batch`) and minimises Eq. 5.
  :meth:`GanTask.save` writes a ``"gan"`` model folder of stage ``"path"``.
* ``stage="generator"``: networks ``{"generator", "discriminator"}``; the path
  predictor comes frozen from ``path_model`` (a model folder of either stage), or with a
  base (``GanConfig.base``, the third recipe) there is none: the generator corrects the keys'
  interpolation and the root path is that interpolation of the key roots, so Eq. 10 is 0.
  Each step draws ``batch_size`` key layouts of ``sequence_frames`` frames
  (:func:`~keyfill.learn.gan.sampling.sample_keys`), the noise, and real crops,
  then updates the discriminator once and the generator once (section 3.7):

  - discriminator: Eq. 7 on real crops and crops of the generated sequences
    (keys pasted in, generator detached), plus ``br_weight`` times Eq. 9 over
    its residual layers;
  - generator: ``adv_weight`` * Eq. 8 + ``br_weight`` * Eq. 9 over its residual
    layers + ``joint_weight`` * the key joint loss + the root weight (growing
    with the step, Appendix A) * Eq. 10 on the path the frozen predictor gives,
    + ``dna_weight`` * (Eq. 11 + Eq. 12) with a Motion DNA encoder (each sequence
    draws its representative poses from the training clips' bank, Appendix D).
    With ``partial_keys`` the key losses cover the coordinates the keys give.

  :meth:`GanTask.save` writes a ``"gan"`` model folder of stage ``"full"``.

Both stages use RMSprop with PyTorch's defaults (section 3.7) at the config's
learning rates, kept constant, or with the second recipe's settings Adam with a
warm-up and cosine decay (``optimizer``, ``lr_schedule``); in-clip windows, the
reconstruction and foot-sliding terms and the moving average of the generator
are the second recipe's too (``keyfill.learn.gan.config``). All randomness of a batch is drawn in
:meth:`GanTask.batches` from ``numpy.random.default_rng([seed, stage, epoch])``
(keys, clips, headings, noise, crop starts), so a resumed run draws what an
uninterrupted one would; the task's own state is the generator step count that
drives the root weight schedule.

The contract is that of ``keyfill.learn.training.TrainingTask`` (kind, config,
fingerprint, build, optimizers, learning_rates, batches, shard, step, validate,
state_dict / load_state_dict, save).
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from keyfill.errors import DataError, UsageError
from keyfill.learn.gan import KIND
from keyfill.learn.gan.config import GanConfig
from keyfill.learn.gan.dna import build_bank, pad_dna
from keyfill.learn.gan.matched_set import load_rows
from keyfill.learn.gan.poses import clip_pool
from keyfill.learn.gan.ranges import estimate_ranges
from keyfill.learn.gan.sampling import body_halves, clip_batch, clip_window, crop_starts, real_crops, training_sequence
from keyfill.learn.training import TrainingTask

STAGES = ("path", "generator")


@dataclass
class Batch:
    """One global batch: ``arrays`` name -> numpy array whose first axis is the row (sequence or clip)."""

    stage: str
    arrays: dict = field(default_factory=dict)

    @property
    def rows(self) -> int:
        return len(next(iter(self.arrays.values())))

    def __len__(self) -> int:
        return self.rows


def _unwrap(net):
    """The module inside a data-parallel wrapper (or ``net`` itself)."""
    return getattr(net, "module", net)


class GanTask(TrainingTask):
    """The training task of either stage (see the module docstring).

    Args:
        corpus: a :class:`~keyfill.learn.corpus.Corpus` (clips of one skeleton).
        config: the settings.
        stage: ``"path"`` or ``"generator"``.
        path_model: for the generator stage, the model folder holding the trained path predictor (none with
            a base, ``GanConfig.base``: the root's path is its interpolation of the key roots).
        epochs: passes of ``steps_per_epoch`` steps (None: the config's ``path_epochs`` or ``generator_epochs``).
        checkpoint_every: epochs between the loop's checkpoints.
    """

    kind = KIND

    def __init__(self, corpus, config: GanConfig | None = None, stage: str = "path",
                 path_model: str | os.PathLike | None = None, epochs: int | None = None, checkpoint_every: int = 1):
        if stage not in STAGES:
            raise UsageError(f"unknown gan training stage {stage!r}; stages are {', '.join(STAGES)}")
        self.cfg = config or GanConfig()
        self.stage = stage
        self.epochs = int(epochs if epochs is not None else
                          (self.cfg.path_epochs if stage == "path" else self.cfg.generator_epochs))
        self.checkpoint_every = max(int(checkpoint_every), 1)
        self.clip = self.cfg.grad_clip
        self.device = "cpu"
        self.corpus = corpus
        self.skeleton = corpus.skeleton
        if self.skeleton.num_joints < 2:
            raise DataError("the gan model needs a skeleton of at least two joints")
        C = len(corpus)
        n_val = round(self.cfg.val_fraction * C) if C > 1 else 0
        order = np.random.default_rng([self.cfg.seed, 7]).permutation(C)
        self.val_clips = np.sort(order[:n_val])
        self.train_clips = np.sort(order[n_val:])
        labels = self.cfg.in_clip_fraction > 0 and stage == "generator"  # contacts and content groups
        spline = self.cfg.base != "none" and stage == "generator"
        matched = self.cfg.matched_set if self.cfg.base == "match" and stage == "generator" else None
        if self.cfg.base == "match" and stage == "generator" and not matched:
            raise UsageError("a gan model on base \"match\" trains on a matched set of its clips: give the GAN "
                             "setting matched_set (benchmarks/gan_matched_set.py builds one)")
        train_rows, val_rows = load_rows(matched, corpus, (self.train_clips, self.val_clips),
                                         corpus.skeleton.meters_per_unit) if matched else ((), ())
        self.train_pool = clip_pool(corpus, self.train_clips, labels, spline, train_rows)
        self.val_pool = clip_pool(corpus, self.val_clips, labels, spline, val_rows) if n_val else None
        train_q = np.concatenate([corpus.clip(int(i))[0] for i in self.train_clips])
        self.ranges = estimate_ranges(self.skeleton, train_q)
        self.spline_ranges = self.ranges if spline else None  # the sampling's spline base
        self.halves = body_halves(self.skeleton) if self.cfg.partial_keys else []
        self.train_bank = build_bank(corpus, self.train_clips) if self.cfg.dna else None
        self.val_bank = build_bank(corpus, self.val_clips) if self.cfg.dna and n_val else None
        self.step_count = 0
        self.ema: dict = {}  # name -> tensor: the moving average of the generator's weights (ema_decay > 0)
        self.nets: dict = {}
        self.path_net = None
        self.path_hash = ""
        if stage == "path" and self.cfg.base != "none":
            raise UsageError(f"a gan model with base {self.cfg.base!r} has no path predictor to train: its root path "
                             f"is that interpolation of the key roots; train its generator stage alone")
        if stage == "generator" and self.cfg.base != "none" and path_model is not None:
            raise UsageError(f"a gan model with base {self.cfg.base!r} takes its root path from that interpolation of "
                             f"the key roots; leave out the path predictor (--path-model)")
        if stage == "generator" and self.cfg.base == "none":
            if path_model is None:
                raise UsageError("the generator stage needs the trained path predictor: give path_model (a gan model "
                                 "folder from the path stage)")
            self.path_net, self.path_hash = self._load_path(path_model)
        if stage == "generator" and self.cfg.real_frames > int(self.train_pool.lengths.max()):
            raise DataError(f"real_frames {self.cfg.real_frames} is longer than every training clip "
                            f"(the longest has {int(self.train_pool.lengths.max())} frames)")

    # --- the contract ---

    def config(self) -> dict:
        """Settings a ``--resume`` must match (all but the epoch counts and the inference-only smoothing)."""
        skip = ("path_epochs", "generator_epochs", "output_smoothing")
        gan = {k: v for k, v in self.cfg.to_json().items() if k not in skip}
        return {"stage": self.stage, "gan": gan, "path_model": self.path_hash}

    def fingerprint(self) -> str:
        """SHA-1 of the corpus arrays (and file names) the task trains on."""
        h = hashlib.sha1()
        c = self.corpus
        for a in (c.quats, c.root, c.starts):
            h.update(np.ascontiguousarray(a).tobytes())
        h.update(json.dumps([Path(f).name for f in c.files]).encode())
        return h.hexdigest()

    def build(self, generator=None) -> dict:
        """The networks of this stage: ``{"path"}`` or ``{"generator", "discriminator"}``.

        Weights come from torch's global generator, which the loop seeds and forks
        around this call (``generator`` is accepted for the contract and not needed).
        """
        from keyfill.learn.gan.model import build_networks

        nets = build_networks(self.skeleton, self.ranges, self.cfg)
        if self.stage == "path":
            self.nets = {"path": nets["path"]}
        else:
            self.nets = {"generator": nets["generator"], "discriminator": nets["discriminator"]}
            if self.cfg.ema_decay > 0:
                self.ema = {k: v.detach().clone() for k, v in nets["generator"].state_dict().items()}
        return self.nets

    def _rates(self) -> dict:
        return {"path": self.cfg.lr_path, "generator": self.cfg.lr_generator,
                "discriminator": self.cfg.lr_discriminator}

    def optimizers(self, nets) -> dict:
        """RMSprop (PyTorch defaults) or Adam (betas 0.5, 0.999: GAN practice) per network (``optimizer``)."""
        import torch

        lr = self._rates()
        if self.cfg.optimizer == "adam":
            return {name: torch.optim.Adam(net.parameters(), lr=lr[name], betas=(0.5, 0.999))
                    for name, net in nets.items()}
        return {name: torch.optim.RMSprop(net.parameters(), lr=lr[name]) for name, net in nets.items()}

    def learning_rates(self, epoch: int, step: int, steps: int):
        """None for constant rates; with ``lr_schedule="cosine"`` each rate times the warm-up and cosine factor
        of the run's step ``epoch * steps + step`` (of ``epochs * steps``), which falls to a tenth."""
        if self.cfg.lr_schedule == "constant":
            return None
        total = max(self.epochs * steps, 1)
        t = epoch * steps + step
        warm = max(round(self.cfg.warmup_fraction * total), 1)
        if t < warm:
            f = (t + 1) / warm
        else:
            f = 0.1 + 0.9 * 0.5 * (1 + math.cos(math.pi * min((t - warm) / max(total - warm, 1), 1.0)))
        return {name: rate * f for name, rate in self._rates().items() if name in self.nets}

    def begin(self, rank: int, world: int, device: str) -> None:
        self.device = device
        if self.path_net is not None:
            self.path_net.to(device)

    def steps(self, epoch: int) -> int:
        return self.cfg.steps_per_epoch

    def batches(self, epoch: int) -> Iterator[Batch]:
        """``steps_per_epoch`` global batches, all drawn from ``default_rng([seed, stage, epoch])``."""
        rng = np.random.default_rng([self.cfg.seed, STAGES.index(self.stage), int(epoch)])
        for _ in range(self.cfg.steps_per_epoch):
            yield self.path_batch(rng) if self.stage == "path" else self.generator_batch(rng, self.train_pool)

    def shard(self, batch: Batch, rank: int, world: int) -> Batch:
        """Rows ``rank, rank + world, ...`` of every array."""
        return Batch(batch.stage, {k: v[rank::world] for k, v in batch.arrays.items()})

    def step(self, batch: Batch, update) -> tuple[dict, int]:
        """One step; calls ``update(name, loss)`` per optimiser (discriminator before generator)."""
        if batch.stage == "path":
            return self._path_step(batch, update)
        return self._generator_step(batch, update)

    def validate(self, epoch: int) -> dict:
        """Held-out scores (:mod:`keyfill.learn.gan.validation`): ``path_loss`` (Eq. 5, m^2), or the key, window
        and Motion DNA errors of the generator stage."""
        from keyfill.learn.gan.validation import validate_generator, validate_path

        if self.val_pool is None or not self.nets:
            return {}
        return validate_path(self) if self.stage == "path" else validate_generator(self)

    def log_row(self, epoch: int, losses: dict, validation: dict) -> dict:
        """The loop's row, with the root weight (a schedule, not a loss) logged as ``root_weight``."""
        row = super().log_row(epoch, {k: v for k, v in losses.items() if k != "root_weight"}, validation)
        if "root_weight" in losses:
            row["root_weight"] = losses["root_weight"]
        return row

    def state_dict(self) -> dict:
        return {"step_count": int(self.step_count), **({"ema": dict(self.ema)} if self.ema else {})}

    def load_state_dict(self, state: dict) -> None:
        self.step_count = int(state["step_count"])
        if self.cfg.ema_decay > 0:
            if "ema" not in state:
                raise DataError("the checkpoint has no moving average of the generator's weights")
            self.ema = {k: v.clone() for k, v in state["ema"].items()}

    def _update_ema(self, G) -> None:
        """One step of the moving average (``ema_decay``; tensors that are not floats are copied)."""
        import torch

        d = self.cfg.ema_decay
        with torch.no_grad():
            for k, v in _unwrap(G).state_dict().items():
                e = self.ema[k]
                if e.device != v.device:
                    e = self.ema[k] = e.to(v.device)
                if v.dtype.is_floating_point:
                    e.mul_(d).add_(v.detach(), alpha=1 - d)
                else:
                    e.copy_(v)

    def _run_steps(self) -> int:
        return self.epochs * self.cfg.steps_per_epoch

    def save(self, output, nets, history) -> Path:
        """Write the model folder ``output`` (kind ``"gan"``; stage ``"path"`` or ``"full"``)."""
        from keyfill.learn.gan.model import GanModel, build_networks

        nets = {k: _unwrap(v) for k, v in nets.items()}
        if self.stage == "path":
            gen, path, stage = None, nets["path"], "path"
        else:
            gen, path, stage = nets["generator"], self.path_net, "full"
            if self.ema:  # the model keeps the moving average (the checkpoint keeps both)
                gen = build_networks(self.skeleton, self.ranges, self.cfg)["generator"]
                gen.load_state_dict({k: v.cpu() for k, v in self.ema.items()})
        if path is None and self.cfg.base == "none":
            path = build_networks(self.skeleton, self.ranges, self.cfg)["path"]
        history = list(history or [])
        final = {k: v for k, v in (history[-1] if history else {}).items()
                 if k not in ("seconds", "cpu_seconds")}  # model files stay reproducible
        info = {"stage": self.stage, "steps": int(self.step_count), "epochs": len(history),
                "clips": len(self.train_clips), "validation_clips": len(self.val_clips), "final": final}
        model = GanModel(self.cfg, self.skeleton, self.ranges, gen, path, bool(self.corpus.folded),
                         float(self.corpus.fps), stage, info, self.train_bank)
        return Path(model.save(output))

    # --- batches ---

    def path_batch(self, rng: np.random.Generator) -> Batch:
        rel, root, lengths = clip_batch(self.train_pool, rng, self.cfg.path_batch, self.cfg.sequence_frames)
        return Batch("path", {"relative": rel, "root": root, "lengths": lengths})

    def generator_batch(self, rng: np.random.Generator, pool) -> Batch:
        """A batch of the paper's long sequences or, ``in_clip_fraction`` of the time, of in-clip windows
        (as many frames in all), with the discriminator's real crops and the fake crops' starts."""
        cfg = self.cfg
        if cfg.in_clip_fraction > 0 and rng.random() < cfg.in_clip_fraction:
            B = max(cfg.batch_size * cfg.sequence_frames // cfg.window_frames, 1)
            arrays = self.windows(rng, pool, B)
            frames = arrays["valid"].sum(1)
        else:
            B = cfg.batch_size
            arrays = self.sequences(rng, pool, B)
            frames = cfg.sequence_frames
        if self.stage == "generator":
            crops = cfg.crops_per_sequence
            real = real_crops(self.train_pool, rng, B * crops, cfg.real_frames)
            arrays["real"] = real.reshape(B, crops, *real.shape[1:])
            arrays["starts"] = crop_starts(rng, B, crops, frames, cfg.real_frames)
        return Batch("generator", arrays)

    def windows(self, rng, pool, count: int) -> dict:
        """The arrays of ``count`` in-clip windows of ``pool`` (:func:`~keyfill.learn.gan.sampling.clip_window`)."""
        cfg = self.cfg
        bank = self.train_bank if pool is self.train_pool else self.val_bank
        wins = [clip_window(pool, rng, cfg, self.halves, bank, self.spline_ranges) for _ in range(count)]
        arrays = {k: np.stack([w[k] for w in wins]) for k in ("dense", "key_mask", "key_root", "valid", "truth",
                                                               "contact", "base", "spline_root", "key_truth")
                  if k in wins[0]}
        arrays["noise"] = rng.standard_normal((count, cfg.noise_dim, cfg.window_frames // 64)).astype(np.float32)
        if bank is not None:
            arrays["dna"], arrays["dna_valid"] = pad_dna([w["dna"] for w in wins])
        return arrays

    def sequences(self, rng, pool, count: int) -> dict:
        """``dense``, ``key_mask``, ``noise`` (and ``dna``, ``dna_valid``) of ``count`` sequences of ``pool``."""
        cfg = self.cfg
        bank = self.train_bank if pool is self.train_pool else self.val_bank
        seqs = [training_sequence(pool, rng, cfg, self.halves, bank, self.spline_ranges) for _ in range(count)]
        arrays = {k: np.stack([q[k] for q in seqs]) for k in ("dense", "key_mask", "key_root", "base", "spline_root",
                                                              "key_truth") if k in seqs[0]}
        arrays["noise"] = rng.standard_normal((count, cfg.noise_dim, cfg.sequence_frames // 64)).astype(np.float32)
        if bank is not None:
            arrays["dna"], arrays["dna_valid"] = pad_dna([q["dna"] for q in seqs])
        return arrays

    # --- steps ---

    def _path_step(self, batch: Batch, update):
        import torch

        from keyfill.learn.gan.losses import displacement_loss
        from keyfill.learn.gan.network import joint_channels

        net = self.nets["path"]
        dev = next(net.parameters()).device
        a = batch.arrays
        rel = torch.as_tensor(a["relative"], device=dev)
        root = torch.as_tensor(a["root"], device=dev)
        loss = displacement_loss(net(joint_channels(rel)), root, torch.as_tensor(a["lengths"], device=dev))
        update("path", loss)
        self.step_count += 1
        return {"path": float(loss.detach())}, batch.rows

    def _frozen_path(self, dev):
        p = self.path_net
        if next(p.parameters()).device != dev:
            p.to(dev)
        return p

    def generator_outputs(self, G, t: dict):
        """``(v, quats, relative (B, T, J, 3), root (B, T, 3))`` of the generator on the tensors ``t`` of
        :meth:`inputs`; the root from the frozen path predictor, or the spline of a spline base."""
        from keyfill.learn.gan.network import joint_channels, root_path

        v = G(t["dense"], t["noise"], dna=t["dna"], dna_valid=t["dna_valid"], base=t["base"])
        quats, rel = _unwrap(G).rcfk(v)
        root = t["spline_root"] if t["spline_root"] is not None else \
            root_path(self._frozen_path(t["dense"].device)(joint_channels(rel)))
        return v, quats, rel, root

    def key_targets(self, dense, key_mask, key_root=None, key_truth=None):
        """``(key poses (B, T, J, 3), their root-relative part, given coordinates (B, T, J, 3) bool)`` of the input.

        The dense format gives every coordinate at the keys; the sparse one (partial keys) those its mask marks.
        ``key_root (B, T, 3)`` (the batches' ``key_root``) replaces the root row: the dense input's root
        channels are no root positions with ``root_input="key-relative"``. ``key_truth (B, 3 J, T)`` (the
        batches' with ``sketch_stretch``) replaces the input's positions: the true poses of stretched sketches.
        """
        import torch

        B, _, N = dense.shape
        J = self.skeleton.num_joints
        shown = dense[:, : 3 * J] if key_truth is None else key_truth
        keypose = shown.transpose(1, 2).reshape(B, N, J, 3)  # each frame's nearest key; the key at keys
        if key_root is not None and not self.cfg.partial_keys:
            keypose = torch.cat([key_root[:, :, None], keypose[:, :, 1:]], dim=2)
        key_rel = torch.cat([torch.zeros_like(keypose[:, :, :1]), keypose[:, :, 1:]], dim=2)
        if self.cfg.partial_keys:
            coords = dense[:, 3 * J :].transpose(1, 2).reshape(B, N, J, 3) > 0.5
        else:
            coords = key_mask[:, :, None, None].expand(B, N, J, 3)
        return keypose, key_rel, coords

    def inputs(self, a: dict, dev) -> dict:
        """The generator's tensors of a batch's arrays: ``dense``, ``key_mask``, ``key_root``, ``noise``, ``dna``,
        ``dna_valid``, ``base``, ``spline_root``, ``key_truth`` (None where the batch has none or the config uses none)."""
        import torch

        names = ("dense", "key_mask", "key_root", "noise", "dna", "dna_valid", "base", "spline_root", "key_truth")
        t = {k: torch.as_tensor(a[k], device=dev) if k in a else None for k in names}
        if not self.cfg.noise_dim:
            t["noise"] = None
        return t

    def _generator_step(self, batch: Batch, update):
        import torch

        from keyfill.learn.gan import losses as L
        from keyfill.learn.gan.layers import batch_regularisation, clear_statistics
        from keyfill.learn.gan.network import joint_channels

        cfg = self.cfg
        G, D = self.nets["generator"], self.nets["discriminator"]
        dev = next(G.parameters()).device
        a = batch.arrays
        t = self.inputs(a, dev)
        key_mask, dna, dna_valid = t["key_mask"], t["dna"], t["dna_valid"]
        keypose, key_rel, coords = self.key_targets(t["dense"], key_mask, t["key_root"], t["key_truth"])

        clear_statistics(G)
        _, quats, rel, root = self.generator_outputs(G, t)
        pasted = torch.where(coords, key_rel, rel)  # keys pasted in before D sees the motion
        fake = self._crops(joint_channels(pasted), torch.as_tensor(a["starts"], device=dev), cfg.real_frames)
        real = torch.as_tensor(a["real"], device=dev)
        real = joint_channels(real.reshape(-1, *real.shape[2:]))

        # discriminator: one forward over real and fake, so Eq. 9 sees both
        clear_statistics(D)
        scores = D(torch.cat([real, fake.detach()]))
        d_adv = L.discriminator_loss(scores[: len(real)], scores[len(real) :])
        d_br = batch_regularisation(D)
        update("discriminator", d_adv + cfg.br_weight * d_br)

        # generator, against the updated discriminator (its weights frozen for this pass)
        for p in D.parameters():
            p.requires_grad_(False)
        try:
            g_adv = L.generator_loss(D(fake))
            g_br = batch_regularisation(G)
            if cfg.partial_keys:
                joint = L.masked_key_joint_loss(rel, key_rel, coords)
                root_l = L.masked_key_root_loss(root, keypose[:, :, 0], coords[:, :, 0])
            else:
                joint = L.key_joint_loss(rel, key_rel, key_mask)
                root_l = L.key_root_loss(root, keypose[:, :, 0], key_mask)
            w_root = cfg.root_weight(self.step_count, self._run_steps())
            total = cfg.adv_weight * g_adv + cfg.br_weight * g_br + cfg.joint_weight * joint + w_root * root_l
            out = {}
            if "truth" in a:  # in-clip windows: the ground truth of every frame
                truth = torch.as_tensor(a["truth"], device=dev)
                valid = torch.as_tensor(a["valid"], device=dev)
                if cfg.recon_weight:
                    out["recon"] = L.reconstruction_loss(rel, truth, key_mask, valid, cfg.loss_form)
                    total = total + cfg.recon_weight * out["recon"]
                if cfg.foot_weight and len(self.train_pool.foot_joints):
                    up = 1 if self.skeleton.up_axis == "Y" else 2
                    out["foot"] = L.foot_sliding_loss(root, rel, self.train_pool.foot_joints,
                                                      torch.as_tensor(a["contact"], device=dev),
                                                      float(self.corpus.fps), up, cfg.loss_form)
                    total = total + cfg.foot_weight * out["foot"]
            if cfg.dna:
                out["dna_1"], out["dna_2"] = L.dna_losses(L.root_free(quats, rel), dna, dna_valid, key_mask,
                                                          round(cfg.dna_seconds * self.corpus.fps))
                total = total + cfg.dna_weight * (out["dna_1"] + out["dna_2"])
            update("generator", total)
        finally:
            for p in D.parameters():
                p.requires_grad_(True)
        if self.ema:
            self._update_ema(G)
        self.step_count += 1
        out.update({"d_adv": d_adv, "d_br": d_br, "g_adv": g_adv, "g_br": g_br, "key_joint": joint,
                    "key_root": root_l, "generator": total})
        return {k: float(v.detach()) for k, v in out.items()} | {"root_weight": w_root}, batch.rows

    @staticmethod
    def _crops(x, starts, length: int):
        """``x (B, C, T)``, ``starts (B, K)`` -> ``(B * K, C, length)``."""
        import torch

        B, C, _ = x.shape
        idx = starts[:, :, None] + torch.arange(length, device=x.device)  # (B, K, length)
        K = idx.shape[1]
        g = x[:, None].expand(B, K, C, x.shape[-1]).gather(3, idx[:, :, None, :].expand(B, K, C, length))
        return g.reshape(B * K, C, length)

    # --- the path predictor of the generator stage ---

    def _load_path(self, path_model):
        from keyfill.learn.gan.model import load_model
        from keyfill.learn.modelfile import WEIGHTS, check_skeleton, model_folder, read_config

        config = read_config(path_model, kind=KIND)
        check_skeleton(config, self.skeleton, model_folder(path_model))
        model = load_model(path_model, stage=None)
        net = model.path
        for p in net.parameters():
            p.requires_grad_(False)
        net.eval()
        digest = hashlib.sha1((model_folder(path_model) / WEIGHTS).read_bytes()).hexdigest()
        return net, digest

