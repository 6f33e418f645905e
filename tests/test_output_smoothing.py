"""The learned human models' inference low-pass: the numpy and torch kernels agree, settings are checked,
and the shipped transformer's smoothing lowers jitter without moving the keys."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import torch

from keyfill import io
from keyfill.errors import ModelError
from keyfill.kinematics import fk
from keyfill.learn import registry
from keyfill.learn.completion import CompleteOptions
from keyfill.learn.gan.rcfk import binomial_lowpass as torch_lowpass
from keyfill.learn.modelfile import load_cached
from keyfill.learn.transformer import model as T
from keyfill.learn.transformer.config import ModelConfig
from keyfill.learn.windows import binomial_lowpass

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "human" / "keys_15.usda"


@pytest.mark.parametrize("order", [0, 2, 4, 12])
def test_numpy_and_torch_lowpass_agree(order):
    x = np.random.default_rng(order).normal(size=(3, 40, 5))
    ours = binomial_lowpass(x, order, axis=1)
    theirs = torch_lowpass(torch.as_tensor(x), order, dim=1).numpy()
    np.testing.assert_allclose(ours, theirs, atol=1e-12)
    if order:
        alternating = np.tile([1.0, -1.0], 20)
        assert np.abs(binomial_lowpass(alternating, order, axis=0)[order:-order]).max() < 1e-12  # period 2 gone


@pytest.mark.parametrize("bad", [-2, 3, 66, 2.0, True])
def test_the_setting_is_an_even_order(bad):
    with pytest.raises(ModelError, match="output_smoothing must be an even order"):
        ModelConfig(output_smoothing=bad)


def test_the_shipped_transformer_smooths_its_correction_and_keeps_its_keys():
    motion = io.load(EXAMPLE)
    keys = motion.keys
    model = load_cached(T.load, T.DEFAULT_MODEL, "cpu")
    assert model.config.output_smoothing == 2

    def jitter(m):
        p = fk(m.rotations, m.positions, m.skeleton.parents)[1]
        return np.linalg.norm(p[3:] - 3 * p[2:-1] + 3 * p[1:-2] - p[:-3], axis=-1).mean()

    torch_path = CompleteOptions(runtime="torch")  # the model object patched below (the graph has its own copy)
    smooth = registry.complete(motion, keys, "transformer", torch_path).motion
    original = model.config
    try:
        model.config = dataclasses.replace(original, output_smoothing=0)
        raw = registry.complete(motion, keys, "transformer", torch_path).motion
    finally:
        model.config = original
    k = keys.frames
    np.testing.assert_array_equal(smooth.rotations[k], motion.rotations[k])
    assert jitter(smooth) < 0.7 * jitter(raw)
