"""``keyfill simulate`` folders: determinism, resuming, Dask, bad input, reading them back."""

from __future__ import annotations

import json
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from keyfill.characters.lamp import is_lamp, to_variables
from keyfill.cli.main import main
from keyfill.errors import DataError
from keyfill.io.hops import read_dataset, read_manifest
from keyfill.sim import runner

FAST = ["--iterations", "3"]


def snapshot(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


def simulate(args: list[str], capsys=None) -> tuple[int, str, str]:
    rc = main(["simulate", *args])
    out, err = capsys.readouterr() if capsys else ("", "")
    return rc, out, err


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> Path:
    """Four sequences, seed 0, 3 iterations, built in this process."""
    folder = tmp_path_factory.mktemp("sim") / "ref"
    assert main(["simulate", "-o", str(folder), "--count", "4", "--seed", "0", "--workers", "1", *FAST]) == 0
    return folder


def test_folder_contents(reference):
    names = sorted(p.name for p in reference.iterdir())
    records = read_manifest(reference)
    assert len(records) == 4
    assert names == sorted(["manifest.jsonl", "runs.jsonl", "simulate.json"] + [r["file"] for r in records])
    runs = [json.loads(line) for line in (reference / "runs.jsonl").read_text().splitlines()]
    assert [r["run"] for r in runs] == list(range(len(runs)))
    assert sum(r["accepted"] for r in runs) == 4 and runs[-1]["accepted"]
    config = json.loads((reference / "simulate.json").read_text())
    assert config["seed"] == 0 and config["iterations"] == 3 and config["format"] == "usd"
    for rec in records:
        assert rec["file"] == rec["id"] + ".usda" and rec["seed"] == 0
        assert rec["hops"] == 3 and rec["frames"] == 87 and len(rec["keys"]) == 9
        assert len(rec["controller"]["durations"]) == 4 and np.shape(rec["controller"]["poses"]) == (4, 3)
        assert rec["energy"] == pytest.approx(-(1 - rec["w_e"]) * rec["distance"] - rec["w_e"] * rec["max_height"])
        assert rec["settings"] == config["settings"]
        assert len(rec["frame_times"]) == 87 and rec["liftoff_frames"] == [0, 31, 62]


def test_a_record_replays_its_episode(reference):
    from keyfill.sim.controller import Controller
    from keyfill.sim.hops import analyse
    from keyfill.sim.physics import LampWorld
    from keyfill.sim.settings import Settings

    rec = read_manifest(reference)[1]
    settings = Settings()
    assert rec["settings"] == settings.to_dict()
    with LampWorld(settings) as world:
        episode = world.simulate(Controller.from_dict(rec["controller"]))
    hops = analyse(episode, settings)
    assert episode.times[hops.liftoffs].tolist() == rec["liftoff_times"]
    assert episode.times[hops.landings].tolist() == rec["landing_times"]
    assert (hops.distance, hops.max_height) == (rec["distance"], rec["max_height"])


def test_read_dataset(reference):
    seqs = read_dataset(reference)
    assert [s.id for s in seqs] == [r["id"] for r in read_manifest(reference)]
    for s in seqs:
        assert is_lamp(s.motion.skeleton) and s.motion.num_frames == 87
        assert s.motion.keys.to_list() == s.record["keys"]
        v = to_variables(s.motion)
        assert v.shape == (87, 6) and v[-1, 0] > v[0, 0]  # hops forward


def test_same_seed_same_bytes_with_two_workers(reference, tmp_path):
    folder = tmp_path / "two"
    assert main(["simulate", "-o", str(folder), "--count", "4", "--seed", "0", "--workers", "2", *FAST]) == 0
    assert snapshot(folder) == snapshot(reference)


def test_dask_local_cluster_gives_the_same_bytes(reference, tmp_path):
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cluster:
        summary = runner.simulate(tmp_path / "dask", 4, seed=0, iterations=3, scheduler=cluster.scheduler_address)
    assert summary.sequences == 4
    assert snapshot(tmp_path / "dask") == snapshot(reference)


def test_resume_recomputes_nothing(reference, tmp_path, monkeypatch):
    folder = tmp_path / "grow"
    computed: list[int] = []
    real = runner.run_job

    def counting(job, run):
        computed.append(run)
        return real(job, run)

    monkeypatch.setattr(runner, "run_job", counting)
    runner.simulate(folder, 2, seed=0, iterations=3, workers=1)
    first = list(computed)
    before = snapshot(folder)
    computed.clear()
    runner.simulate(folder, 4, seed=0, iterations=3, workers=1)
    assert not set(computed) & set(first)  # nothing recomputed
    after = snapshot(folder)
    for name, data in before.items():  # nothing lost or changed but the two lists
        if name not in ("manifest.jsonl", "runs.jsonl"):
            assert after[name] == data
    assert after == snapshot(reference)
    computed.clear()
    runner.simulate(folder, 3, seed=0, iterations=3, workers=1)  # already enough: nothing to do
    assert computed == [] and snapshot(folder) == after


def test_killed_build_resumes(reference, tmp_path):
    folder = tmp_path / "killed"
    cmd = [sys.executable, "-m", "keyfill", "simulate", "-o", str(folder), "--count", "4", "--seed", "0",
           "--workers", "1", "--iterations", "3", "--json"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    runs = folder / "runs.jsonl"
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and proc.poll() is None:
        if runs.is_file() and len(runs.read_text().splitlines()) >= 2:
            break
        time.sleep(0.01)
    proc.send_signal(signal.SIGKILL)
    assert proc.wait() == -signal.SIGKILL
    done = [json.loads(line) for line in runs.read_text().splitlines()]
    assert len(done) >= 2, "the build should have finished two runs before it was killed"
    assert len([p for p in folder.glob("seq_*.usda")]) < 4
    # A half-written line (a kill in the middle of a write) is ignored as well.
    with open(runs, "a") as f:
        f.write('{"run": 99, "acc')
    out = subprocess.run(cmd, capture_output=True, text=True, check=True)
    summary = json.loads(out.stdout)
    assert summary["new_runs"] >= 1 and summary["new_runs"] == summary["runs"] - len(done)  # nothing recomputed
    assert snapshot(folder) == snapshot(reference)


def test_bvh_format(tmp_path, capsys):
    folder = tmp_path / "bvh"
    rc, out, _err = simulate(["-o", str(folder), "--count", "1", "--format", "bvh", "--workers", "1", *FAST, "--json"],
                            capsys)
    assert rc == 0 and json.loads(out)["sequences"] == 1
    seqs = read_dataset(folder)
    assert seqs[0].path.suffix == ".bvh" and len(seqs[0].motion.keys) == 9  # keys from the manifest
    assert "HIERARCHY" in seqs[0].path.read_text()[:20]


@pytest.mark.parametrize(
    "args, message",
    [
        (["--count", "0"], "--count must be at least 1, got 0"),
        (["--seed", "-1"], "--seed must be between 0 and 2**63-1, got -1"),
        (["--workers", "0"], "--workers must be between 1 and 1,024, got 0"),
        (["--iterations", "0"], "--iterations must be at least 1, got 0"),
        (["--count", "many"], "'many' is not a valid integer"),
    ],
)
def test_bad_numbers(tmp_path, capsys, args, message):
    folder = tmp_path / "out"
    rc, _out, err = simulate(["-o", str(folder), *args], capsys)
    assert rc == 2
    assert err.startswith("keyfill: error: ") and message in err and len(err.strip().splitlines()) == 1
    assert not folder.exists()


def test_folder_of_another_configuration(reference, tmp_path, capsys):
    folder = tmp_path / "other"
    folder.mkdir()
    for name, data in snapshot(reference).items():
        (folder / name).write_bytes(data)
    before = snapshot(folder)
    rc, _out, err = simulate(["-o", str(folder), "--count", "4", "--seed", "1", *FAST], capsys)
    assert rc == 2 and "holds a dataset of a different configuration (seed 0 there, 1 now)" in err
    assert "--force" in err and snapshot(folder) == before
    rc, _out, err = simulate(["-o", str(folder), "--count", "4", "--seed", "0", "--iterations", "4"], capsys)
    assert rc == 2 and "iterations 3 there, 4 now" in err and snapshot(folder) == before
    rc, _out, err = simulate(["-o", str(folder), "--count", "1", "--seed", "1", "--workers", "1", *FAST, "--force"],
                            capsys)
    assert rc == 0
    assert json.loads((folder / "simulate.json").read_text())["seed"] == 1
    assert [r["seed"] for r in read_manifest(folder)] == [1]
    assert len([p for p in folder.iterdir() if p.suffix == ".usda"]) == 1  # the old sequences are gone


def test_foreign_folder_is_refused(tmp_path, capsys):
    folder = tmp_path / "mine"
    folder.mkdir()
    (folder / "notes.txt").write_text("keep me")
    rc, _out, err = simulate(["-o", str(folder), "--count", "1", *FAST], capsys)
    assert rc == 2 and "is not empty and is not a keyfill simulate folder" in err
    assert [p.name for p in folder.iterdir()] == ["notes.txt"]
    rc, _out, err = simulate(["-o", str(folder), "--count", "1", "--workers", "1", *FAST, "--force"], capsys)
    assert rc == 0 and (folder / "notes.txt").read_text() == "keep me"  # --force removes only its own files


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_unreachable_scheduler(tmp_path, capsys):
    folder = tmp_path / "out"
    address = f"tcp://127.0.0.1:{_free_port()}"
    start = time.monotonic()
    rc, _out, err = simulate(["-o", str(folder), "--count", "1", "--scheduler", address, "--connect-timeout", "1"],
                            capsys)
    assert time.monotonic() - start < 30
    assert rc == 2 and err.startswith(f"keyfill: error: cannot reach the --scheduler {address} within "
                                      "--connect-timeout 1 s")
    assert len(err.strip().splitlines()) == 1
    assert not folder.exists()


def test_empty_folder_is_not_a_dataset(tmp_path):
    with pytest.raises(DataError, match="holds no simulated sequences"):
        read_dataset(tmp_path)
    with pytest.raises(DataError, match="no such dataset folder"):
        read_dataset(tmp_path / "missing")
    (tmp_path / "manifest.jsonl").write_text("")
    with pytest.raises(DataError, match="holds no simulated sequences yet"):
        read_dataset(tmp_path)


def test_help_shows_an_example(capsys):
    rc = main(["simulate", "--help"])
    out = capsys.readouterr().out
    assert rc == 0 and "keyfill simulate -o data/hops --count 300 --seed 0" in out
    for option in ("--count", "--seed", "--iterations", "--workers", "--format", "--scheduler", "--force", "--json"):
        assert option in out


@pytest.mark.slow
def test_the_full_dataset_is_valid():
    """data/hops as built by `keyfill simulate -o data/hops --count 300 --seed 0` (skipped when absent)."""
    from keyfill.sim.hops import link_clearances
    from keyfill.sim.settings import Settings

    folder = Path(__file__).resolve().parents[1] / "data" / "hops"
    if not (folder / "manifest.jsonl").is_file():
        pytest.skip(f"needs {folder} (make -C examples hops)")
    s = Settings()
    seqs = read_dataset(folder)
    assert len(seqs) >= 300
    for seq in seqs:
        rec = seq.record
        assert rec["hops"] == 3 and seq.motion.num_frames == 87 and len(rec["keys"]) == 9
        assert rec["distance"] >= s.min_distance and rec["max_height"] >= s.min_height
        clear = link_clearances(to_variables(seq.motion), s.dimensions)
        tol = s.contact_tolerance + 1e-5  # USD keeps 32-bit floats
        assert np.all(clear[rec["liftoff_frames"], 0] <= tol) and np.all(clear[rec["landing_frames"], 0] <= tol)
        assert np.all(clear[rec["air_frames"], 0] > s.contact_tolerance - 1e-5)
        assert clear[:, 1:].min() > 0.0
