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


def demo_commands(out: Path) -> list[list[str]]:
    """The ``keyfill`` command lines of the Makefile's ``demo`` target, writing into ``out``."""
    import shlex

    makefile = (PYPROJECT.parent / "Makefile").read_text()
    recipe = re.search(r"^demo:.*\n((?:\t.*\n)+)", makefile, re.MULTILINE).group(1)
    lines = [line.strip() for line in recipe.splitlines() if line.strip().startswith("$(BIN)/keyfill ")]
    return [shlex.split(line.replace("$(OUT)", str(out)))[1:] for line in lines]


def test_make_demo_installs_the_base_and_the_models_only():
    """`make demo` must not pull torch (on a plain index: gigabytes of CUDA packages) to show the demo."""
    makefile = (PYPROJECT.parent / "Makefile").read_text()
    assert re.search(r"^demo: \$\(DEMO_STAMP\)$", makefile, re.MULTILINE)
    recipe = re.search(r"^\$\(DEMO_STAMP\):.*\n((?:\t.*\n)+)", makefile, re.MULTILINE).group(1)
    installs = [line for line in recipe.splitlines() if "pip install" in line]
    assert [line.split()[-1] for line in installs] == [".", "./models/bandai"]


def test_every_demo_command_runs_without_torch_pybullet_or_dask(tmp_path):
    """What `make demo` installs is enough: each of its commands, with torch, pybullet and dask unimportable,
    exits 0 (the shipped models run through their ONNX graphs)."""
    import subprocess
    import sys

    commands = demo_commands(tmp_path)
    assert len(commands) >= 10 and any("gan" in c for c in commands) and any("transformer" in c for c in commands)
    code = ("import sys\n"
            "for name in ('torch', 'pybullet', 'dask', 'distributed'):\n"
            "    sys.modules[name] = None  # as if only `make demo`'s install were there\n"
            "from keyfill.cli.main import main\n"
            f"for args in {commands!r}:\n"
            "    code = main(args)\n"
            "    if code:\n"
            "        sys.exit(f'{args}: exit {code}')\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600, check=False,
                       cwd=PYPROJECT.parent)
    assert r.returncode == 0, r.stderr[-2000:]
    assert (tmp_path / "human_gan.usda").is_file() and (tmp_path / "human15_transformer.usda").is_file()
