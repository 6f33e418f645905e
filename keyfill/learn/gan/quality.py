"""The Motion DNA and partial-key figures of docs/gan.md (section 4.8 and section 5 of Zhou et al. 2020).

:func:`quality_report` scores a ``"gan"`` model on held-out clips, from the
networks' output before any exact-key correction:

* ``dna_error_1``, ``dna_error_2`` (cm): Eqs. 11-12 as errors, the mean joint
  distance of the root-free poses (:func:`keyfill.learn.gan.losses.dna_losses`
  with ``squared=False``), each sequence with keys sampled as in training
  (Appendix C, whole poses) and a DNA of one held-out clip's representative
  poses, one per 3 s of gap (Appendix D); the paper reports 8.4 and 6.5 cm;
* ``key_errors`` (cm) per kind of key (the networks given the sequence's DNA, as ``complete`` always
  gives a DNA model one): ``full``, ``root`` (root positions only,
  5.1), ``half`` (each half of the body with the root, 5.2), ``plane`` (2-D
  joint positions in the XY, XZ and YZ view planes, 5.3), ``sketch`` (the same
  planes, the keys drawn as a casual stick figure: every bone of every key
  scaled by ``exp(U(-0.3, 0.3))``, :func:`~keyfill.learn.gan.sampling.sketch_poses`;
  the error is to the true, unstretched pose): the mean over keys and
  keyed joints of the distance over the given coordinates, for the joints
  (root-relative) and for the root (after the path is moved onto the given key
  roots); the partial kinds need a ``partial_keys`` model;
* ``variety`` (cm): through the keys of each sequence, the mean pairwise
  distance of the in-betweens' world joint positions (frames between keys) for
  4 DNAs of 4 held-out clips with one noise seed, and for 4 noise seeds with one
  DNA (the paper's Fig. 10 in numbers);
* ``dna_pull_cm``: whether the DNA pulls: the Eq. 11 error of each of those 4 in-betweens to the DNA it was
  given (``own``) and to the next of the 4 DNAs (``other``); ``own`` below ``other`` when it steers.

:func:`path_errors` scores the global path predictor alone (Table 2): on each
held-out clip, the root displacement it predicts over ``n`` frames from the
clip's real joint positions against the real one.
"""

from __future__ import annotations

import itertools

import numpy as np

from keyfill.errors import DataError
from keyfill.learn.gan.dna import build_bank, dna_count, draw_dna
from keyfill.learn.gan.features import centre_keys
from keyfill.learn.gan.model import GanModel, generate
from keyfill.learn.gan.poses import clip_pool, relative_positions
from keyfill.learn.gan.sampling import body_halves, sample_keys, sketch_poses
from keyfill.learn.representative import root_free_poses

#: how many DNAs and seeds the variety figure compares
VARIETY = 4
#: the bone stretch of the ``sketch`` keys (each bone of each key scaled by ``exp(U(-s, s))``)
SKETCH_STRETCH = 0.3


def _key_kinds(model: GanModel, K: int) -> dict:
    """``{kind: [(K, J, 3) bool, ...]}``: the coordinates each kind of key gives."""
    J = model.skeleton.num_joints
    full = np.ones((K, J, 3), dtype=bool)
    kinds = {"full": [full]}
    if model.config.partial_keys:
        root = full.copy()
        root[:, 1:] = False
        kinds["root"] = [root]
        kinds["half"] = [full & h[None, :, None] for h in body_halves(model.skeleton)]
        kinds["plane"] = [full & (np.arange(3) != a) for a in range(3)]
        kinds["sketch"] = kinds["plane"]
    return kinds


