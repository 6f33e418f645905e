"""The CLI contract of issue 48: outputs named as what they hold, one exit code per kind of misuse in every
command, and one line naming the user's path when an output cannot be written. Each case checks the exit code,
the one ``keyfill: error:`` line and what the folder holds afterwards."""

from __future__ import annotations

import json
import os
import resource
import shutil
import subprocess
import sys

import pytest
from conftest import DATA, run

MIXAMO = DATA / "bvhtoolbox_test_freebvh_mixamo.bvh"


def one_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("keyfill: error: "), err
    assert "internal error" not in lines[0] and "Traceback" not in err
    return lines[0].removeprefix("keyfill: error: ")


def listing(folder) -> list[str]:
    """Every name under ``folder`` (hidden ones too), relative and sorted."""
    return sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*"))


@pytest.fixture()
def walks(tmp_path, monkeypatch):
    """``walk.bvh`` and ``b.bvh`` in an otherwise empty working folder."""
    monkeypatch.chdir(tmp_path)
    for name in ("walk.bvh", "b.bvh"):
        shutil.copy(MIXAMO, tmp_path / name)
    return tmp_path


# --- output names -------------------------------------------------------------------------------------


@pytest.mark.parametrize("args", [
    ("complete", "walk.bvh", "--key-every", "10", "--format", "usda", "-o", "out.bvh"),
    ("convert", "walk.bvh", "out.bvh", "--format", "usda"),
    ("convert", "walk.bvh", "out.usd", "--format", "usda"),  # .usd is written as crate: usda would be ignored
    ("complete", "walk.bvh", "--key-every", "10", "--format", "glb", "-o", "out.gltf"),
])
def test_a_format_that_contradicts_the_output_suffix_is_refused(walks, capsys, args):
    code, out, err = run(capsys, *args)
    line = one_line(err)
    fmt, dst = args[args.index("--format") + 1], next(a for a in args if a.startswith("out."))
    assert code == 2 and out == ""
    assert line.startswith(f"{dst}: --format {fmt} contradicts the suffix '{dst[3:]}'") and f".{fmt}" in line
    assert listing(walks) == ["b.bvh", "walk.bvh"]


def test_a_format_that_agrees_or_an_unknown_suffix_and_a_format_still_write(walks, capsys):
    code, _, err = run(capsys, "convert", "walk.bvh", "out.usda", "--format", "usda")
    assert code == 0, err
    code, _, err = run(capsys, "convert", "walk.bvh", "out.anim", "--format", "bvh")
    assert code == 0, err
    assert (walks / "out.anim").read_text().startswith("HIERARCHY")


@pytest.mark.parametrize("args", [
    ("complete", "walk.bvh", "b.bvh", "--key-every", "10", "-o", "single.bvh"),
    ("complete", ".", "--key-every", "10", "-o", "d2.bvh"),
    ("convert", "walk.bvh", "b.bvh", "-o", "single.usda"),
])
def test_a_file_name_for_several_outputs_is_refused(walks, capsys, args):
    code, _, err = run(capsys, *args)
    dst = args[-1]
    assert code == 2 and one_line(err).startswith(f"-o {dst}: a batch writes into an output folder")
    assert f"{dst}/" in err
    assert listing(walks) == ["b.bvh", "walk.bvh"]
    # the same name as a folder is a folder
    code, _, err = run(capsys, *args[:-1], dst + "/")
    assert code == 0, err
    assert listing(walks / dst) == [".keyfill-outputs.json", "b.bvh", "walk.bvh"]  # the inputs' names


def test_a_folder_input_never_takes_an_output_folder_as_input(walks, capsys):
    for outdir in ("d1/", "d2/", "sub/d3/"):
        code, out, err = run(capsys, "complete", ".", "--key-every", "10", "-o", outdir, "--json")
        assert code == 0, err
        assert sorted(json.loads(out)["input"]) == ["b.bvh", "walk.bvh"], outdir
    assert listing(walks / "sub" / "d3") == [".keyfill-outputs.json", "b.bvh", "walk.bvh"]
    # an output folder named as an input is an input
    code, out, err = run(capsys, "convert", "d1", "-o", "u/", "--format", "usda")
    assert code == 0, err
    assert listing(walks / "u") == [".keyfill-outputs.json", "b.usda", "walk.usda"]


