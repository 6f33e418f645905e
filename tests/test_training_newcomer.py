"""Training as a newcomer meets it (issue 48): progress lines off a terminal, the cache folder chosen by
``KEYFILL_CACHE``, and no empty log file after an interrupt (a real SIGINT to a real ``keyfill train``)."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from synthetic_corpus import write_corpus

from keyfill import progress
from keyfill.cli.main import main
from keyfill.learn import corpus as corpus_module
from keyfill.learn import training

pytestmark = pytest.mark.usefixtures("one_torch_thread")

ROOT = Path(__file__).resolve().parents[1]
#: the tests' tiny transformer (tests/test_training.py)
TINY = {"model": {"layers": 1, "d_model": 16, "heads": 2, "ffn": 32, "dropout": 0.0, "max_frames": 65},
        "training": {"epochs": 2, "batch_size": 8, "lr": 2e-3, "warmup_epochs": 0.2, "decay_every": 1,
                     "window": 65, "window_offset": 20, "val_fraction": 0.25, "val_lengths": [5]}}
#: a model whose first epoch takes many seconds (one window per step, a window every frame): time to interrupt it
SLOW = {"model": {**TINY["model"], "d_model": 64, "ffn": 256, "layers": 2},
        "training": {**TINY["training"], "batch_size": 1, "window_offset": 1}}
#: a progress line: where the loop is, the loss, the time so far and the time left
LINE = re.compile(r"^training: epoch (\d+)/(\d+), (step \d+/\d+|starting|validating|writing the model)(, loss [0-9.e+-]+)?; "
                  r"(\d+ s|\d+ min \d\d s) so far, (about (\d+ s|\d+ min \d\d s) left|time left not known yet)$")


@pytest.fixture(scope="module")
def corpus_dir(tmp_path_factory):
    folder = tmp_path_factory.mktemp("walkers")
    write_corpus(folder, styles=("happy", "tired"), clips_per_style=2, frames=(100, 130), seed=5)
    return folder


def _config(folder: Path, name: str, config: dict) -> Path:
    path = folder / f"{name}.json"
    path.write_text(json.dumps(config))
    return path


@pytest.fixture(autouse=True)
def private_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("KEYFILL_CACHE", str(tmp_path / "cache"))


def test_off_a_terminal_training_prints_progress_lines_with_epoch_loss_and_time_left(corpus_dir, tmp_path,
                                                                                     capsys, monkeypatch):
    """stderr is not a terminal here (captured): no bar, but a line every LINE_EVERY_S seconds."""
    monkeypatch.setattr(training, "LINE_EVERY_S", 0.02)
    config = _config(tmp_path, "tiny", {**TINY, "training": {**TINY["training"], "epochs": 4}})
    assert main(["train", "transformer", str(corpus_dir), "-o", str(tmp_path / "m"), "--config", str(config),
                 "--threads", "1"]) == 0
    err = capsys.readouterr().err.splitlines()
    lines = [line for line in err if line.startswith("training: epoch")]
    assert len(lines) >= 3, err
    for line in lines:
        assert LINE.match(line), line
    epochs = [int(LINE.match(line).group(1)) for line in lines]
    assert epochs == sorted(epochs) and max(epochs) <= 4
    assert any("loss" in line and "left" in line and "not known" not in line for line in lines), lines


def test_on_a_terminal_or_in_the_library_no_lines_are_printed(corpus_dir, tmp_path, capsys, monkeypatch):
    """The library prints nothing by itself; with -q the CLI prints no progress line either."""
    monkeypatch.setattr(training, "LINE_EVERY_S", 0.02)
    config = _config(tmp_path, "tiny", TINY)
    assert main(["-q", "train", "transformer", str(corpus_dir), "-o", str(tmp_path / "m"), "--config", str(config),
                 "--threads", "1"]) == 0
    assert capsys.readouterr().err == ""


def test_the_ticker_tells_time_so_far_and_left(monkeypatch):
    now = [100.0]
    monkeypatch.setattr(progress.time, "monotonic", lambda: now[0])
    said = []
    ticker = progress.Ticker(said.append, every=3600)
    with ticker:
        assert ticker.line() == "starting; 0 s so far, time left not known yet"
        now[0] += 90
        ticker.set(0.25, "training: epoch 1/4, step 5/5")
        assert ticker.line() == "training: epoch 1/4, step 5/5; 1 min 30 s so far, about 4 min 30 s left"
        now[0] += 7200
        ticker.set(0.5, "x")
        assert ticker.line() == "x; 2 h 01 min so far, about 2 h 01 min left"
    assert said == []  # an hour between lines: none within the block, and none after it
    assert not ticker._thread.is_alive()
    assert [progress.duration(s) for s in (0, 59.4, 60, 3599, 3600, 86400)] == \
        ["0 s", "59 s", "1 min 00 s", "59 min 59 s", "1 h 00 min", "24 h 00 min"]


def test_keyfill_cache_chooses_the_cache_folder(corpus_dir, tmp_path, monkeypatch):
    """The one place that decides: KEYFILL_CACHE, else $XDG_CACHE_HOME/keyfill; writing an entry says where."""
    monkeypatch.setattr(corpus_module, "CACHE_AFTER_S", -1.0)  # cache even a corpus that reads in no time
    notes = []
    progress.listen_notes(notes.append)
    try:
        monkeypatch.setenv("KEYFILL_CACHE", str(tmp_path / "mine"))
        corpus_module.load_corpus([corpus_dir])
    finally:
        progress.listen_notes(None)
    entries = list((tmp_path / "mine").glob("corpus-*.npz"))
    assert len(entries) == 1
    assert len(notes) == 1 and str(entries[0]) in notes[0] and "KEYFILL_CACHE" in notes[0]

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    for unset in (lambda: monkeypatch.delenv("KEYFILL_CACHE"), lambda: monkeypatch.setenv("KEYFILL_CACHE", "")):
        unset()
        assert corpus_module.cache_dir() == tmp_path / "xdg" / "keyfill"
    corpus_module.load_corpus([corpus_dir])
    assert len(list((tmp_path / "xdg" / "keyfill").glob("corpus-*.npz"))) == 1


@pytest.fixture(scope="module")
def earlier(corpus_dir, tmp_path_factory):
    """A folder with a finished run's model, checkpoint and log (``m``, ``m.checkpoint.pt``, ``m.log.jsonl``)."""
    folder = tmp_path_factory.mktemp("earlier")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("KEYFILL_CACHE", str(folder.parent / "earlier-cache"))
        assert main(["-q", "train", "transformer", str(corpus_dir), "-o", str(folder / "m"), "--config",
                     str(_config(folder.parent, "earlier", TINY)), "--threads", "1"]) == 0
    return folder


