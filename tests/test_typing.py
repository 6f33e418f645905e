"""What a type checker sees of keyfill's public API: keyfill ships ``py.typed``, so mypy reads its annotations.

mypy looks at an installed package's annotations only when the package has a ``py.typed`` marker (PEP 561);
without it ``keyfill.io.load`` is ``Any``. The test installs keyfill, as pip would, into a bare environment (a
link in its site-packages; numpy and the rest seen through a ``.pth`` line) and runs mypy on a user's script
from another folder, so the checkout on the current directory cannot stand in for the installed package.
"""

import subprocess
import sys
import sysconfig
import textwrap
import venv
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

SCRIPT = """\
from keyfill import Keys, io
from keyfill.learn.registry import complete
motion = io.load("walk.bvh")
reveal_type(motion)
reveal_type(complete(motion, Keys.every(10, motion.num_frames)).motion)
reveal_type(motion.keys)
reveal_type(io.save(motion, "walk.usda"))
"""


def test_mypy_infers_the_public_api_of_the_installed_package(tmp_path):
    pytest.importorskip("mypy", reason="needs mypy (the test extra: pip install 'keyfill[test]')")
    assert (ROOT / "keyfill" / "py.typed").is_file()
    env = tmp_path / "env"
    venv.create(env, with_pip=False)
    python = env / "bin" / "python"
    site = Path(subprocess.run([python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                               capture_output=True, text=True, check=True).stdout.strip())
    (site / "keyfill").symlink_to(ROOT / "keyfill", target_is_directory=True)
    (site / "deps.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")  # numpy & co. of this interpreter
    user = tmp_path / "user" / "script.py"
    user.parent.mkdir()
    user.write_text(SCRIPT)
    result = subprocess.run([sys.executable, "-m", "mypy", "--python-executable", str(python), "--no-incremental",
                             "--follow-imports=silent", "--cache-dir", str(tmp_path / "cache"), user.name],
                            cwd=user.parent, capture_output=True, text=True, timeout=300, check=False)
    revealed = [line.split('Revealed type is "')[1].rstrip('"') for line in result.stdout.splitlines()
                if "Revealed type is" in line]
    assert revealed == ["keyfill.motion.Motion", "keyfill.motion.Motion", "keyfill.motion.Keys | None", "None"], (
        textwrap.indent(result.stdout + result.stderr, "  "))
    assert result.returncode == 0, result.stdout
