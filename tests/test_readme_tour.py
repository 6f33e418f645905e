"""The README's tour runs as written from a fresh clone (issue 32): every file its shell commands read ships in the
repository or is made by an earlier command, and no command writes anywhere but the git-ignored ``out/``.

The commands are read from the README's ``sh`` code blocks. ``python tests/test_readme_tour.py`` prints the
tour's commands (those it can run without the Bandai-Namco corpora or a Dask cluster), to run them by hand in a
fresh clone: ``git clone . /tmp/tour && cd /tmp/tour && ln -s "$OLDPWD/.venv" .venv && PATH=$PWD/.venv/bin:$PATH
bash -ex <(python tests/test_readme_tour.py)``.
"""

from __future__ import annotations

import fnmatch
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
#: what a token must look like to be read as a file (besides holding a ``/``)
SUFFIXES = (".bvh", ".usda", ".usdc", ".usd", ".glb", ".gltf", ".toml", ".onnx", ".png", ".gif", ".svg", ".jsonl")
#: the shell's words between commands that the tour uses
OPERATORS = ("&&", "|", ">")
#: why a command cannot run from a fresh clone alone: (pattern in the command, reason)
CORPORA = "needs the Bandai-Namco corpora (make corpora unpacks them from ../shared/data)"
NEEDS = (("../shared/data", "needs the Bandai-Namco corpora in ../shared/data"),
         ("make corpora", CORPORA),
         ("data/bandai", CORPORA),
         ("--scheduler", "needs a Dask cluster"))
#: the Makefile's targets that the tour runs
MAKE_TARGETS = ("corpora",)


def shell_blocks(text: str) -> list[list[str]]:
    """The lines of each ```sh block."""
    return [block.splitlines() for block in re.findall(r"^```sh\n(.*?)^```", text, flags=re.DOTALL | re.MULTILINE)]


def tour_lines(text: str) -> list[str]:
    """Every command line of the README after the quick start, ``$VAR`` expanded, comments dropped."""
    env: dict[str, str] = {}
    lines = []
    for block in shell_blocks(text)[1:]:
        for raw in block:
            tokens = shlex.split(raw, comments=True)
            if not tokens:
                continue
            if len(tokens) == 1 and re.fullmatch(r"[A-Z_][A-Z0-9_]*=\S+", tokens[0]):
                name, value = tokens[0].split("=", 1)
                env[name] = value
                continue
            line = " ".join(t if t in OPERATORS else shlex.quote(t) for t in tokens)
            for name in sorted(env, key=len, reverse=True):  # $BANDAI12 before $BANDAI1
                line = line.replace(f"${name}", env[name])
            lines.append(line)
    return lines


def needs(line: str, skipped_outputs: dict[str, str] | None = None) -> str | None:
    """Why ``line`` cannot run from a fresh clone alone (also: it reads what a skipped line writes), or None."""
    why = next((why for pattern, why in NEEDS if pattern in line), None)
    if why is None and skipped_outputs:
        reads, _ = reads_and_writes(line)
        why = next((skipped_outputs[o] for r in reads for o in skipped_outputs
                    if r.rstrip("/") == o or r.startswith(o + "/")), None)
    return why


def needs_of_lines(lines: list[str]) -> list[str | None]:
    """:func:`needs` of each line of the tour, in order."""
    skipped_outputs: dict[str, str] = {}
    whys = []
    for line in lines:
        why = needs(line, skipped_outputs)
        if why:
            skipped_outputs.update((w.rstrip("/"), why) for w in reads_and_writes(line)[1])
        whys.append(why)
    return whys


def is_path(token: str) -> bool:
    return token != "-" and "://" not in token and not token.startswith("-") and (
        "/" in token or token.endswith(SUFFIXES))


def reads_and_writes(line: str) -> tuple[list[str], list[str]]:
    """``(inputs, outputs)`` of one command line (``&&`` and ``|`` split it into commands; ``>`` redirects)."""
    reads, writes = [], []
    for command in re.split(r"\s(?:&&|\|)\s", line):
        tokens = shlex.split(command)
        if ">" in tokens:
            at = tokens.index(">")
            writes.append(tokens[at + 1])
            tokens = tokens[:at]
        if tokens[0] == "mkdir":
            writes += [t for t in tokens[1:] if not t.startswith("-")]
            continue
        if tokens[0] in ("printf", "echo"):
            continue
        if tokens[0] == "make":  # writes only git-ignored folders of the checkout (data/)
            assert set(tokens[1:]) <= set(MAKE_TARGETS), command
            continue
        if tokens[0] in ("cat", "cp"):
            reads += tokens[1:]
            continue
        assert tokens[0] == "keyfill", command
        sub, args = tokens[1], tokens[2:]
        positional = []
        i = 0
        while i < len(args):
            t = args[i]
            if t in ("-o", "--output"):
                writes.append(args[i + 1])
                i += 2
                continue
            if t.startswith("-") and t != "-":
                if i + 1 < len(args) and is_path(args[i + 1]):  # an option's file (--edit, --to, --model, ...)
                    reads.append(args[i + 1])
                    i += 2
                    continue
                i += 1
                continue
            positional.append(t)
            i += 1
        if sub == "convert" and len(positional) == 2 and "-o" not in args:
            reads.append(positional[0])
            writes.append(positional[1])
        elif sub == "export" and "-o" not in args and is_path(positional[0]):
            reads.append(positional[0])
            writes.append(str(Path(positional[0]) / "model.onnx"))
        else:
            reads += [p for p in positional if is_path(p)]
    return reads, writes


