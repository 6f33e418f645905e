"""Held-out scores of the gan's training stages (``GanTask.validate``), on the task's validation clips.

* path stage: ``path_loss``, Eq. 5 (m^2);
* generator stage: ``key_joint_error`` and ``key_root_error`` (the mean distances at the keys of held-out
  long sequences, the root after Eq. 10's re-centring), with Motion DNA ``dna_error_1`` / ``dna_error_2``
  (Eqs. 11-12 as mean joint distances), and with in-clip windows ``window_error`` and
  ``window_foot_speed`` (:func:`window_errors`); file units (per second for the speed).

Every score draws its sequences from a fixed seed (``[seed, 97..99]``), so epochs compare.
"""

from __future__ import annotations

import numpy as np

from keyfill.learn.gan.sampling import clip_batch


def validate_path(task) -> dict:
    """``path_loss``: Eq. 5 (m^2) on up to 64 whole held-out clips."""
    import torch

    from keyfill.learn.gan.losses import displacement_loss
    from keyfill.learn.gan.network import joint_channels

    net = task.nets["path"]
    was = net.training
    net.eval()
    rng = np.random.default_rng([task.cfg.seed, 99])
    rel, root, lengths = clip_batch(task.val_pool, rng, min(len(task.val_pool), 64), task.cfg.sequence_frames)
    dev = next(net.parameters()).device
    with torch.no_grad():
        loss = displacement_loss(net(joint_channels(torch.as_tensor(rel, device=dev))),
                                 torch.as_tensor(root, device=dev), torch.as_tensor(lengths, device=dev))
    net.train(was)
    return {"path_loss": float(loss)}


def validate_generator(task) -> dict:
    """Mean key errors over the given coordinates (joints, and the root after Eq. 10's re-centring) and,
    with Motion DNA, the errors of Eqs. 11-12 as mean joint distances; file units. A model on a matched base
    (trained on in-clip windows only: sequences across clips have no match) has only the window figures."""
    import torch

    from keyfill.learn.gan.losses import dna_losses, root_free

    G = task.nets["generator"]
    was = G.training
    G.eval()
    rng = np.random.default_rng([task.cfg.seed, 98])
    cfg = task.cfg
    errors = {"key_joint_error": [], "key_root_error": [], "dna_error_1": [], "dna_error_2": []}
    dev = next(G.parameters()).device
    with torch.no_grad():
        for _ in range(cfg.val_sequences if cfg.base != "match" else 0):
            seq = task.sequences(rng, task.val_pool, 1)
            t = task.inputs(seq, dev)
            key_mask, dna, dna_valid = t["key_mask"], t["dna"], t["dna_valid"]
            _, quats, rel, root = task.generator_outputs(G, t)
            keypose, _, coords = task.key_targets(t["dense"], key_mask, t["key_root"], t["key_truth"])
            k = torch.nonzero(key_mask[0]).flatten()
            c = coords[0, k].cpu().numpy()
            d = (rel[0, k] - keypose[0, k]).cpu().numpy()
            joints = c[:, 1:].any(-1)
            if joints.any():
                errors["key_joint_error"].append(np.sqrt((d[:, 1:] ** 2 * c[:, 1:]).sum(-1))[joints].mean())
            rk, kr, cr = root[0, k].cpu().numpy(), keypose[0, k, 0].cpu().numpy(), c[:, 0]
            n = np.maximum(cr.sum(0), 1)
            aligned = rk - (rk * cr).sum(0) / n + (kr * cr).sum(0) / n
            if cr.any():
                errors["key_root_error"].append(np.sqrt(((aligned - kr) ** 2 * cr).sum(-1))[cr.any(-1)].mean())
            if cfg.dna:
                e1, e2 = dna_losses(root_free(quats, rel), dna, dna_valid, key_mask,
                                    round(cfg.dna_seconds * task.corpus.fps), squared=False)
                errors["dna_error_1"].append(float(e1))
                errors["dna_error_2"].append(float(e2))
    if cfg.in_clip_fraction > 0:
        errors.update(window_errors(task, G, dev))
    G.train(was)
    m = task.skeleton.meters_per_unit
    return {name: float(np.mean(v) / m) for name, v in errors.items() if v}


def window_errors(task, G, dev) -> dict:
    """On held-out in-clip windows: ``window_error`` (the mean world joint position error on the frames
    between keys, the root path moved onto the key roots as ``complete`` does; metres) and
    ``window_foot_speed`` (the mean horizontal foot speed where the ground truth is in contact, m/s;
    file units per second once the caller divides)."""
    import torch

    rng = np.random.default_rng([task.cfg.seed, 97])
    a = task.windows(rng, task.val_pool, max(4 * task.cfg.val_sequences, 1))
    with torch.no_grad():
        _, _, rel, root = task.generator_outputs(G, task.inputs(a, dev))
    truth = a["truth"]
    km, valid = a["key_mask"], a["valid"]
    root = root.cpu().numpy()
    n = km.sum(1, keepdims=True)[..., None]
    root = root + ((truth[:, :, 0] - root) * km[..., None]).sum(1, keepdims=True) / n
    world = rel.cpu().numpy() + root[:, :, None]
    true_world = truth[:, :, 1:] + truth[:, :, :1]
    between = valid & ~km
    err = np.linalg.norm(world[:, :, 1:] - true_world, axis=-1).mean(-1)[between]
    out = {"window_error": [float(err.mean())] if err.size else []}
    feet = task.val_pool.foot_joints
    if len(feet):
        up = 1 if task.skeleton.up_axis == "Y" else 2
        ground = [x for x in range(3) if x != up]
        w = world[:, :, feet][..., ground]
        speed = np.linalg.norm(np.diff(w, axis=1), axis=-1) * task.corpus.fps
        both = a["contact"][:, 1:] & a["contact"][:, :-1]
        if both.any():
            out["window_foot_speed"] = [float(speed[both].mean())]
    return out
