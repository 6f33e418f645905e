"""A trained generative tweening model: its folder (kind ``"gan"``) and ``complete``.

A model folder (:mod:`keyfill.learn.modelfile`) holds ``weights.safetensors`` with the generator's tensors under
``generator.`` and the path predictor's under ``path.`` (none for a model with a base, ``GanConfig.base``), and a
``config.json`` with the skeleton it serves, whether its corpus folded a static top joint into the hips, the frame
rate, the :class:`~keyfill.learn.gan.config.GanConfig`, the joint ranges of the RC-FK layer (plain arrays,
:class:`~keyfill.learn.gan.ranges.JointRanges`), the ``stage`` (``"path"``: only the path predictor, from the first
training stage; ``"full"``: both networks) and a training summary. A model with a Motion DNA encoder
(``GanConfig.dna_width`` > 0) also keeps the representative poses of its training clips
(:class:`~keyfill.learn.gan.dna.DnaBank`) under ``dna_bank.``, the DNA ``complete`` draws by the seed when no DNA
file is given. The discriminator is a training tool and is not saved in the model (training checkpoints keep it).

:func:`complete_motion` fills a motion between its keys:

1. the key poses become root positions and root-relative joint positions
   (metres), re-centred on the keys' mean ground position, in the dense
   input format over the key range (padded to a multiple of 64 frames);
2. the generator, with noise drawn from ``torch.Generator().manual_seed(seed)``,
   gives every frame's local rotations through RC-FK; the path predictor gives
   root velocities, summed to a path and moved (a least-squares translation,
   as in Eq. 10) onto the key roots. With a base the generator corrects the keys'
   interpolation (:func:`spline_input`, :mod:`keyfill.learn.gan.spline_base`) or a
   match (:mod:`keyfill.learn.gan.matched_base`), whose root path it keeps;
3. joints the network does not drive (leaves) are interpolated between keys;
   frames outside the key range hold the generated first or last frame, so
   the exact-key correction puts them on the nearest key.

With whole keys the driven joints' rotations are then made to hit the keys inside their ranges
(:func:`keyfill.learn.gan.ranges.snap_in_range`); the rest of the keys (root, undriven joints) are not yet exact:
:func:`complete` applies the shared correction (:func:`keyfill.learn.exact_keys.snap_to_keys`) when asked. The
generator's angles are low-passed before FK (``GanConfig.output_smoothing``). Without ``--model``,
:data:`DEFAULT_MODEL` (whole keys) or :data:`PARTIAL_MODEL` (partial keys) is used: they serve the Bandai-Namco
skeleton.

Partial keys (:attr:`keyfill.motion.Keys.partial`) need a model trained with ``partial_keys``; its input is the
sparse format with the coordinates the keys give, and the root path is moved onto the key roots along the axes
they give. A Motion DNA (:func:`dna_poses`) is a set of representative poses of a motion file (its representative
frames, or listed frames) or of the model's bank.
"""

from __future__ import annotations

import itertools
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from keyfill import rotations as R
from keyfill.errors import KeyfillError, ModelError, UsageError
from keyfill.learn import installed_models
from keyfill.learn.gan import KIND
from keyfill.learn.gan.config import GanConfig
from keyfill.learn.gan.dna import DnaBank, dna_poses
from keyfill.learn.gan.features import centre_keys, dense_input, sparse_input
from keyfill.learn.gan.long_takes import FRAME_MULTIPLE, check_anchors, fill_take, latent_steps, take_noise, windows
from keyfill.learn.gan.ranges import JointRanges, snap_in_range
from keyfill.learn.gan.spline_base import spline_root, spline_values, track_values
from keyfill.limits import check_count, check_fps
from keyfill.motion import Skeleton

STAGES = ("path", "full")
#: the shipped gan model: Bandai-Namco dataset-2's skeleton, Motion DNA, whole keys (its MODEL_CARD.md and
#: LICENSE: CC BY-NC 4.0, as the data it learned from, so it comes in the model distribution models/bandai,
#: :mod:`keyfill.learn.installed_models`); None when that is not installed
DEFAULT_MODEL = installed_models.shipped("bandai2-gan")
#: the shipped model ``complete`` uses for partial keys (also trained with ``--partial-keys``), or None
PARTIAL_MODEL = installed_models.shipped("bandai2-gan-partial")
#: ends the error for a motion of another skeleton
TRAIN_HINT = ("; train a gan model on your own clips with 'keyfill train gan CLIPS -o MODEL-path --stage path' "
              "then 'keyfill train gan CLIPS -o MODEL --stage generator --path-model MODEL-path'")


