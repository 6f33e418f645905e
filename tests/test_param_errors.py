"""Issue 27: library errors name the Python parameter (``key_every``), the CLI writes it as its flag (``--key-every``).

A Python caller reads the parameter it passed, and ``params`` lists it; a shell user reads the same message with
each listed parameter written as the flag that gives it (:func:`keyfill.cli.common.flag_words`).
"""

from __future__ import annotations

import json
import pickle
from pathlib import Path

import conftest
import numpy as np
import pytest
import torch
from conftest import DATA, run
from synthetic_corpus import walker_motion, walker_skeleton

from keyfill import io, limits, parallel, viz
from keyfill.cli.common import flag, flag_words
from keyfill.cli.main import main
from keyfill.errors import DataError, KeyfillError, UsageError
from keyfill.io.batch import failure
from keyfill.io.batch_record import Item
from keyfill.motion import Keys, Motion, Skeleton

MIXAMO = DATA / "bvhtoolbox_test_freebvh_mixamo.bvh"
HUMAN_KEYS = Path(__file__).parent.parent / "examples" / "human" / "keys_15.usda"
LAMP_MODEL = Path(__file__).parent.parent / "keyfill" / "learn" / "models" / "lamp-arnn"


def one_error_line(err: str) -> str:
    """The message of the one ``keyfill: error:`` line of ``err``."""
    return conftest.one_error_line(err).removeprefix("keyfill: error: ")


def unkeyed() -> Motion:
    return io.load(MIXAMO).replace(keys=None)


def _library_cases(tmp_path):
    from keyfill.learn import onnx, registry
    from keyfill.learn.arnn.task import Settings
    from keyfill.learn.completion import CompleteOptions
    from keyfill.learn.gan.dna import parse_dna
    from keyfill.learn.protocols import choose_protocol
    from keyfill.learn.training import train
    from keyfill.sim.runner import simulate
    from keyfill.viz import gif, stick

    m = unkeyed()
    keys = Keys.every(10, m.num_frames)
    return [
        (lambda: Keys.resolve(m, key_every=0), "key_every must be at least 1, got 0", ("key_every",)),
        (lambda: Keys.resolve(m, keys_text="0,a"), "keys_text takes frame numbers separated by commas",
         ("keys_text",)),
        (lambda: Keys.resolve(m, "0,5", 3), "give keys_text or key_every, not both", ("keys_text", "key_every")),
        (lambda: Keys.resolve(m), "this file records no keys; give keys_text (e.g. 0,12,30) or key_every N",
         ("keys_text", "key_every")),
        (lambda: Keys.every(0, 10), "step must be at least 1, got 0", ("step",)),
        (lambda: limits.check_seed(-1), "seed must be between 0 and 2**63-1, got -1", ("seed",)),
        (lambda: CompleteOptions(seed=-1), "seed must be between 0 and 2**63-1, got -1", ("seed",)),
        (lambda: simulate(tmp_path / "hops", count=0), "count must be at least 1, got 0", ("count",)),
        (lambda: simulate(tmp_path / "hops", count=1, iterations=0), "iterations must be at least 1, got 0",
         ("iterations",)),
        (lambda: simulate(tmp_path / "hops", count=1, max_runs=0), "max_runs must be at least 1, got 0",
         ("max_runs",)),
        (lambda: parallel.check_options(0), "workers must be between 1 and 1,024, got 0", ("workers",)),
        (lambda: parallel.check_options(None, connect_timeout=0), "connect_timeout must be positive",
         ("connect_timeout",)),
        (lambda: Settings(lr=0.0).check(), "lr must be a positive number, got 0.0", ("lr",)),
        (lambda: Settings(batch_size=0).check(), "batch_size must be at least 1, got 0", ("batch_size",)),
        (lambda: Settings(key_loss="max").check(), "key_loss must be mean or sum, not 'max'", ("key_loss",)),
        (lambda: train(None, tmp_path / "model", resume=True), "resume: no checkpoint None", ("resume",)),
        (lambda: registry.complete(m, keys, "cubic", CompleteOptions(dna="x.bvh")),
         "dna and dna_count apply to methods with Motion DNA", ("dna", "dna_count")),
        (lambda: registry.complete(m, keys, "cubic", CompleteOptions(model=str(tmp_path))),
         "model applies to learned methods, not to 'cubic'", ("model",)),
        (lambda: onnx.select(registry.get("arnn"), "x.onnx", "torch"),
         "x.onnx: an ONNX graph runs with runtime onnx (or auto), not torch", ("runtime",)),
        (lambda: onnx.select(registry.get("arnn"), None, "jit"), "runtime is one of", ("runtime",)),
        (lambda: choose_protocol(str(LAMP_MODEL), ["clips"], "lafan1"), "is scored with protocol keys, not lafan1",
         ("protocol",)),
        (lambda: parse_dna("x.bvh:a"), "dna takes FILE or FILE:FRAMES", ("dna",)),
        (lambda: parse_dna("x.bvh:"), "dna 'x.bvh:' lists no frames", ("dna",)),
        (lambda: viz.frame_range("30:40", 24, "walk"), "frames 30:40 selects no frame of walk (frames 0-23)",
         ("frames",)),
        (lambda: viz.check_suffix("o.jpg", viz.PLOT_SUFFIXES), "output o.jpg: unsupported picture type '.jpg'",
         ("output",)),
        (lambda: stick.preview([m], ["m"], tmp_path / "o.gif", size=(8, 8)),
         "size 8x8: each side must be 16 to 8192 pixels", ("size",)),
        (lambda: stick.preview([m], ["m"], tmp_path / "o.gif", step=0), "step must be between 1 and", ("step",)),
        (lambda: gif.delays_ms(2, 1e-6), "(give a higher fps or a smaller step)", ("fps", "step")),
    ]