def tracked() -> set[str]:
    out = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True).stdout
    return set(out.splitlines())


def made(path: str, outputs: list[str], files: set[str]) -> bool:
    """Whether ``path`` (a file, folder or glob) ships in the repository or was written before."""
    p = path.rstrip("/")
    if any(c in p for c in "*?["):
        return any(fnmatch.fnmatch(o, p) or fnmatch.fnmatch(o, p.replace("**/", "")) for o in outputs)
    if p in files or any(f.startswith(p + "/") for f in files):
        return True
    return any(p == o or p.startswith(o + "/") for o in outputs)


def test_the_quick_start_is_two_commands():
    assert shell_blocks(README.read_text())[0] == ["make demo", "make test"]


def test_every_file_the_tour_reads_ships_or_is_made_first_and_it_writes_only_into_out():
    files = tracked()
    outputs: list[str] = []
    lines = tour_lines(README.read_text())
    assert len(lines) > 30
    skipped = []
    for line, why in zip(lines, needs_of_lines(lines)):
        reads, writes = reads_and_writes(line)
        if why:
            skipped.append((line, why))
        else:
            missing = [r for r in reads if not made(r, outputs, files)]
            assert not missing, f"{line}: reads {missing}, which neither ship nor are made by an earlier command"
        for w in writes:
            w = w.rstrip("/")
            assert w == "out" or w.startswith("out/"), f"{line}: writes {w}, outside the git-ignored out/"
            assert not made(w, [], files), f"{line}: writes the tracked {w}"
            outputs.append(w)
    assert len(skipped) <= 7, skipped


def test_the_tour_unpacks_the_corpora_it_trains_on_with_a_make_target_before_it_reads_them():
    """Issue 48: the training block named no step that unpacks the corpora (its hint was hours of gan training).
    ``make corpora`` comes first, and unpacks the very folders that the tour's $BANDAI1 and $BANDAI2 name."""
    lines = tour_lines(README.read_text())
    first = next(i for i, line in enumerate(lines) if "data/bandai" in line)
    assert "make corpora" in lines[:first]
    makefile = (ROOT / "Makefile").read_text()
    folders = dict(re.findall(r"^(BANDAI[12]) := (\S+)$", makefile, flags=re.MULTILINE))
    tour = dict(re.findall(r"^(BANDAI[12])=(\S+)", README.read_text(), flags=re.MULTILINE))
    assert tour == folders and len(tour) == 2
    assert re.search(r"^corpora: \| \$\(BANDAI1\) \$\(BANDAI2\)$", makefile, flags=re.MULTILINE)
    assert re.search(r"^\.PHONY: .*\bcorpora\b", makefile, flags=re.MULTILINE)
    if shutil.which("make") is None:
        pytest.skip("no make here")
    dry = subprocess.run(["make", "-n", "-B", "corpora"], cwd=ROOT, capture_output=True, text=True, check=True)
    assert "locate('bandai1')" in dry.stdout and "locate('bandai2')" in dry.stdout, dry.stdout


def test_the_tour_trains_a_human_model_in_minutes_not_hours():
    """The tour's training commands on the corpora are the quick ones (a few epochs of dataset-1); the recipes
    of the shipped models (hours) are named in the text, not run."""
    trains = [line for line in tour_lines(README.read_text()) if line.startswith("keyfill train")]
    assert trains
    for line in trains:
        assert "--epochs" in line, line
        if "data/bandai" in line:
            assert "data/bandai1/" in line and int(shlex.split(line)[shlex.split(line).index("--epochs") + 1]) <= 3


def test_out_is_ignored_by_git():
    proc = subprocess.run(["git", "check-ignore", "-q", "out/walk.bvh"], cwd=ROOT, check=False)
    assert proc.returncode == 0


@pytest.mark.parametrize("line,reads,writes", [
    ("keyfill convert a/x.bvh out/x.usda", ["a/x.bvh"], ["out/x.usda"]),
    ("keyfill plot a.usda out/b.usda --labels a,b -o out/p.png", ["a.usda", "out/b.usda"], ["out/p.png"]),
    ("cat out/w.bvh | keyfill convert - - --format usda > out/w.usda", ["out/w.bvh"], ["out/w.usda"]),
    ("keyfill export out/m", ["out/m"], ["out/m/model.onnx"]),
    ("keyfill pose c.usda --edit e.toml --frame 15 -o out/p.usda", ["e.toml", "c.usda"], ["out/p.usda"]),
])
def test_the_reader_of_commands(line, reads, writes):
    assert reads_and_writes(line) == (reads, writes)


if __name__ == "__main__":
    tour = tour_lines(README.read_text())
    for line, why in zip(tour, needs_of_lines(tour)):
        print(f"# skipped ({why}): {line}" if why else line)
    sys.exit(0)