def build_networks(skeleton: Skeleton, ranges: JointRanges, cfg: GanConfig) -> dict:
    """Fresh ``{"generator", "discriminator", "path"}`` torch modules (weights from torch's global generator).

    The skeleton's offsets are converted to metres for the RC-FK layer. ``residual_form`` and
    ``upsampling`` shape the generator and the discriminator; the path predictor keeps Table 5's layers
    (a path stage model serves generators of either recipe).
    """
    from keyfill.learn.gan.network import Discriminator, Generator, PathPredictor
    from keyfill.learn.gan.rcfk import RCFK

    J = skeleton.num_joints
    rcfk = RCFK(skeleton.parents, skeleton.offsets * skeleton.meters_per_unit, ranges)
    w = cfg.widths
    return {
        "generator": Generator(J, rcfk, w["encoder"], w["decoder"], cfg.noise_dim, cfg.style_dim, cfg.dna_width,
                               cfg.residual_form, cfg.upsampling, cfg.output_init, cfg.dna_norm, cfg.base_input),
        "discriminator": Discriminator(3 * (J - 1), w["discriminator"], cfg.residual_form),
        "path": PathPredictor(3 * (J - 1), w["path"]),
    }


@dataclass
class GanModel:
    """A generative tweening model with everything needed to use it.

    Attributes:
        config: the settings it was built and trained with.
        skeleton: the skeleton it serves (constant offsets; file units).
        ranges: the RC-FK joint ranges.
        generator, path: the torch modules (``generator`` is None for a ``"path"`` stage model, ``path`` for a
            model with a base, whose root path is the keys' interpolation).
        folded: whether its corpus folded a static top joint into the hips.
        fps: the corpus frame rate.
        stage: ``"path"`` or ``"full"``.
        info: training summary.
    """

    config: GanConfig
    skeleton: Skeleton
    ranges: JointRanges
    generator: object
    path: object
    folded: bool = False
    fps: float = 30.0
    stage: str = "full"
    info: dict = field(default_factory=dict)
    bank: DnaBank | None = None

    def model_config(self) -> dict:
        """The ``config.json`` content of this model."""
        s = self.skeleton
        return {
            "skeleton": s.to_json(),
            "folded_root": bool(self.folded),
            "fps": float(self.fps),
            "stage": self.stage,
            "gan": self.config.to_json(),
            "ranges": self.ranges.to_json(),
            "training": self.info,
        }

    def benchmark_method(self, seed: int = 0, library: str | os.PathLike | None = None):
        """This model as a method of :func:`keyfill.learn.protocols.lafan1.evaluate` (the LaFAN1 protocol); on a
        matched base, the windows are matched from ``library`` (default: the shipped library it names) first."""

        match = None
        if self.config.base == "match":
            from keyfill.learn.gan.matched_base import library_path
            from keyfill.learn.library.matcher import load_matcher, window_method

            match = window_method(load_matcher(library if library is not None else library_path(self, None)))

        def method(skeleton: Skeleton, quats, root, keys):
            starts = None if match is None else match(skeleton, quats, root, keys)
            return complete_windows(self, skeleton, quats, root, keys, seed, starts)

        method.folded = self.folded  # the protocol should prepare clips as the model's corpus was
        return method

    def tensors(self) -> dict:
        out = {} if self.path is None else {f"path.{k}": v for k, v in self.path.state_dict().items()}
        if self.generator is not None:
            out.update({f"generator.{k}": v for k, v in self.generator.state_dict().items()})
        if self.bank is not None and self.config.dna:
            import torch

            out["dna_bank.poses"] = torch.as_tensor(self.bank.poses)
            out["dna_bank.clips"] = torch.as_tensor(self.bank.clips)
        return out

    def save(self, path: str | os.PathLike):
        """Write the model folder ``path`` atomically (replaces a model already there)."""
        from keyfill.learn.modelfile import save_model

        return save_model(path, KIND, self.tensors(), self.model_config())