def test_a_folder_with_no_motion_files_is_named(walks, capsys):
    (walks / "adir").mkdir()
    (walks / "adir" / "notes.txt").write_text("no motion here")
    code, _, err = run(capsys, "complete", "adir", "--key-every", "3", "-o", "x/")
    assert code == 2 and one_line(err).startswith("adir: no motion files (.bvh, ") and "in this folder" in err
    code, _, err = run(capsys, "complete", "walk.bvh", "-o", "only/", "--key-every", "3")
    assert code == 0, err
    code, _, err = run(capsys, "complete", "only", "-o", "again/", "--key-every", "3")  # named: an input
    assert code == 0, err
    (walks / "holder").mkdir()
    shutil.move(walks / "only", walks / "holder" / "only")
    code, _, err = run(capsys, "complete", "holder", "-o", "x/", "--key-every", "3")
    assert code == 2 and "outside keyfill's output folders (holder/only)" in one_line(err)
    assert not (walks / "x").exists()


@pytest.mark.parametrize("args,message", [
    (("complete", "walk.bvh", "--key-every", "3", "-o", ""), "the output path is empty"),
    (("complete", "walk.bvh", "b.bvh", "--key-every", "3", "-o", ""), "-o is empty"),
    (("convert", "walk.bvh", ""), "the output path is empty"),
    (("convert", "walk.bvh", "-o", ""), "-o is empty"),
])
def test_an_empty_output_is_named_as_such(walks, capsys, args, message):
    code, _, err = run(capsys, *args)
    assert code == 2 and one_line(err).startswith(message) and "is the input" not in err
    assert listing(walks) == ["b.bvh", "walk.bvh"]


# --- one code for one kind of misuse ------------------------------------------------------------------

ROOT = DATA.parents[1]
CURVES = ROOT / "examples" / "edit" / "lamp_nod_curves.usda"
EDIT = ROOT / "examples" / "edit" / "lamp_lift.toml"

#: a missing path in every place a command takes one: exit 2 (a usage error, found before any work)
MISSING = [
    ("info", "nope.bvh"),
    ("convert", "nope.bvh", "o.usda"),
    ("convert", "nope.bvh", "walk.bvh", "-o", "od/"),
    ("complete", "nope.bvh", "--key-every", "3", "-o", "o.bvh"),
    ("complete", "nope.bvh", "walk.bvh", "--key-every", "3", "-o", "od/"),
    ("complete", "walk.bvh", "--key-every", "3", "-o", "o.bvh", "--model", "nope"),
    ("complete", "walk.bvh", "--key-every", "3", "-o", "o.bvh", "--rig-map", "nope.toml"),
    ("complete", "walk.bvh", "--keys", "0,30,68", "-o", "o.bvh", "--method", "gan", "--dna", "nope.bvh"),
    ("retarget", "nope.bvh", "--to", "walk.bvh", "-o", "o.bvh"),
    ("retarget", "walk.bvh", "--to", "nope.bvh", "-o", "o.bvh"),
    ("train", "arnn", "nope", "-o", "m"),
    ("train", "transformer", "walk.bvh", "-o", "m", "--config", "nope.json"),
    ("evaluate", "cubic", "nope"),
    ("edit-tangents", "nope.usda", "--edit", EDIT, "-o", "o.usda"),
    ("edit-tangents", CURVES, "--edit", "nope.toml", "-o", "o.usda"),
    ("pose", "nope.usda", "--edit", EDIT, "--frame", "10", "-o", "o.usda"),
    ("plot", "nope.bvh", "-o", "p.png"),
    ("preview", "nope.bvh", "-o", "p.gif"),
    ("export", "nope", "-o", "m.onnx"),
]


@pytest.mark.parametrize("args", MISSING, ids=lambda a: " ".join(map(str, a[:2])))
def test_a_missing_path_is_exit_2_in_every_command(walks, capsys, args):
    if "--dna" in args:
        pytest.importorskip("torch")
    code, _, err = run(capsys, *args)
    assert code == 2 and "nope" in one_line(err), err
    assert listing(walks) == ["b.bvh", "walk.bvh"]