def _key_error(model: GanModel, frames, poses, coords, seed: int, dna=None, key_quats=None,
               shown=None) -> tuple[float, float]:
    """``(joint error, root error)`` in metres of one generation through partial keys ``coords`` (with the Motion
    DNA ``dna`` a DNA model is given, as ``complete`` always gives one; ``key_quats`` for a model with a base).
    ``shown``: the key poses the network is given instead of ``poses`` (a sketch of them); the error is to
    ``poses``."""
    m = model.skeleton.meters_per_unit
    centred, _ = centre_keys(poses, model.skeleton.up_axis, coords)
    keys_in = centred if shown is None else centre_keys(shown, model.skeleton.up_axis, coords)[0]
    q, root = generate(model, frames, keys_in, seed, dna=dna, coords=coords, key_quats=key_quats)
    rel = relative_positions(q[frames], model.skeleton.offsets * m, model.skeleton.parents)
    d = (rel[:, 1:] - centred[:, 1:]) ** 2 * coords[:, 1:]
    given = coords[:, 1:].any(-1)
    joint = float(np.sqrt(d.sum(-1))[given].mean()) if given.any() else np.nan
    cr = coords[:, 0]
    r = np.sqrt((((root[frames] - centred[:, 0]) ** 2) * cr).sum(-1))[cr.any(-1)]
    return joint, float(r.mean()) if len(r) else np.nan


def _cm(values) -> float | None:
    """The mean of the finite ``values`` (metres) in cm; None when there is none (root-only keys give no joint)."""
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]
    return 100.0 * float(v.mean()) if len(v) else None


def _pairwise(motions) -> float:
    """Mean over pairs of the mean joint distance of world positions ``(T, J, 3)``."""
    return float(np.mean([np.linalg.norm(a - b, axis=-1).mean() for a, b in itertools.combinations(motions, 2)]))


def path_errors(model: GanModel, pool, horizons=(1, 64, 128)) -> dict:
    """Table 2: ``{n: cm}``, the mean 3-D error of the predicted root displacement over ``n`` frames.

    For every clip of ``pool`` (a :class:`~keyfill.learn.gan.poses.ClipPool`, metres) longer than
    ``n`` frames and every start ``t``: ``|sum_{i=t}^{t+n-1} v_i - (root[t+n] - root[t])|`` with
    ``v`` the path predictor's velocities from the clip's real root-relative joint positions; the
    mean over all (clip, t) pairs. ``n = 1`` is the error per frame. The paper's figures are at
    60 fps (0.7 cm per frame, 5.5 cm after 128 frames); at 30 fps, 64 frames last as long as its 128.
    """
    import torch

    from keyfill.learn.gan.network import joint_channels

    sums = {n: 0.0 for n in horizons}
    counts = {n: 0 for n in horizons}
    dev = next(model.path.parameters()).device
    with torch.inference_mode():
        for rel, root in zip(pool.relative, pool.root):
            v = model.path(joint_channels(torch.as_tensor(rel[None], device=dev)))[0].double().cpu().numpy()
            cum = np.concatenate([np.zeros((1, 3)), np.cumsum(v.T[:-1], axis=0)])  # predicted root - root[0]
            for n in horizons:
                if len(root) > n:
                    err = (cum[n:] - cum[:-n]) - (root[n:] - root[:-n])
                    sums[n] += float(np.linalg.norm(err, axis=-1).sum())
                    counts[n] += len(err)
    return {n: (100.0 * sums[n] / counts[n] if counts[n] else None) for n in horizons}