def config_parts(config: dict) -> tuple[GanConfig, Skeleton, JointRanges, float, str]:
    """``(settings, skeleton, ranges, fps, stage)`` of a model's ``config.json`` (no torch; a graph's
    :mod:`keyfill.learn.gan.onnx` reads the same); KeyError, TypeError, ValueError or a KeyfillError when damaged."""
    cfg = GanConfig.from_json(config["gan"])
    skel = Skeleton.from_json(config["skeleton"])
    ranges = JointRanges.from_json(config["ranges"])
    fps = float(config["fps"])
    if problem := check_fps(fps):
        raise ValueError(problem)
    stage = config["stage"]
    if stage not in STAGES:
        raise ValueError(f"unknown stage {stage!r}")
    return cfg, skel, ranges, fps, stage


def load_model(path: str | os.PathLike, device: str = "cpu", stage: str | None = "full") -> GanModel:
    """Read a ``"gan"`` model folder (no code is executed); ``stage`` (if given) must match."""
    from keyfill.learn import modelfile
    from keyfill.learn.modelfile import torch_device

    dev = torch_device(device)
    tensors, config = modelfile.load_model(path, kind=KIND)
    folder = modelfile.model_folder(path)
    try:
        cfg, skel, ranges, fps, model_stage = config_parts(config)
        nets = modelfile.build_for_loading(lambda: build_networks(skel, ranges, cfg))
    except (KeyError, TypeError, ValueError, KeyfillError) as e:
        raise ModelError(f"{folder}: damaged gan model config ({e})") from None
    if stage is not None and model_stage != stage:
        raise ModelError(f"{folder}: a gan model of stage {model_stage!r} (only the global path predictor); "
                         f"train its generator (the second stage) before completing motions with it")
    gen = nets["generator"] if model_stage == "full" else None
    path_net = nets["path"] if cfg.base == "none" else None  # a base gives the root path
    for name, net in (("path", path_net), ("generator", gen)):
        if net is None:
            continue
        part = {k[len(name) + 1 :]: v for k, v in tensors.items() if k.startswith(name + ".")}
        modelfile.load_state(net, part, folder)
        net.eval().to(dev)
    bank = None
    if cfg.dna and model_stage == "full":
        if "dna_bank.poses" not in tensors or "dna_bank.clips" not in tensors:
            raise ModelError(f"{folder}: a gan model with Motion DNA but no bank of representative poses")
        bank = DnaBank(tensors["dna_bank.poses"].numpy(), tensors["dna_bank.clips"].numpy())
    return GanModel(cfg, skel, ranges, gen, path_net, bool(config["folded_root"]), fps,
                    model_stage, dict(config.get("training") or {}), bank)


def load(path: str | os.PathLike, device: str = "cpu") -> GanModel:
    """The registry's loader: a full (two-stage) gan model."""
    return load_model(path, device)


# --- completing motions -------------------------------------------------------------


def check_keys(model: GanModel, frames: np.ndarray) -> None:
    """A :class:`UsageError` when two consecutive keys are too far apart (a key range of any length is filled
    by windows, :func:`~keyfill.learn.gan.long_takes.windows`)."""
    cfg = model.config
    for a, b in itertools.pairwise(int(f) for f in frames):
        if b - a > cfg.max_gap:
            raise UsageError(f"keys {a} and {b} are {b - a} frames apart; this gan model fills gaps of at most "
                             f"{cfg.max_gap} frames (the longest gap it was trained for); add a key between them")
        if b - a >= cfg.max_frames:
            raise UsageError(f"keys {a} and {b} are {b - a} frames apart; this gan model fills at most "
                             f"{cfg.max_frames} frames at once (its max_frames); add a key between them")