@pytest.mark.parametrize("workers", ["0", "2000"])
@pytest.mark.parametrize("inputs,dst", [(("walk.bvh",), "o.bvh"), (("walk.bvh", "b.bvh"), "od/")])
def test_workers_out_of_range_are_refused_for_one_file_as_for_a_batch(walks, capsys, workers, inputs, dst):
    convert_dst = ("-o", dst) if len(inputs) > 1 else (dst,)  # convert SRC DST, or SRC... -o OUTDIR/
    for args in (("complete", *inputs, "--key-every", "3", "-o", dst), ("convert", *inputs, *convert_dst),
                 ("retarget", *inputs, "--to", "b.bvh", "-o", dst)):
        code, _, err = run(capsys, *args, "--workers", workers)
        assert code == 2 and one_line(err) == f"--workers must be between 1 and 1,024, got {workers}"
        assert listing(walks) == ["b.bvh", "walk.bvh"]


@pytest.mark.parametrize("args,line", [
    (("complete", "walk.bvh", "--key-every", "3", "-o", "o.bvh", "--method", "cubc"), "Did you mean 'cubic'?"),
    (("compelte", "walk.bvh"), "No such command 'compelte'. Did you mean 'complete'?"),
    (("train", "transfomer", "x"), "No such command 'transfomer'. Did you mean 'transformer'?"),
    (("convert", "walk.bvh", "o.usda", "--format", "usdx"), "(Did you mean one of: 'usd', 'usdc', 'usdz'?)"),
    (("complete", "walk.bvh", "--key-evry", "3", "-o", "o.bvh"), "Did you mean one of: '--key-every'"),
])
def test_a_mistyped_command_method_or_option_is_told_what_it_may_mean(walks, capsys, args, line):
    code, _, err = run(capsys, *args)
    assert code == 2 and line in one_line(err)
    assert listing(walks) == ["b.bvh", "walk.bvh"]


@pytest.mark.parametrize("signal", [None, 15])
def test_an_interrupt_is_one_line_without_a_blank_line_before_it(walks, capsys, monkeypatch, signal):
    from keyfill import io
    from keyfill.cli.signals import Interrupted

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt if signal is None else Interrupted(signal)

    monkeypatch.setattr(io, "_read", interrupted)
    code, out, err = run(capsys, "convert", "walk.bvh", "o.usda")
    assert (code, out) == ((130, "") if signal is None else (128 + signal, ""))
    assert err == f"keyfill: error: {'interrupted' if signal is None else 'terminated'}\n"
    assert listing(walks) == ["b.bvh", "walk.bvh"]


# --- outputs that cannot be written -------------------------------------------------------------------


def keyfill(*args, limit: int | None = None, stdout=subprocess.PIPE, cwd=None) -> tuple[int, str]:
    """``python -m keyfill ARGS`` in a subprocess (under a file-size limit of ``limit`` bytes): ``(code, stderr)``."""
    def limited():
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    proc = subprocess.run([sys.executable, "-m", "keyfill", *map(str, args)], stdout=stdout, stderr=subprocess.PIPE,
                          text=True, cwd=cwd, env={**os.environ, "PYTHONPATH": str(ROOT)}, check=False,
                          preexec_fn=None if limit is None else limited, timeout=120)
    return proc.returncode, proc.stderr


@pytest.mark.parametrize("suffix", [".bvh", ".usda", ".usdc", ".usd", ".glb", ".gltf"])
def test_a_file_size_limit_is_one_line_naming_the_output_and_leaves_nothing(walks, suffix):
    """A full disk as the writer meets it: each write past the limit fails with EFBIG (Python ignores SIGXFSZ);
    USD's C++ writer reports it inside its own exception."""
    (walks / "out").mkdir()
    dst = walks / "out" / f"walk{suffix}"
    code, err = keyfill("convert", "walk.bvh", dst, limit=8192, cwd=walks)
    named = dst.with_suffix(".bin") if suffix == ".gltf" else dst  # the glTF's buffer is written first
    assert code == 1 and one_line(err) == f"{named}: cannot write the output (File too large)"
    assert listing(walks / "out") == []