def test_library_errors_name_the_python_parameter(tmp_path):
    for fn, text, params in _library_cases(tmp_path):
        with pytest.raises(KeyfillError) as caught:
            fn()
        message = str(caught.value)
        assert text in message and caught.value.params == params, (text, message, caught.value.params)
        assert "--" not in message, message
    assert list(tmp_path.iterdir()) == []  # nothing was written


def test_flag_words_writes_the_first_mention_of_each_parameter_as_its_flag():
    assert flag("key_every") == "--key-every" and flag("keys_text") == "--keys" and flag("chunk") == "--batch-size"
    assert flag("output") == "-o" and flag("lr") == "--lr"
    assert flag_words("give keys_text or key_every, not both", ("keys_text", "key_every")) == \
        "give --keys or --key-every, not both"
    # later words that spell a parameter are the message's own
    assert flag_words("fps: the frame rate 1e+308 fps is outside", ("fps",)) == \
        "--fps: the frame rate 1e+308 fps is outside"
    assert flag_words("resume: m.ckpt was made with other settings (seed 0, now 3); give the same options to resume",
                      ("resume", "seed")) == \
        "--resume: m.ckpt was made with other settings (--seed 0, now 3); give the same options to resume"
    # only whole words: not part of a name, a path or a longer word
    assert flag_words("dna_count and data/dna.bvh need dna", ("dna",)) == "dna_count and data/dna.bvh need --dna"
    assert flag_words("seed must be between 0 and 2**63-1", ()) == "seed must be between 0 and 2**63-1"


def test_params_survive_pickling_and_batch_outcomes():
    e = pickle.loads(pickle.dumps(UsageError("key_every must be at least 1, got 0", params="key_every")))
    assert e.params == ("key_every",) and str(e) == "key_every must be at least 1, got 0"
    out = failure(Item("a.bvh", "out/a.bvh"), e)
    assert out["error"] == "a.bvh: key_every must be at least 1, got 0" and out["params"] == ["key_every"]
    assert "params" not in failure(Item("a.bvh", "out/a.bvh"), DataError("a.bvh: no frames"))


# --- the CLI: the same messages as before, in flags ---------------------------------------------------------


def _static_motion(frames: int = 3) -> Motion:
    """A root with only position channels and a child with none: nothing moves."""
    sk = Skeleton(["Root", "Tip"], [-1, 0], [[0, 0, 0], [0, 10, 0]],
                  [("Xposition", "Yposition", "Zposition"), ()], end_sites=())
    return Motion(sk, 30.0, np.tile([1.0, 0, 0, 0], (frames, 2, 1)), np.tile(sk.offsets, (frames, 1, 1)))