def generate(model: GanModel, key_frames: np.ndarray, key_poses: np.ndarray, seed: int = 0, style=None,
             dna=None, coords=None, key_quats=None, noise=None, track=None):
    """Run the networks over the key range (the generator, and the path predictor of a model without a base).

    Args:
        key_frames: ``(K,)`` increasing, starting at 0.
        key_poses: ``(K, J, 3)``, or ``(B, K, J, 3)`` for ``B`` sequences sharing the keys; metres:
            root positions (re-centred) and root-relative joints.
        seed: the seed of the noise (``torch.Generator().manual_seed(seed)``, one draw for the batch).
        style: optional ``(style_dim,)`` or ``([B,] style_dim)`` per-sequence style vector (None: zeros).
        dna: optional ``(P, J - 1, 3)`` or ``([B,] P, J - 1, 3)`` root-free representative poses
            (metres) for a model with a Motion DNA encoder (instead of ``style``).
        coords: ``(K, J, 3)`` bool, the coordinates partial keys give (a ``partial_keys`` model's
            sparse input; None: every coordinate). The root path is moved onto the key roots
            along the axes they give.
        key_quats: ``([B,] K, J, 4)`` the keys' local rotations, for a model with a base (``GanConfig.base``,
            :mod:`keyfill.learn.gan.spline_base`: the network corrects their interpolation, and the root
            path is the interpolation of the key roots).
        noise: ``(B, noise_dim, T' / 64)`` float32, the noise of a model with noise instead of the draw from
            ``seed`` (``T'`` the key range padded to a multiple of 64 frames; a window's share of a long
            take's noise, :func:`complete_motion`).
        track: for a model on a matched base (``GanConfig.base`` ``"match"``), the matched in-between
            ``(quats ([B,] T, J, 4), root ([B,] T, 3))`` (metres, re-centred as the key poses are) it corrects;
            the root path is then the track's.

    Returns:
        ``(quats ([B,] T, J, 4), root ([B,] T, 3))`` for ``T = key_frames[-1] + 1`` frames, each
        root path moved onto its key roots (the least-squares translation); float64 numpy.
    """
    key_poses = np.asarray(key_poses)
    single = key_poses.ndim == 3
    poses = key_poses[None] if single else key_poses
    T = int(key_frames[-1]) + 1
    x = network_input(model, key_frames, poses, coords)
    if model.config.base == "match":
        if track is None:
            raise ValueError("a gan model on a matched base needs the matched in-between (track)")
        tq, troot = (np.asarray(a, dtype=np.float64) for a in track)
        tq, troot = (tq[None], troot[None]) if tq.ndim == 3 else (tq, troot)
        base = np.stack([track_values(model.ranges, np.concatenate([q, np.repeat(q[-1:], x.shape[-1] - T, 0)]))
                         for q in tq])
    else:
        base = spline_input(model, key_frames, key_quats, len(poses), x.shape[-1])
    run = getattr(model.generator, "run_numpy", None)  # an exported graph (keyfill.learn.gan.onnx)
    if run is not None:  # a graph: no noise (only noise-free models export)
        quats, root = run(model, x, seed, style, dna, base)
    else:
        quats, root = _run_torch(model, x, seed, style, dna, base, noise)
    kr = poses[:, :, 0]
    if model.config.base == "match":
        root = troot[:, :T]
    elif base is not None:
        root = np.stack([spline_root(T, key_frames, r, model.config.base) for r in kr])
    q, root = quats[:, :T].astype(np.float64), root[:, :T].astype(np.float64)
    if coords is None:
        root = root + (kr.mean(1) - root[:, key_frames].mean(1))[:, None]
    else:
        cr = np.asarray(coords)[:, 0]  # (K, 3)
        n = np.maximum(cr.sum(0), 1)
        root = root + (((kr - root[:, key_frames]) * cr).sum(1) / n)[:, None]
    q = R.quat_normalize(q)
    return (q[0], root[0]) if single else (q, root)


def network_input(model: GanModel, key_frames, poses: np.ndarray, coords=None) -> np.ndarray:
    """The generator's input ``(B, 6 J, T')`` float32 for ``poses (B, K, J, 3)`` (:func:`generate`'s), ``T'`` the
    key range padded to a multiple of :data:`FRAME_MULTIPLE`: the dense format, or the sparse one for a
    ``partial_keys`` model (``coords``: the coordinates the keys give)."""
    cfg = model.config
    T = int(key_frames[-1]) + 1
    Tp = T + (-T) % FRAME_MULTIPLE
    if cfg.partial_keys:
        given = np.ones(poses.shape[1:], dtype=bool) if coords is None else np.asarray(coords, dtype=bool)
        return np.stack([sparse_input(Tp, key_frames, p, given) for p in poses])
    return np.stack([dense_input(Tp, key_frames, p, cfg.mask_scale, cfg.root_input, model.skeleton.up_axis)
                     for p in poses])


