"""The one table of file formats (``keyfill.io.FORMATS``) and errors that name parameters, not flags."""

from __future__ import annotations

import re
from io import BytesIO, TextIOWrapper
from pathlib import Path

import pytest
from conftest import DATA, run

from keyfill import io
from keyfill.cli.common import FORMAT_CHOICE
from keyfill.errors import UsageError
from keyfill.io import batch

MIXAMO = DATA / "bvhtoolbox_test_freebvh_mixamo.bvh"
DOC = Path(__file__).resolve().parents[1] / "docs" / "formats.md"


def test_every_list_of_formats_is_the_table():
    assert list(FORMAT_CHOICE.choices) == list(io.FORMATS)
    assert batch.MOTION_SUFFIXES == tuple(io.SUFFIXES)
    assert len(io.SUFFIXES) == sum(len(f.suffixes) for f in io.FORMATS.values())  # no suffix twice
    for name, spec in io.FORMATS.items():
        assert spec.name == name and all(io.format_of("x" + s, reading=True) == name for s in spec.suffixes)


def test_the_formats_page_lists_the_table():
    rows = [line.split("|")[1:6] for line in DOC.read_text().splitlines() if re.match(r"\| `\w+` \| `\.", line)]
    table = {cells[0].strip(" `"): [c.strip(" `") for c in cells[1:]] for cells in rows}
    assert list(table) == list(io.FORMATS)
    for name, (suffix, family, description, _) in table.items():
        spec = io.FORMATS[name]
        assert (suffix, family, description.replace("`", "")) == (spec.suffixes[0], spec.family, spec.description)


def test_library_errors_name_parameters_and_the_cli_its_flags(capsys, tmp_path, monkeypatch):
    with pytest.raises(UsageError, match="^chunk must be at least 1, got 0$") as e:
        batch.run([], None, None, chunk=0)
    assert e.value.params == ("chunk",)
    code, _, err = run(capsys, "convert", MIXAMO, "-o", tmp_path / "out/", "--batch-size", "0")
    assert code == 2 and err == "keyfill: error: --batch-size must be at least 1, got 0\n"
    with pytest.raises(UsageError, match=r"^writing '-' needs format \(bvh, usda, usdc, usd, usdz, glb or gltf\)$"):
        io.format_of("-")
    monkeypatch.setattr("sys.stdin", TextIOWrapper(BytesIO(b"not a motion file")))
    code, _, err = run(capsys, "info", "-")
    assert code == 2 and err == ("keyfill: error: cannot tell the format of standard input from its first bytes; "
                                 "give --in-format (bvh, usda, usdc, usd, usdz, glb, gltf or fbx)\n")
    (tmp_path / "notes.txt").write_text("x")
    with pytest.raises(UsageError, match="; give format$"):
        batch.plan([tmp_path / "notes.txt"], tmp_path / "o")
    code, _, err = run(capsys, "convert", tmp_path / "notes.txt", "-o", tmp_path / "o/")
    assert code == 2 and err.endswith("unknown file type '.txt'; give --format\n")
    (tmp_path / "format").mkdir()
    (tmp_path / "format" / "notes.txt").write_text("x")
    code, _, err = run(capsys, "convert", tmp_path / "format" / "notes.txt", "-o", tmp_path / "o/")
    assert f"{tmp_path}/format/notes.txt: unknown" in err  # a path that holds the word keeps it
