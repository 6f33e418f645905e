"""The base install: no torch, pybullet or dask in keyfill's own requirements; extras bring them."""

import re
import tomllib
from pathlib import Path

PYPROJECT = Path(__file__).resolve().parents[1] / "pyproject.toml"
HEAVY = {"torch", "pybullet", "dask"}


def _names(requirements: list[str]) -> set[str]:
    return {re.match(r"[A-Za-z0-9_.-]+", r).group(0).lower() for r in requirements}


def test_the_base_install_needs_no_torch_pybullet_or_dask():
    project = tomllib.loads(PYPROJECT.read_text())["project"]
    assert not _names(project["dependencies"]) & HEAVY
    extras = project["optional-dependencies"]
    assert "torch" in _names(extras["train"]) and "pybullet" in _names(extras["sim"])
    assert "dask" in _names(extras["dask"])
    assert "onnxruntime" in _names(project["dependencies"])  # exported graphs run without any extra


def test_make_installs_every_extra():
    makefile = (PYPROJECT.parent / "Makefile").read_text()
    installed = re.search(r"-e '\.\[([a-z,]+)\]'", makefile).group(1).split(",")
    extras = tomllib.loads(PYPROJECT.read_text())["project"]["optional-dependencies"]
    assert set(extras) <= set(installed)


def test_a_command_that_needs_a_missing_extra_names_the_pip_line(tmp_path):
    import subprocess
    import sys

    example = PYPROJECT.parent / "examples" / "human" / "keys.usda"  # runtime torch: shipped graph or not
    out = tmp_path / "o.bvh"
    code = ("import sys; sys.modules['torch'] = None  # as if the train extra were not installed\n"
            "from keyfill.cli.main import main\n"
            f"sys.exit(main(['complete', {str(example)!r}, '-o', {str(out)!r}, '--method', 'gan', '--runtime', 'torch']))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=False)
    assert r.returncode == 1 and not out.exists()
    assert r.stderr.strip() == ("keyfill: error: this needs torch, which the base install leaves out: "
                                "pip install 'keyfill[train]'")