def spline_input(model: GanModel, key_frames, key_quats, batch: int, frames: int) -> np.ndarray | None:
    """The generator's base ``(B, 6 + 3 D, T')`` float32 for a model with a base (``GanConfig.base``; None for the
    others): the RC-FK values of its interpolation of ``key_quats ([B,] K, J, 4)``, ``T'`` padded frames."""
    if model.config.base == "none":
        return None
    if key_quats is None:
        raise ValueError("a gan model with a base needs the keys' rotations (key_quats)")
    kq = np.asarray(key_quats, dtype=np.float64)
    kq = np.broadcast_to(kq[None] if kq.ndim == 3 else kq, (batch, *kq.shape[-3:]))
    return np.stack([spline_values(model.ranges, frames, key_frames, q, model.config.base) for q in kq])


def _run_torch(model: GanModel, x: np.ndarray, seed: int, style, dna, base=None, noise=None):
    """The torch networks on ``x`` (:func:`network_input`): ``(quats (B, T', J, 4), root (B, T', 3))`` float32,
    the root path from 0 (``noise``, or noise from ``torch.Generator().manual_seed(seed)``, one draw for the
    batch); with a ``base`` (:func:`spline_input`) the output corrects it and the root is None (the caller's
    spline)."""
    import torch

    from keyfill.learn.gan.network import GENERATOR_MULTIPLE, joint_channels, root_path

    cfg = model.config
    B, Tp = len(x), x.shape[-1]
    dev = next(model.generator.parameters()).device
    x = torch.as_tensor(x, device=dev)
    if not cfg.noise_dim:
        noise = None
    elif noise is None:
        noise = torch.randn(B, cfg.noise_dim, Tp // GENERATOR_MULTIPLE, generator=torch.Generator().manual_seed(int(seed)))
    noise = None if noise is None else torch.as_tensor(noise).to(dev)
    w = d = None
    if style is not None:
        w = torch.as_tensor(np.asarray(style, dtype=np.float32), device=dev).reshape(-1, cfg.style_dim).expand(B, -1)
    if dna is not None:
        d = torch.as_tensor(np.asarray(dna, dtype=np.float32), device=dev)
        d = (d[None] if d.ndim == 3 else d).expand(B, -1, -1, -1)
    with torch.inference_mode():
        v = model.generator(x, noise, w, dna=d, base=None if base is None else torch.as_tensor(base, device=dev))
        quats, rel = model.generator.rcfk(v, cfg.output_smoothing)
        if base is not None:
            return quats.cpu().numpy(), None
        root = root_path(model.path(joint_channels(rel)))
    return quats.cpu().numpy(), root.cpu().numpy()


def _undriven(model: GanModel, num_joints: int) -> np.ndarray:
    """Joints of the file whose rotation the network does not give: the leaves, and the top joint when folded."""
    out = set(range(1, num_joints)) - {int(j) for j in model.ranges.driven}
    if model.folded:
        out.add(0)
    return np.array(sorted(out), dtype=np.int64)


def _key_hemispheres(quats: np.ndarray, key_frames: np.ndarray, key_quats: np.ndarray) -> np.ndarray:
    """``quats (T, J, 4)`` with each key frame on its key's hemisphere (``key_quats (K, J, 4)``) and the frames
    between continuing it: RC-FK's root has ``w >= 0`` and its joints an Euler conversion's sign, where the
    LaFAN1 metrics compare quaternions sign and all (``complete`` gets continuous tracks from the rig bridge)."""
    q = np.array(quats, dtype=np.float64, copy=True)
    flip = np.sum(q[key_frames] * key_quats, axis=-1) < 0
    q[key_frames] = np.where(flip[..., None], -q[key_frames], q[key_frames])
    return R.quat_continuous_between(q, key_frames)


def complete_motion(model: GanModel, motion, keys, seed: int = 0, dna=None, start=None) -> tuple[object, dict]:
    """Fill every frame of ``motion`` between its ``keys`` (reads only the key frames; see the module docstring).

    ``keys`` is a :class:`~keyfill.motion.Keys` (partial keys need a ``partial_keys`` model) or
    key frames; ``dna`` the ``(P, J - 1, 3)`` poses of :func:`dna_poses` (a DNA model without
    them draws from its bank by ``seed``). A model on a matched base corrects ``start``, the motion's in-between
    from a library (:func:`keyfill.learn.gan.matched_base.matched_start`; every frame, keys exact). Returns
    ``(motion, info)``; keys are not yet exact.

    A key range longer than ``GanConfig.max_frames`` is filled by overlapping windows that share one Motion
    DNA (a model of its keys' own DNA, ``dna_source`` ``"own"``: each window's) and one draw of noise, cross-faded
    where they overlap (:mod:`keyfill.learn.gan.long_takes`). Memory: the motion's arrays plus one window's.
    """
    from keyfill.learn.windows import file_take, model_take
    from keyfill.motion import Keys

    if model.generator is None:
        raise ModelError("this gan model holds only the global path predictor; train its generator first")
    keys = keys if isinstance(keys, Keys) else Keys(np.asarray(keys, dtype=np.int64))
    k = keys.frames
    coords = None
    if keys.partial:
        if not model.config.partial_keys:
            raise UsageError("this gan model was trained on whole poses only; partial keys need a model trained "
                             "with partial_keys (see docs/gan.md)")
        coords = keys.coordinate_mask(motion.num_joints)
    check_keys(model, k)
    skel = motion.skeleton
    # the take's arrays: translations and undriven joints interpolated, in the model's hierarchy; the
    # windows write the root and the driven joints into them, and they become the result's arrays
    track = None
    if model.config.base != "match":
        q, p, top = model_take(model.skeleton, model.folded, motion, k, _undriven(model, motion.num_joints),
                               hint=TRAIN_HINT)
    elif start is None:
        raise ValueError("a gan model on a matched base completes from a matched start")
    else:  # the matched in-between (its keys the motion's), every joint its own: the base and the undriven joints
        q, p, top = model_take(model.skeleton, model.folded, start, np.arange(start.num_frames), slerped=np.arange(0),
                               continuous=True, hint=TRAIN_HINT)  # every frame a key: the match's own root
        track = (q.copy(), p[:, 0].copy())
    if model.folded and coords is not None:  # the folded top joint is the hips: keyed where either of them is
        c = skel.children(0)[0]
        coords = coords.copy()
        coords[:, 0] |= coords[:, c]
        coords[:, c] = coords[:, 0]
    plan = windows(k, model.config.max_frames)
    if coords is not None:
        check_anchors(coords, k, plan, model.config.max_frames)
    key_q, key_root = q[k], p[k, 0]  # the windows' input; q and p then take their output in place
    if model.config.dna and dna is None and model.config.dna_source != "own":
        dna = dna_poses(model, key_frames=k, seed=seed)
    noise = take_noise(model.config.noise_dim, k, plan, seed)
    k0, end = int(k[0]), int(k[-1])

    def fill(i: int, j: int):
        first = (int(k[i]) - k0) // FRAME_MULTIPLE  # the window's first latent step in the take's noise
        span = slice(int(k[i]), int(k[j]) + 1)
        return _fill_window(model, k[i : j + 1] - k[i], key_q[i : j + 1], key_root[i : j + 1],
                            None if coords is None else coords[i : j + 1], seed, dna,
                            None if noise is None else noise[:, :, first : first + latent_steps(k[j] - k[i] + 1)],
                            None if track is None else (track[0][span], track[1][span]))

    fill_take(q, p[:, 0], k, plan, model.ranges, fill)
    out_q, pos = q, p
    # outside the key range, hold the generated first and last frames (the exact-key correction then
    # moves them onto the keys together with the frames inside)
    out_q[:k0], out_q[end + 1 :] = out_q[k0], out_q[end]
    pos[:k0, 0], pos[end + 1 :, 0] = pos[k0, 0], pos[end, 0]
    file_take(out_q, pos, top, skel)
    result = motion.replace(rotations=out_q, positions=pos, keys=keys)
    span = slice(k0, end + 1)
    info = {"seed": int(seed), "max_gap": model.config.max_gap, "frames_generated": int(span.stop - k0),
            "windows": len(plan)}
    if keys.partial:
        keyed = "all" if keys.mask is None else f"{int(keys.mask.any(0).sum())} of {motion.num_joints}"
        info["partial_keys"] = f"{keys.given}, {keyed} joints keyed"
    if dna is not None:
        info["dna_poses"] = len(dna)
    return result, info


def _fill_window(model: GanModel, key_frames: np.ndarray, key_quats: np.ndarray, key_roots: np.ndarray, coords,
                 seed: int, dna, noise, track=None) -> tuple[np.ndarray, np.ndarray]:
    """One window of :func:`complete_motion`: ``(quats (T, J, 4), root (T, 3))`` of its ``T`` frames in the
    model's hierarchy (root in file units; driven joints and the root set, whole keys' driven joints exact
    in the ranges).

    Args:
        key_frames: ``(K,)`` from 0; key_quats: ``(K, J, 4)`` their local rotations (the model's hierarchy);
        key_roots: ``(K, 3)`` their root positions (file units); coords: ``(K, J, 3)`` bool of partial keys
        or None; dna: the take's Motion DNA or None (a DNA model then takes the keys' own poses); noise: the
        window's ``(1, noise_dim, T' / 64)`` or None (:func:`generate`); track: a matched base's
        ``(quats (T, J, 4), root (T, 3))`` of the window (the model's hierarchy, file units), else None.
    """
    from keyfill.learn.gan.poses import relative_positions

    m = model.skeleton.meters_per_unit
    poses = relative_positions(key_quats, model.skeleton.offsets * m, model.skeleton.parents)
    poses[:, 0] = key_roots * m
    poses, shift = centre_keys(poses, model.skeleton.up_axis, coords)
    if model.config.dna and dna is None:
        dna = dna_poses(model, key_frames=key_frames, seed=seed, key_quats=key_quats)
    if track is not None:  # in the key poses' frame: metres, re-centred
        track = (track[0], track[1] * m - shift)
    gq, groot = generate(model, key_frames, poses, seed, dna=dna, coords=coords, key_quats=key_quats, noise=noise,
                         track=track)
    if coords is None:  # whole keys: exact in the ranges' angles, so the ranges hold between keys
        gq = snap_in_range(model.ranges, gq, key_frames, key_quats)
    return gq, (groot + shift) / m


def complete(motion, keys, options):
    """``keyfill complete --method gan``: :func:`complete_motion`, then exact keys when ``options.exact_keys``.

    ``options.dna`` (``FILE[:FRAMES]``) and ``options.dna_count`` choose the Motion DNA.
    """
    from keyfill.learn.modelfile import load_cached

    path = model_path(options, keys)
    return complete_with(load_cached(load, path, options.device), motion, keys, options, path)


def complete_with(model: GanModel, motion, keys, options, path):
    """:func:`complete` with a loaded ``model`` (torch, or an exported graph's) from ``path``."""
    from keyfill import io
    from keyfill.learn import rig_bridge
    from keyfill.learn.completion import Completion
    from keyfill.learn.exact_keys import snap_to_keys
    from keyfill.learn.gan.dna import parse_dna
    from keyfill.learn.gan.matched_base import completion_start

    dna = source = frames = None
    if options.dna is not None or options.dna_count is not None:
        if options.dna is not None:
            dna_file, frames = parse_dna(options.dna)
            served = rig_bridge.Served(model.skeleton, model.fps, model.folded)
            source = rig_bridge.on_model_skeleton(io.load(dna_file), served, hint=TRAIN_HINT, what="the DNA motion")
        if options.dna_count is not None and model.config.dna:  # named as the option, not dna_poses' count
            check_count("dna_count", options.dna_count, model.config.max_frames)
        dna = dna_poses(model, source, frames, options.dna_count, keys.frames, options.seed)
    start, matched = completion_start(model, motion, keys, options, source, frames)
    filled, info = complete_motion(model, motion, keys, options.seed, dna, start)
    info = {"model": str(options.model or path.name), **info, **matched, "exact_keys": bool(options.exact_keys)}
    if options.dna is not None:
        info["dna"] = options.dna
    if options.exact_keys:
        filled, report = snap_to_keys(filled, motion, keys, in_place=True)  # filled: ours
        info.update(report)
    return Completion(filled, info)


def complete_windows(model: GanModel, skeleton: Skeleton, quats: np.ndarray, root: np.ndarray, keys, seed: int = 0,
                     starts=None):
    """Fill windows that share their ``keys`` (the benchmark's arrays; numpy in, numpy out).

    Args:
        skeleton: the windows' skeleton (as the model's corpus was prepared: folded or not).
        quats: ``(B, T, J, 4)`` local quaternions, root: ``(B, T, 3)`` (only key frames are read).
        keys: ``(K,)`` increasing frames.

        starts: for a model on a matched base, ``(quats (B, T, J, 4), root (B, T, 3))``: each window's
            matched in-between, on the windows' skeleton (:meth:`GanModel.benchmark_method` makes them).

    Returns ``(quats, root)`` of all ``T`` frames with exact keys (the shared smooth correction).
    """
    from keyfill.learn.corpus import bone_difference
    from keyfill.learn.exact_keys import snap_to_keys
    from keyfill.learn.gan.poses import relative_positions
    from keyfill.learn.windows import model_take, window_motion
    from keyfill.motion import Keys

    diff = bone_difference(model.skeleton, skeleton)
    if diff is not None:
        raise ModelError(f"the gan model serves another skeleton: {diff}")
    k = np.asarray(keys, dtype=np.int64)
    check_keys(model, k)
    if k[-1] - k[0] >= model.config.max_frames:
        raise UsageError(f"the benchmark's keys span {int(k[-1] - k[0]) + 1} frames; this gan model fills windows "
                         f"of at most {model.config.max_frames} frames at once")
    m = model.skeleton.meters_per_unit
    poses = relative_positions(np.asarray(quats)[:, k], model.skeleton.offsets * m, model.skeleton.parents)
    poses[:, :, 0] = np.asarray(root)[:, k] * m
    shifts = []
    for b in range(len(poses)):
        poses[b], shift = centre_keys(poses[b], model.skeleton.up_axis)
        shifts.append(shift)
    k0, end = int(k[0]), int(k[-1])
    dna = dna_poses(model, key_frames=k, seed=seed, key_quats=np.asarray(quats)[:, k]) if model.config.dna \
        else None  # as complete: from the bank, or the keys' own poses
    track = None
    if starts is not None:  # in the key poses' frame: metres, re-centred
        span = slice(k0, end + 1)
        track = (np.asarray(starts[0])[:, span], np.asarray(starts[1])[:, span] * m - np.array(shifts)[:, None])
    gq, groot = generate(model, k - k0, poses, seed, dna=dna, key_quats=np.asarray(quats)[:, k], track=track)
    out_q, out_r = [], []
    undriven = _undriven(model, skeleton.num_joints)
    for b in range(len(poses)):
        # frames between keys may hold NaN (the protocol hides them); only key frames are read
        src = window_motion(skeleton, np.nan_to_num(np.asarray(quats[b], dtype=np.float64)),
                            np.nan_to_num(np.asarray(root[b], dtype=np.float64)))
        rot, pos, _ = model_take(skeleton, False, src, k, undriven)
        if starts is not None:  # the undriven joints as the match has them
            rot[k0 : end + 1] = np.asarray(starts[0][b], dtype=np.float64)[k0 : end + 1]
        driven = np.concatenate([[0], model.ranges.driven])
        rot[k0 : end + 1, driven] = snap_in_range(model.ranges, gq[b], k - k0, rot[k])[:, driven]
        pos[k0 : end + 1, 0] = (groot[b] + shifts[b]) / m
        rot[:k0], rot[end + 1 :] = rot[k0], rot[end]
        pos[:k0, 0], pos[end + 1 :, 0] = pos[k0, 0], pos[end, 0]
        pred = src.replace(rotations=_key_hemispheres(R.quat_normalize(rot), k, src.rotations[k]), positions=pos)
        fixed, _ = snap_to_keys(pred, src, Keys(k))
        out_q.append(fixed.rotations)
        out_r.append(fixed.positions[:, 0])
    return np.array(out_q), np.array(out_r)


def model_path(options, keys) -> Path:
    """The model folder (or graph) a completion with ``options`` uses: ``options.model``, else the shipped
    model for whole keys or, for partial ``keys``, the one trained with them."""
    return Path(options.model) if options.model is not None else PARTIAL_MODEL if keys.partial else DEFAULT_MODEL
