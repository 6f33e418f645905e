"""A few hundred mutation cases per ``make test`` (``make fuzz`` runs 100,000: see ``tests/fuzzing.py``).

Hypothesis drives the mutations of :mod:`fuzzing` over the fixtures (BVH
text, USD text, edit TOML, the shipped model folder, glTF); every case must end in
success or a :class:`keyfill.errors.KeyfillError`, never another exception.
"""

from __future__ import annotations

import random

import fuzzing
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

pytestmark = pytest.mark.usefixtures("one_torch_thread")

CASES = {"bvh": 60, "usd": 50, "toml": 80, "model": 40, "gltf": 60}


def _check(kind: str, rnd: random.Random, variant: int, tmp_path_factory) -> None:
    pool = fuzzing.seeds(kind)
    data = fuzzing.mutate(pool[rnd.randrange(len(pool))], rnd, kind)
    out = fuzzing.run_case(kind, data, tmp_path_factory.mktemp(kind), variant)
    assert out.status != "finding", f"{kind} input {data[:200]!r}...: {out.detail}"


def _test(kind: str):
    @settings(max_examples=CASES[kind], deadline=None, derandomize=True, database=None,
              suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
    @given(rnd=st.randoms(use_true_random=False), variant=st.integers(0, 999))
    def test(rnd, variant, tmp_path_factory):
        _check(kind, rnd, variant, tmp_path_factory)

    test.__name__ = f"test_mutated_{kind}_inputs_fail_cleanly"
    return test


test_mutated_bvh_inputs_fail_cleanly = _test("bvh")
test_mutated_usd_inputs_fail_cleanly = _test("usd")
test_mutated_toml_inputs_fail_cleanly = _test("toml")
test_mutated_model_folders_fail_cleanly = _test("model")
test_mutated_gltf_inputs_fail_cleanly = _test("gltf")


def test_the_seeds_themselves_are_accepted(tmp_path):
    for kind in fuzzing.KINDS:
        for i, data in enumerate(fuzzing.seeds(kind)):
            work = tmp_path / f"{kind}{i}"
            work.mkdir()
            out = fuzzing.run_case(kind, data, work, variant=1)
            assert out.status != "finding", out.detail