@pytest.mark.parametrize("args,named", [
    (("complete", "walk.bvh", "--key-every", "3", "-o", "/sys/x.bvh"), "/sys/x.bvh"),
    (("convert", "walk.bvh", "/sys/x.usda"), "/sys/x.usda"),
    (("complete", "walk.bvh", "b.bvh", "--key-every", "3", "-o", "/sys/kernel/"), "/sys/kernel"),
    (("convert", "walk.bvh", "b.bvh", "-o", "/sys/new/"), "/sys/new"),
])
def test_an_unwritable_place_is_one_line_naming_it(walks, capsys, args, named):
    code, _, err = run(capsys, *args)
    line = one_line(err)
    assert code == 1 and line.startswith(f"{named}: cannot write the output (") and ".part" not in line
    assert listing(walks) == ["b.bvh", "walk.bvh"]


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into a read-only folder")
@pytest.mark.parametrize("batch", [False, True])
def test_a_read_only_folder_is_one_line_naming_it(walks, capsys, batch):
    (walks / "ro").mkdir()
    (walks / "ro").chmod(0o555)
    try:
        args = ("walk.bvh", "b.bvh", "-o", "ro/") if batch else ("walk.bvh", "-o", "ro/o.bvh")
        code, _, err = run(capsys, "complete", *args, "--key-every", "3")
        assert code == 1 and one_line(err) == f"{'ro' if batch else 'ro/o.bvh'}: cannot write the output " \
                                              "(Permission denied)"
        assert listing(walks / "ro") == []
    finally:
        (walks / "ro").chmod(0o755)


def test_a_batch_past_the_file_size_limit_names_each_output_and_leaves_no_part_file(walks):
    code, err = keyfill("complete", "walk.bvh", "b.bvh", "--key-every", "3", "-o", "out/", "--format", "usda",
                        limit=8192, cwd=walks)
    lines = err.strip().splitlines()
    assert code == 1 and "Traceback" not in err and "internal error" not in err
    assert lines[:2] == [f"keyfill: error: {n}.bvh: out/{n}.usda: cannot write the output (File too large)"
                         for n in ("b", "walk")]
    assert not [p for p in listing(walks / "out") if ".part" in p or p.endswith(".usda")]


@pytest.mark.parametrize("args", [("convert", "walk.bvh", "-", "--format", "bvh"), ("info", "walk.bvh", "--json"),
                                  ("info", "walk.bvh")])
def test_a_full_standard_output_is_one_line(walks, args):
    with open("/dev/full", "w") as full:
        code, err = keyfill(*args, stdout=full, cwd=walks)
    assert code == 1 and one_line(err) == "cannot write standard output (No space left on device)"


# --- the exit-code table of docs/robustness.md, as run ------------------------------------------------

BAD = "HIERARCHY\nROOT Hips\n{\n OFFSET 0 0 x\n"  # a BVH file cut short: bad data, exit 1

