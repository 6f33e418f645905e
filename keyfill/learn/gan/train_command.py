"""``keyfill train gan``: its options, help and lines, around :class:`~keyfill.learn.gan.task.GanTask`."""

from __future__ import annotations

import os

from keyfill.errors import UsageError
from keyfill.files import read_json_object
from keyfill.learn.gan.config import DNA_WIDTHS, SPARSE_RECEPTIVE_FIELD, GanConfig
from keyfill.learn.gan.task import STAGES, GanTask
from keyfill.learn.training import Option, TrainingSpec


def read_config(path: str | os.PathLike | None, preset: str = "cpu", seed: int = 0, dna: bool = False,
                partial_keys: bool = False) -> GanConfig:
    """The :class:`GanConfig` of preset ``preset`` with the settings of the JSON file ``path`` (if any) and ``seed``.

    The file is one object of :class:`GanConfig` fields; its ``"preset"`` (without
    ``"widths"``) picks the widths of that preset instead. ``dna`` (``--dna``) gives a config without a
    Motion DNA encoder the preset's (``DNA_WIDTHS``); ``partial_keys`` (``--partial-keys``) turns partial keys
    on, with ``max_gap`` at most the sparse format's receptive field. Both apply before the settings are
    checked, so a file may hold settings that need them (``dna_norm``, ``sketch_stretch``).
    """
    data = {} if path is None else read_json_object(path)
    preset = data.pop("preset", preset) if "widths" not in data else data.get("preset", "custom")
    if dna and not data.get("dna_width"):
        width = DNA_WIDTHS.get(preset, DNA_WIDTHS["cpu"])
        data.update(style_dim=data.get("style_dim") or width, dna_width=width)
    if partial_keys and not data.get("partial_keys"):
        data.update(partial_keys=True, max_gap=min(data.get("max_gap", GanConfig.max_gap), SPARSE_RECEPTIVE_FIELD))
    try:
        return GanConfig.from_preset(preset, **data, seed=seed) if "widths" not in data else \
            GanConfig.from_json({**data, "seed": seed})
    except (TypeError, UsageError) as e:  # name the file a bad setting came from
        raise UsageError(f"{path}: {e}" if path is not None else str(e), params=getattr(e, "params", ())) from None


def _make_task(common, options: dict, progress) -> GanTask:
    """The task of ``keyfill train gan``: the BVH clips in DATA, chosen by --include / --exclude."""
    from keyfill.learn.corpus import load_corpus

    cfg = read_config(options["config"], options["preset"], common.seed, options["dna"], options["partial_keys"])
    corpus = load_corpus(common.data, fold=options["fold_root"],
                         progress=lambda f: progress(f, desc="reading clips", unit="file"))
    corpus = corpus.select(options["include"], options["exclude"])
    return GanTask(corpus, cfg, options["stage"], options["path_model"], common.epochs, common.checkpoint_every or 1)


def _started(task: GanTask) -> str:
    what = ("the global path predictor" if task.stage == "path" else
            f"the local motion generator over the {task.cfg.base} base," if task.cfg.base != "none" else
            "the local motion generator, path predictor frozen,")
    return (f"training {what} with {task.cfg.preset} widths on {len(task.train_clips)} clips, validating on "
            f"{len(task.val_clips)}; {task.epochs} epochs of {task.cfg.steps_per_epoch} steps")


def _epoch_line(row: dict) -> str:
    if "loss_path" in row:
        val = f", held-out {row['path_loss']:.4f}" if "path_loss" in row else ""
        return f"epoch {row['epoch']}: Eq. 5 loss {row['loss_path']:.4f} m^2{val}"
    val = (f", held-out key errors: joints {row['key_joint_error']:.2f}, root {row['key_root_error']:.2f} "
           "(file units)") if "key_joint_error" in row else ""
    return (f"epoch {row['epoch']}: generator {row['loss_generator']:.4f}, discriminator {row['loss_d_adv']:.4f}"
            f"{val}")


def _finished(task: GanTask, outcome) -> tuple[dict, str]:
    summary = {"output": str(outcome.output), "checkpoint": str(outcome.checkpoint), "log": str(outcome.log),
               "stage": task.stage, "steps": task.step_count}
    nxt = "" if task.stage == "generator" else \
        f"; next: keyfill train gan DATA --stage generator --path-model {outcome.output} -o MODEL"
    return summary, f"wrote {outcome.output} (checkpoint {outcome.checkpoint}, log {outcome.log}){nxt}"


TRAINING = TrainingSpec(
    help="""Train a generative tweening GAN (Zhou et al. 2020) on the BVH clips in DATA, in two stages.

    Stage "path" trains the global path predictor on whole clips (Eq. 5) and
    writes a gan model folder holding only it. Stage "generator" loads that
    folder (--path-model), freezes the predictor and trains the local motion
    generator against a discriminator on long sequences whose keys come from
    several clips. The result completes motions: keyfill complete --method gan.
    A config with a base (benchmarks/gan_recipe3.json: the generator corrects
    the cubic spline, whose root path it keeps) trains the generator stage
    alone, without --path-model.

    \b
    Examples:
      keyfill train gan bandai2/data -o models/gan-path --stage path
      keyfill train gan bandai2/data -o models/gan --stage generator --path-model models/gan-path
      keyfill train gan bandai2/data -o models/gan --stage generator --path-model models/gan-path --resume
      keyfill train gan bandai2/data -o models/gan-dna --stage generator --path-model models/gan-path --dna \\
          --partial-keys
      keyfill train gan bandai2/data -o models/gan-spline --stage generator --config benchmarks/gan_recipe3.json --dna
    """,
    options=(
        Option("stage", "path", "Which stage to train: the path predictor, or the generator.",
               choices=STAGES),
        Option("path_model", None, "The gan model folder of the path stage (the generator stage needs it, "
               "unless its config has a base).", metavar="FOLDER"),
        Option("preset", "cpu", "Layer widths: 'cpu' (small, trains on a CPU) or 'paper' (Table 5).",
               choices=("cpu", "paper")),
        Option("config", None, "JSON file of gan settings overriding the preset's (see docs/gan.md).", type="file"),
        Option("include", (), "Train only on files matching one of these patterns.", multiple=True, metavar="GLOB"),
        Option("exclude", (), "Leave out files matching these patterns (e.g. a test style).", multiple=True,
               metavar="GLOB"),
        Option("dna", False, "Give the generator a Motion DNA encoder (style_dim and its width from the preset: "
               "cpu 128, paper 1024) trained with Eqs. 11-12; complete then takes --dna.", flag=True),
        Option("partial_keys", False, "Train on partial keys too (root paths, half bodies, 2-D keys) with the "
               "sparse input format; max_gap becomes at most 318 frames.", flag=True),
        Option("fold_root", None, "Fold a static top joint (like Bandai's joint_Root) into the hips. "
               "Default: when it is static.", flag=True),
    ),
    make_task=_make_task,
    started=_started,
    finished=_finished,
    threads=1,
    epoch_line=_epoch_line,
)