def _train_process(corpus_dir: Path, config: Path, out: Path, env: dict) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "keyfill", "train", "transformer", str(corpus_dir), "-o", str(out), "--config",
         str(config), "--threads", "1"], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _wait_for(proc: subprocess.Popen, text: str, timeout: float = 120.0) -> str:
    """Read proc's stderr until a line holds ``text``; returns what was read."""
    seen = ""
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        line = proc.stderr.readline()
        if not line:
            break
        seen += line
        if text in line:
            return seen
    raise AssertionError(f"no line with {text!r} in {seen!r}")


@pytest.mark.parametrize("moment,folders", [("start-up", ("fresh",)), ("first epoch", ("fresh", "earlier"))])
def test_sigint_before_the_first_epoch_ends_leaves_no_log_and_keeps_the_last_runs(corpus_dir, earlier, tmp_path,
                                                                                   moment, folders):
    """A finished run's model and log stay as they were when a new run into the same folder is interrupted
    before its first epoch ends; without an earlier run, nothing at all is left (no empty log)."""
    env = {**os.environ, "OMP_NUM_THREADS": "1", "KEYFILL_CACHE": str(tmp_path / "cache")}
    slow = _config(tmp_path, "slow", SLOW)
    log_before = (earlier / "m.log.jsonl").read_bytes()
    assert log_before.count(b"\n") == 2
    for folder in (earlier if name == "earlier" else tmp_path / name for name in folders):
        folder.mkdir(exist_ok=True)
        before = {p.name: p.stat().st_mtime_ns for p in folder.iterdir()}
        proc = _train_process(corpus_dir, slow, folder / "m", env)
        try:
            if moment == "start-up":
                time.sleep(1.0)  # importing torch, reading the clips
            else:
                _wait_for(proc, "training on")  # the data is read; the first epoch is under way
                time.sleep(0.3)
            proc.send_signal(signal.SIGINT)
            _, err = proc.communicate(timeout=60)
        finally:
            proc.kill()
        assert proc.returncode == 128 + signal.SIGINT, err
        assert err.splitlines()[-1] == "keyfill: error: interrupted", err
        assert {p.name: p.stat().st_mtime_ns for p in folder.iterdir()} == before
    assert (earlier / "m.log.jsonl").read_bytes() == log_before
    assert list((tmp_path / "fresh").iterdir()) == []


def test_the_log_is_written_from_the_first_finished_epoch(corpus_dir, tmp_path):
    """Interrupted after its first epochs, a run leaves the log of its finished epochs (and a checkpoint);
    --resume continues it, rewriting the log from the checkpoint's rows: it then has every epoch once."""
    env = {**os.environ, "OMP_NUM_THREADS": "1", "KEYFILL_CACHE": str(tmp_path / "cache")}
    config = _config(tmp_path, "slowish", {**TINY, "training": {**TINY["training"], "epochs": 400}})
    proc = _train_process(corpus_dir, config, tmp_path / "m", env)
    try:
        _wait_for(proc, "epoch 2:")  # the transformer's line after each epoch: epoch 1's checkpoint is written
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 128 + signal.SIGINT, err
    rows = [json.loads(line) for line in (tmp_path / "m.log.jsonl").read_text().splitlines()]
    assert rows and [r["epoch"] for r in rows] == list(range(1, len(rows) + 1))
    assert (tmp_path / "m.checkpoint.pt").is_file() and not (tmp_path / "m").exists()
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []
    done = rows[-1]["epoch"]
    assert main(["-q", "train", "transformer", str(corpus_dir), "-o", str(tmp_path / "m"), "--config", str(config),
                 "--threads", "1", "--resume", "--epochs", str(done + 1)]) == 0
    rows = [json.loads(line) for line in (tmp_path / "m.log.jsonl").read_text().splitlines()]
    assert [r["epoch"] for r in rows] == list(range(1, done + 2))