#: (command, misuse, args, exit code): each row is a cell of the table in docs/robustness.md
TABLE = [
    ("info", "unknown option", ("info", "walk.bvh", "--bogus"), 2),
    ("info", "bad data", ("info", "bad.bvh"), 1),
    ("convert", "format against suffix", ("convert", "walk.bvh", "o.bvh", "--format", "usda"), 2),
    ("convert", "bad data", ("convert", "bad.bvh", "o.usda"), 1),
    ("convert", "unwritable output", ("convert", "walk.bvh", "/sys/o.usda"), 1),
    ("retarget", "unknown option", ("retarget", "walk.bvh", "--to", "b.bvh", "-o", "o.bvh", "--bogus"), 2),
    ("retarget", "bad data", ("retarget", "bad.bvh", "--to", "walk.bvh", "-o", "o.bvh"), 1),
    ("retarget", "unwritable output", ("retarget", "walk.bvh", "--to", "b.bvh", "-o", "/sys/o.bvh"), 1),
    ("complete", "option out of range", ("complete", "walk.bvh", "--key-every", "0", "-o", "o.bvh"), 2),
    ("complete", "bad data", ("complete", "bad.bvh", "--key-every", "3", "-o", "o.bvh"), 1),
    ("complete", "unwritable output", ("complete", "walk.bvh", "--key-every", "3", "-o", "/sys/o.bvh"), 1),
    ("simulate", "option out of range", ("simulate", "-o", "sim", "--count", "0"), 2),
    ("simulate", "unwritable output", ("simulate", "-o", "/sys/sim", "--count", "1"), 1),
    ("train", "unknown method", ("train", "arnnn", "data", "-o", "m"), 2),
    ("train", "bad data", ("train", "arnn", "bad.bvh", "-o", "m"), 1),
    ("evaluate", "option out of range", ("evaluate", "cubic", "walk.bvh", "--lengths", "x"), 2),
    ("evaluate", "bad data", ("evaluate", "cubic", "bad.bvh"), 1),
    ("edit-tangents", "unknown option", ("edit-tangents", CURVES, "--edit", EDIT, "-o", "o.usda", "--bogus"), 2),
    ("edit-tangents", "bad data", ("edit-tangents", "bad.bvh", "--edit", EDIT, "-o", "o.usda"), 1),
    ("edit-tangents", "unwritable output", ("edit-tangents", CURVES, "--edit", EDIT, "-o", "/sys/o.usda"), 1),
    ("pose", "unknown option", ("pose", CURVES, "--edit", EDIT, "--frame", "10", "-o", "o.usda", "--bogus"), 2),
    ("pose", "bad data", ("pose", "bad.bvh", "--edit", EDIT, "--frame", "10", "-o", "o.usda"), 1),
    ("plot", "unknown option", ("plot", "walk.bvh", "-o", "p.png", "--bogus"), 2),
    ("plot", "bad data", ("plot", "bad.bvh", "-o", "p.png"), 1),
    ("plot", "unwritable output", ("plot", "walk.bvh", "-o", "/sys/p.png"), 1),
    ("preview", "option out of range", ("preview", "walk.bvh", "-o", "p.gif", "--step", "0"), 2),
    ("preview", "bad data", ("preview", "bad.bvh", "-o", "p.gif"), 1),
    ("preview", "unwritable output", ("preview", "walk.bvh", "-o", "/sys/p.gif"), 1),
    ("export", "unknown option", ("export", "arnn", "--bogus"), 2),
    ("export", "bad data", ("export", "adir"), 1),
    ("export", "unwritable output", ("export", "arnn", "-o", "/sys/x.onnx"), 1),
    ("keyfill", "unknown command", ("compelte", "walk.bvh"), 2),
]


@pytest.mark.parametrize("command,misuse,args,code", TABLE, ids=[f"{c} {m}" for c, m, _, _ in TABLE])
def test_every_command_s_misuse_has_the_documented_exit_code(walks, capsys, command, misuse, args, code):
    if command == "simulate":
        pytest.importorskip("pybullet")
    if command == "export":
        pytest.importorskip("torch")
    (walks / "bad.bvh").write_text(BAD)
    (walks / "adir").mkdir()
    before = listing(walks)
    got, _, err = run(capsys, *args)
    line = one_line(err)
    assert got == code, (got, line)
    assert listing(walks) == before and ".part" not in line
    if misuse == "unwritable output":
        assert line.startswith(args[args.index("-o") + 1 if "-o" in args else 2].rstrip("/")) and \
            "cannot write the output" in line


def test_the_table_in_the_docs_is_the_table_run():
    """docs/robustness.md's exit-code table lists each cell of TABLE and MISSING with its code."""
    text = (ROOT / "docs" / "robustness.md").read_text()
    rows = {line.split("|")[1].strip().strip("`"): line for line in text.splitlines()
            if line.startswith("| `") and line.count("|") == 7}
    columns = ["usage", "missing path", "bad data", "unwritable output", "interrupted"]
    for command, misuse, _, code in TABLE:
        if command == "keyfill":
            continue
        cell = {"bad data": 2, "unwritable output": 3}.get(misuse, 0)
        assert rows[command].split("|")[2 + cell].strip() == str(code), (command, misuse, columns[cell])
    for args in MISSING:
        assert rows[args[0]].split("|")[3].strip() == "2", args[0]


def test_help_states_the_exit_codes_and_the_interrupt_behaviour_of_the_docs(capsys):
    """``keyfill --help`` gives the docs' codes (0, 1, 2, 128 + N with 130/143/129) and what an interrupt
    leaves behind, as tests/test_signals.py checks it."""
    code, out, _ = run(capsys, "--help")
    assert code == 0
    text = " ".join(out.split())
    docs = (ROOT / "docs" / "robustness.md").read_text()
    for figure in ("SIGINT 130", "SIGTERM 143", "SIGHUP 129"):
        assert figure in docs
    for said in ("0 success", "1 the work failed", "2 usage error", "128 + N signal N",
                 "130 Ctrl-C", "143 SIGTERM", "129 SIGHUP", "whole or absent", "same command again"):
        assert said in text, said