def quality_report(model: GanModel, corpus, clips, sequences: int = 20, frames: int | None = None,
                   seed: int = 0) -> dict:
    """The figures of the module docstring over ``sequences`` key layouts of the ``clips`` of ``corpus``.

    ``frames`` is the length of each sequence (default: the model's ``sequence_frames``).
    """
    import torch

    from keyfill.learn.gan.losses import dna_losses

    if model.generator is None:
        raise DataError("the quality report needs a full gan model (both stages)")
    cfg = model.config
    pool = clip_pool(corpus, clips, rotations=cfg.base != "none")  # a base interpolates the keys' rotations
    bank = build_bank(corpus, clips) if cfg.dna else None
    if cfg.dna and len(np.unique(bank.clips)) < VARIETY:
        raise DataError(f"the variety figure needs DNAs of {VARIETY} clips; {len(np.unique(bank.clips))} given")
    sk = model.skeleton
    off, par = sk.offsets * sk.meters_per_unit, sk.parents
    rng = np.random.default_rng(seed)
    N = frames or cfg.sequence_frames
    min_frames = round(cfg.dna_seconds * pool.fps)
    dna_err: dict = {1: [], 2: []}
    key_err: dict = {}
    variety: dict = {"dna": [], "seed": []}
    pull: dict = {"own": [], "other": []}
    for i in range(sequences):
        lay = sample_keys(pool, rng, N, cfg.min_gap, cfg.max_gap, cfg.short_gap_seconds, cfg.jump_speed)
        k = lay.frames
        count = dna_count(k, pool.fps, cfg.dna_seconds)
        dnas = [draw_dna(bank, rng, count) for _ in range(VARIETY)] if cfg.dna else [None]
        sketch = np.random.default_rng([seed, i])  # its own stream: the other figures stay as they were
        for kind, masks in _key_kinds(model, len(k)).items():
            for coords in masks:
                shown = sketch_poses(sketch, lay.poses, par, SKETCH_STRETCH) if kind == "sketch" else None
                key_err.setdefault(kind, []).append(_key_error(model, k, lay.poses, coords, i, dnas[0], lay.quats,
                                                               shown))
        between = np.setdiff1d(np.arange(k[-1] + 1), k)

        def world(q, root, between=between):
            return (relative_positions(q, off, par) + root[:, None])[between]

        if cfg.dna:
            outs = [generate(model, k, lay.poses, i, dna=d, key_quats=lay.quats) for d in dnas]
            key_mask = np.zeros(len(outs[0][0]), dtype=bool)
            key_mask[k] = True

            def errors(q, dna, key_mask=key_mask):  # Eqs. 11-12 as errors (m) of motion q to the poses dna
                return dna_losses(torch.as_tensor(root_free_poses(q, off, par))[None],
                                  torch.as_tensor(dna, dtype=torch.float64)[None],
                                  torch.ones(1, len(dna), dtype=torch.bool), torch.as_tensor(key_mask)[None],
                                  min_frames, squared=False)

            e = errors(outs[0][0], dnas[0])
            dna_err[1].append(float(e[0]))
            if np.any(np.diff(k) >= min_frames):  # Eq. 12 has terms only in gaps of 3 s or more
                dna_err[2].append(float(e[1]))
            for j, (q, _) in enumerate(outs):  # the pull: closer to the DNA it was given than to another?
                pull["own"].append(float(errors(q, dnas[j])[0]))
                pull["other"].append(float(errors(q, dnas[(j + 1) % VARIETY])[0]))
            variety["dna"].append(_pairwise([world(q, r) for q, r in outs]))
        seeds = [generate(model, k, lay.poses, i * VARIETY + s, dna=dnas[0], key_quats=lay.quats)
                 for s in range(VARIETY)]
        variety["seed"].append(_pairwise([world(q, r) for q, r in seeds]))
    report = {"sequences": sequences, "frames": N, "clips": len(pool),
              "key_errors": {kind: {"joints_cm": _cm([e[0] for e in v]), "root_cm": _cm([e[1] for e in v])}
                             for kind, v in key_err.items()},
              "variety_cm": {"seeds": _cm(variety["seed"])}}
    if cfg.dna:
        report["dna_error_1_cm"] = _cm(dna_err[1])
        report["dna_error_2_cm"] = _cm(dna_err[2])
        report["variety_cm"]["dnas"] = _cm(variety["dna"])
        report["dna_pull_cm"] = {"own": _cm(pull["own"]), "other": _cm(pull["other"])}
    return report
