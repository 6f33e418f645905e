"""Shared test helpers: where fixtures and the shared data live."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from hypothesis import settings

# CI (.ci/run sets HYPOTHESIS_PROFILE=ci) draws the same examples on every run, so a red build is never a
# lucky draw and always reproduces; a developer's `make test` keeps exploring new examples and remembers the
# failing ones in .hypothesis/.
settings.register_profile("ci", derandomize=True, database=None)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "default"))

DATA = Path(__file__).parent / "data"
SHARED = Path(__file__).resolve().parents[2] / "shared" / "data"
BVH_FIXTURES = SHARED / "bvh_fixtures"


def shared_path(*parts: str) -> Path:
    """A path under ../shared/data, or skip the test with the reason."""
    p = SHARED.joinpath(*parts)
    if not p.exists():
        pytest.skip(f"needs {p} (the shared data folder beside the checkout); it is absent here")
    return p


def shared_fixtures() -> list[Path]:
    """All BVH files in ../shared/data/bvh_fixtures (skips when absent)."""
    return sorted(shared_path("bvh_fixtures").glob("*.bvh"))


@pytest.fixture(scope="module")
def one_torch_thread():
    """One torch thread for a module: small models train fastest so, and two oversubscribe a busy 2-core machine."""
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


def run(capsys, *args):
    """``keyfill ARGS...`` in this process: ``(exit code, stdout, stderr)``."""
    from keyfill.cli.main import main

    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


def one_error_line(err: str) -> str:
    """The one ``keyfill: error:`` line of ``err`` (asserting there is exactly one and it is no internal error)."""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("keyfill: error: "), err
    assert "internal error" not in lines[0] and "Traceback" not in err
    return lines[0]