@pytest.fixture()
def files(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    io.save(unkeyed(), tmp_path / "a.bvh")
    io.save(unkeyed(), tmp_path / "b.bvh")
    io.save(_static_motion(), tmp_path / "still.bvh", bvh_layout="source")  # no rotation channel
    (tmp_path / "x.onnx").write_bytes(b"")
    (tmp_path / "folder").mkdir()
    return tmp_path


M = str(MIXAMO)
CLI = [
    (["complete", M, "-o", "o.bvh", "--key-every", "0"], "--key-every must be at least 1, got 0"),
    (["complete", M, "-o", "o.bvh", "--keys", "0,5", "--key-every", "3"], "give --keys or --key-every, not both"),
    (["complete", "a.bvh", "-o", "o.bvh"], "this file records no keys; give --keys (e.g. 0,12,30) or --key-every N"),
    (["complete", M, M, "-o", "out", "--key-every", "10", "--scheduler", "foo://x:1"],
     "--scheduler 'foo://x:1' is not a scheduler address like tcp://host:8786"),
    (["simulate", "-o", "hops", "--count", "1", "--max-runs", "0"], "--max-runs must be at least 1, got 0"),
    (["train", "arnn", M, "-o", "model", "--lr", "0"], "--lr must be a positive number, got 0.0"),
    (["train", "arnn", M, "-o", "model", "--batch-size", "0"], "--batch-size must be at least 1, got 0"),
    (["train", "arnn", M, "-o", "model", "--checkpoint-every", "0"], "--checkpoint-every must be at least 1, got 0"),
    (["train", "transformer", M, "-o", "model", "--checkpoint-every", "1"],
     "the transformer writes a checkpoint after every epoch; --checkpoint-every does not apply"),
    (["complete", M, "-o", "o.bvh", "--key-every", "10", "--method", "cubic", "--dna", "x.bvh"],
     "--dna and --dna-count apply to methods with Motion DNA (gan), not to 'cubic'"),
    (["complete", M, "-o", "o.bvh", "--key-every", "10", "--method", "cubic", "--model", "folder"],
     "--model applies to learned methods, not to 'cubic'"),
    (["complete", M, "-o", "o.bvh", "--key-every", "10", "--method", "arnn", "--model", "x.onnx", "--runtime",
      "torch"], "x.onnx: an ONNX graph runs with --runtime onnx (or auto), not torch"),
    (["complete", str(HUMAN_KEYS), "-o", "o.usda", "--method", "gan", "--dna", "x.bvh:a"],
     "--dna takes FILE or FILE:FRAMES with frames separated by commas; got 'x.bvh:a'"),
    (["complete", str(HUMAN_KEYS), "-o", "o.usda", "--method", "gan", "--dna", "x.bvh:"],
     "--dna 'x.bvh:' lists no frames"),
    (["plot", "still.bvh", "-o", "p.png"], "nothing to plot: no channel of this motion is animated; try --positions",
     1),
    (["plot", "still.bvh", "-o", "p.png", "--joints", "Tip"], "joint Tip has no animated channels; try --positions"),
    (["plot", M, "-o", "p.png", "--channels", "Xrotation,Yrotation"],
     "110 panels is too many for one figure (at most 64); choose fewer with --joints or --channels"),
    (["plot", M, "-o", "p.jpg"], "-o p.jpg: unsupported picture type '.jpg'; expected .png, .svg, .pdf"),
    (["preview", M, "-o", "o.gif", "--fps", "1e-6"], "(give a higher --fps or a smaller --step)"),
    (["preview", M, "-o", "o.gif", "--size", "8x8"], "--size 8x8: each side must be 16 to 8192 pixels"),
]


@pytest.mark.parametrize("args,message,code", [c if len(c) == 3 else (*c, 2) for c in CLI],
                         ids=[" ".join(c[0][:1] + c[0][-2:]) for c in CLI])
def test_cli_messages_keep_their_flags(files, capsys, args, message, code):
    if "--scheduler" in args:
        pytest.importorskip("distributed")
    got, _, err = run(capsys, *args)
    assert got == code and message in one_error_line(err), err
    assert sorted(p.name for p in files.iterdir()) == ["a.bvh", "b.bvh", "folder", "still.bvh", "x.onnx"]


def test_too_many_gif_frames_names_step_and_frames(files, capsys):
    io.save(walker_motion(walker_skeleton(), 5001, np.random.default_rng(0)), files / "long.bvh")
    code, _, err = run(capsys, "preview", "long.bvh", "-o", "o.gif")
    assert code == 2 and "GIF images is too many (at most 5000); use --step or --frames" in one_error_line(err)


def test_a_missing_gpu_names_the_device_flag(files, capsys):
    if torch.cuda.is_available():
        pytest.skip("this machine has a GPU")
    code, _, err = run(capsys, "complete", HUMAN_KEYS, "-o", "o.usda", "--method", "gan", "--device", "cuda")
    assert code == 2 and one_error_line(err) == ("'cuda' was asked for, but torch sees no CUDA GPU here; "
                                                 "use --device cpu")


def test_a_graph_runs_on_the_cpu_only(files, capsys):
    code, _, err = run(capsys, "complete", HUMAN_KEYS, "-o", "o.usda", "--method", "gan", "--runtime", "onnx",
                       "--device", "cuda")
    assert code == 2 and one_error_line(err) == "--device cuda needs --runtime torch: an ONNX graph runs on the CPU"


def test_batch_error_lines_and_json_write_flags(files, capsys):
    code, out, err = run(capsys, "complete", "a.bvh", "b.bvh", "-o", "out/", "--key-every", "0", "--json")
    lines = err.strip().splitlines()
    assert code == 1 and lines == [f"keyfill: error: {f}.bvh: --key-every must be at least 1, got 0" for f in "ab"]
    summary = json.loads(out)
    assert [f["error"] for f in summary["files"]] == [f"{f}.bvh: --key-every must be at least 1, got 0" for f in "ab"]
    assert all("params" not in f for f in summary["files"])
    code, _, err = run(capsys, "complete", "a.bvh", "b.bvh", "-o", "out/")
    assert code == 1 and err.splitlines()[0] == ("keyfill: error: a.bvh: this file records no keys; give --keys "
                                                 "(e.g. 0,12,30) or --key-every N")


def test_edit_files_name_the_frame_flag(files, capsys):
    from test_edit_character import character

    io.save(character(), files / "wave.bvh")
    assert main(["convert", "wave.bvh", "wave.usda", "--curves", "--keys", "0,10,20,30,40"]) == 0
    (files / "pose.toml").write_text("[[edit]]\njoint = 'Hand_L'\nmove = [0, 6, 0]\n")
    (files / "at10.toml").write_text("[[edit]]\njoint = 'Hand_L'\nframe = 10\nmove = [0, 6, 0]\n")
    capsys.readouterr()
    code, _, err = run(capsys, "pose", "wave.usda", "--edit", "pose.toml", "--frame", 55, "-o", "posed.usda")
    assert code == 1
    assert one_error_line(err) == "pose.toml:1: edit 1: --frame 55 is outside the curves (keys from 0 to 40)"
    code, _, err = run(capsys, "pose", "wave.usda", "--edit", "at10.toml", "--frame", 30, "-o", "posed.usda")
    assert code == 1 and one_error_line(err) == "at10.toml:1: edit 1: --frame is 30 but this edit is at frame 10"
    # the edit file's own frame field stays a word of the file
    code, _, err = run(capsys, "pose", "wave.usda", "--edit", "at10.toml", "--frame", 10, "-o", "posed.usda")
    assert code == 0, err
    (files / "at55.toml").write_text("[[edit]]\njoint = 'Hand_L'\nframe = 55\nmove = [0, 6, 0]\n")
    code, _, err = run(capsys, "pose", "wave.usda", "--edit", "at55.toml", "-o", "posed.usda")
    assert code == 1 and "edit 1: frame 55 is outside the curves" in one_error_line(err)


def _raises_naming_flags() -> list[str]:
    """``file:line`` of every ``raise`` outside keyfill/cli whose message text names a ``--flag``."""
    import ast
    import re

    root = Path(__file__).resolve().parents[1] / "keyfill"
    found = []
    for path in sorted(root.rglob("*.py")):
        if path.relative_to(root).parts[0] == "cli":
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Raise) and node.exc is not None:
                text = " ".join(c.value for c in ast.walk(node.exc)
                                if isinstance(c, ast.Constant) and isinstance(c.value, str))
                if re.search(r"(?<![\w-])--[a-z]", text):
                    found.append(f"{path.relative_to(root.parent)}:{node.lineno}")
    return found


def test_at_most_five_library_raises_name_a_flag():
    found = _raises_naming_flags()
    assert len(found) <= 5, found  # hints to run another command may name its flags; the rest name parameters
