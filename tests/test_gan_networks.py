"""The residual layer (Eq. 6), batch regularisation (Eq. 9), Table 5's networks, the losses (Eqs. 5, 7, 8, 10)."""

from __future__ import annotations

import math

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from keyfill.learn.gan import losses as L
from keyfill.learn.gan.config import PRESETS, GanConfig
from keyfill.learn.gan.features import dense_input, nearest_key
from keyfill.learn.gan.layers import ResidualConv, batch_regularisation
from keyfill.learn.gan.network import (
    Discriminator,
    Generator,
    PathPredictor,
    discriminator_receptive_field,
    generator_receptive_field,
    root_path,
)
from keyfill.learn.gan.ranges import JointRanges
from keyfill.learn.gan.rcfk import RCFK

pytestmark = pytest.mark.usefixtures("one_torch_thread")


# --- Eq. 5 ---------------------------------------------------------------------------------


def test_displacement_loss_matches_a_hand_computed_example():
    # three frames; true root x: 0, 1, 3 (y: 0); predicted velocities (2, 1, 0), (0, 0, 0), (the last is unused)
    root = torch.tensor([[[0.0, 0, 0], [1, 0, 0], [3, 0, 0]]])
    vel = torch.tensor([[[2.0, 0, 9], [1, 0, 9], [0, 0, 9]]])  # (1, 3 coords, 3 frames)
    # n = 1: t=0: (2,1,0) - (1,0,0) -> 2; t=1: (0,0,0) - (2,0,0) -> 4; mean over N - n = 2 terms: 3
    # n = 2: t=0: (2,1,0) - (3,0,0) -> 2; one term: 2
    # n = 4 ... 128 do not fit three frames; the mean of the two intervals: 2.5
    assert float(L.displacement_loss(vel, root)) == pytest.approx(2.5)
    # padded to five frames, the padding carries no loss; beside a row of zero error, the mean over rows
    root2 = torch.cat([root, root[:, -1:].expand(1, 2, 3)], dim=1)
    vel2 = torch.cat([vel, torch.full((1, 3, 2), 7.0)], dim=2)
    assert float(L.displacement_loss(vel2, root2, torch.tensor([3]))) == pytest.approx(2.5)
    still = torch.zeros(1, 3, 5)
    both = L.displacement_loss(torch.cat([vel2, still]), torch.cat([root2, torch.zeros(1, 5, 3)]), torch.tensor([3, 5]))
    assert float(both) == pytest.approx(1.25)


def test_displacement_loss_is_eq5_over_eight_intervals():
    rng = np.random.default_rng(0)
    N = 300
    root = np.cumsum(rng.normal(size=(N, 3)), axis=0)
    vel = rng.normal(size=(N, 3))
    expected = []
    for q in range(8):
        n = 2**q
        terms = [np.sum((vel[t : t + n].sum(0) - (root[t + n] - root[t])) ** 2) for t in range(N - n)]
        expected.append(np.mean(terms))
    got = L.displacement_loss(torch.tensor(vel.T[None]), torch.tensor(root[None]))
    assert float(got) == pytest.approx(np.mean(expected), rel=1e-10)
    # true velocities give zero loss
    true_v = np.diff(root, axis=0, append=root[-1:])
    assert float(L.displacement_loss(torch.tensor(true_v.T[None]), torch.tensor(root[None]))) == pytest.approx(0, abs=1e-18)


# --- Eqs. 7, 8, 10 -----------------------------------------------------------------------------


def test_least_squares_gan_losses():
    real = torch.tensor([[1.0, 0.0]])
    fake = torch.tensor([[-1.0, 1.0]])
    assert float(L.discriminator_loss(real, fake)) == pytest.approx(0.5 + 2.0)  # (0 + 1)/2 + (0 + 4)/2
    assert float(L.generator_loss(fake)) == pytest.approx(((-1 - 0.2361) ** 2 + (1 - 0.2361) ** 2) / 2)


def test_key_root_loss_recentres_on_the_keys():
    g = torch.Generator().manual_seed(0)
    key_root = torch.randn(2, 10, 3, generator=g)
    mask = torch.zeros(2, 10, dtype=torch.bool)
    mask[:, [0, 4, 9]] = True
    assert float(L.key_root_loss(key_root + torch.tensor([5.0, -2.0, 1.0]), key_root, mask)) == pytest.approx(0, abs=1e-10)
    bent = key_root.clone()
    bent[0, 4] += torch.tensor([3.0, 0.0, 0.0])
    # one row: the key moved by 3 along x; re-centring spreads it: errors (-1, 2, -1) -> (1 + 4 + 1) / 3 = 2; mean over 2 rows
    assert float(L.key_root_loss(bent, key_root, mask)) == pytest.approx(1.0)


# --- Fig. 4 ---------------------------------------------------------------------------------


def test_dense_input_follows_figure_4():
    keys = np.array([3, 64, 67])
    idx, dist = nearest_key(70, keys)
    assert dist[[0, 1, 2, 3, 4, 5, 33, 34, 63, 64, 66, 67, 68, 69]].tolist() == [3, 2, 1, 0, 1, 2, 30, 30, 1, 0, 1, 0, 1, 2]
    assert keys[idx[[0, 33, 34, 63, 65, 66, 69]]].tolist() == [3, 3, 64, 64, 64, 67, 67]
    poses = np.arange(3 * 2 * 3, dtype=float).reshape(3, 2, 3)
    x = dense_input(70, keys, poses, mask_scale=10.0)
    assert x.shape == (12, 70)
    assert np.allclose(x[:6, 34], poses[1].reshape(-1)) and np.allclose(x[6:, 33], 3.0)


# --- Eq. 6 and Eq. 9 ----------------------------------------------------------------------------


def test_residual_layer_is_eq6():
    torch.manual_seed(0)
    x = torch.randn(2, 5, 16)
    layer = ResidualConv(5, 5, 3, 1, 1, ratio=0.25)
    with torch.no_grad():
        layer.scale.uniform_(0.5, 2.0)
        layer.bias.normal_()
        h = layer.act(layer.conv(x) * layer.scale[:, None] + layer.bias[:, None])
        s = 0.25
        expected = math.sqrt(s) * (h + math.sqrt(1 - s) * x) + math.sqrt(1 - s) * x
        assert torch.allclose(layer(x), expected, atol=1e-6)
        plain = ResidualConv(5, 7, 4, 2, 1, ratio=1.0)
        assert plain.project is None
        assert torch.allclose(plain(x), plain.act(plain.conv(x) * plain.scale[:, None] + plain.bias[:, None]))
        assert plain(x).shape == (2, 7, 8)
        up = ResidualConv(5, 3, 4, 2, 1, ratio=0.5, transpose=True)
        assert up(x).shape == (2, 3, 32)


def test_batch_regularisation_is_eq9():
    torch.manual_seed(1)
    net = torch.nn.Sequential(ResidualConv(3, 4, 3, 1, 1, 1.0), ResidualConv(4, 6, 3, 1, 1, 0.5))
    x = torch.randn(5, 3, 20)
    net.requires_grad_(False)
    h1 = net[0].conv(x)
    y1 = net[0](x)
    h2 = net[1].conv(y1)
    net[1](y1)
    expected = 0.0
    for h in (h1, h2):
        m, s = h.mean((0, 2)), h.std((0, 2))
        expected += float((m**2).sum() + (torch.log(s + 1e-5) ** 2).sum())
    assert float(batch_regularisation(net)) == pytest.approx(expected / 10, rel=1e-5)


# --- Table 5 ------------------------------------------------------------------------------------


def test_receptive_fields_are_the_papers():
    from keyfill.errors import UsageError
    from keyfill.learn.gan.config import EFFECTIVE_RECEPTIVE_FIELD

    assert generator_receptive_field() == 318
    assert discriminator_receptive_field() == 190
    assert EFFECTIVE_RECEPTIVE_FIELD == 2 * generator_receptive_field()
    with pytest.raises(UsageError, match="receptive field"):
        GanConfig(max_gap=700)


def _tiny_rcfk(J=4):
    ranges = JointRanges(np.arange(1, J - 1), ("XZY",) * (J - 2), -np.ones((J - 2, 3)), np.ones((J - 2, 3)))
    offsets = np.array([[0, 0, 0]] + [[0, 0.1, 0]] * (J - 1))
    return RCFK(np.arange(J) - 1, offsets, ranges)


def test_network_shapes_and_the_style_hook():
    torch.manual_seed(0)
    J = 4
    rcfk = _tiny_rcfk(J)
    G = Generator(J, rcfk, [8] * 6, [8] * 13, noise_dim=3, style_dim=2).eval()
    x = torch.randn(2, 6 * J, 128)
    noise = torch.randn(2, 3, 2)
    v = G(x, noise)
    assert v.shape == (2, rcfk.channels, 128)
    assert torch.allclose(G(x, noise), G(x, noise, torch.zeros(2, 2)))  # no style = zero style
    assert not torch.allclose(G(x, noise), G(x, noise, torch.ones(2, 2)))
    assert not torch.allclose(G(x, noise), G(x, torch.randn(2, 3, 2)))
    D = Discriminator(3 * (J - 1), [8] * 6)
    assert D(torch.randn(3, 3 * (J - 1), 256)).shape == (3, 4)
    P = PathPredictor(3 * (J - 1), [8] * 8)
    assert P(torch.randn(2, 3 * (J - 1), 150)).shape == (2, 3, 150)  # any length
    with pytest.raises(ValueError, match="multiple of 64"):
        G(torch.randn(1, 6 * J, 100))
    path = root_path(torch.ones(1, 3, 4))
    assert path[0, :, 0].tolist() == [0, 1, 2, 3]


def test_presets_build_and_count():
    from keyfill.learn.gan.network import count_weights

    cpu = GanConfig()
    paper = GanConfig.from_preset("paper")
    assert cpu.widths == PRESETS["cpu"] and paper.widths == PRESETS["paper"]
    small = Generator(22, _tiny_rcfk(22), cpu.widths["encoder"], cpu.widths["decoder"], cpu.noise_dim)
    assert 0 < count_weights(small) < 5_000_000
    assert GanConfig.from_json(cpu.to_json()) == cpu


def test_path_errors_are_table_2_displacement_errors():
    """``path_errors`` on a hand-made pool: a predictor of zero velocity errs by the true displacement,
    a predictor of the true velocities by nothing."""
    from keyfill.learn.gan.poses import ClipPool
    from keyfill.learn.gan.quality import path_errors

    class Fixed(torch.nn.Module):
        """Returns the velocities it was given, whatever the joints (B, 3, T)."""

        def __init__(self, velocities):
            super().__init__()
            self.anchor = torch.nn.Parameter(torch.zeros(1))
            self.v = velocities

        def forward(self, x):
            return torch.as_tensor(self.v[None], dtype=x.dtype)

    t = np.arange(5, dtype=np.float64)
    root = np.stack([0.01 * t**2, np.zeros(5), 0.02 * t], axis=1)  # metres: a curve, steps growing in x
    pool = ClipPool((np.zeros((5, 3, 3), np.float32),), (root,), 30.0, "Y")
    zero = type("M", (), {"path": Fixed(np.zeros((3, 5)))})()
    got = path_errors(zero, pool, horizons=(1, 2, 4, 5))
    hand_1 = np.mean([np.hypot(0.01 * (2 * i + 1), 0.02) for i in range(4)])  # |root[t+1] - root[t]|
    hand_2 = np.mean([np.hypot(0.01 * (4 * i + 4), 0.04) for i in range(3)])
    hand_4 = np.hypot(0.16, 0.08)
    assert got[1] == pytest.approx(100 * hand_1) and got[2] == pytest.approx(100 * hand_2)
    assert got[4] == pytest.approx(100 * hand_4) and got[5] is None  # no pair 5 frames apart in 5 frames
    exact = np.concatenate([np.diff(root, axis=0), np.zeros((1, 3))]).T  # entry t = root[t + 1] - root[t]
    assert path_errors(type("M", (), {"path": Fixed(exact)})(), pool, horizons=(1, 4))[4] == pytest.approx(0, abs=1e-5)


def test_a_generator_that_reads_its_base_corrects_what_it_sees():
    """``base_input``: the residual depends on the base (blind, one residual for any base); zero output gives it."""
    J, T = 5, 64
    rcfk = _tiny_rcfk(J)
    torch.manual_seed(0)
    dense = torch.randn(1, 6 * J, T)
    bases = torch.randn(2, rcfk.channels, T)
    for reads in (False, True):
        torch.manual_seed(1)
        g = Generator(J, rcfk, [8] * 6, [8] * 13, base_input=reads).eval()
        with torch.no_grad():
            residual = [g(dense, base=b[None]) - b[None] for b in bases]
        assert torch.allclose(residual[0], residual[1], atol=1e-5) is not reads  # (v + b) - b: rounding
    zero = Generator(J, rcfk, [8] * 6, [8] * 13, output_init="zero", base_input=True).eval()
    with torch.no_grad():
        assert torch.equal(zero(dense, base=bases[:1]), bases[:1])  # a fresh one gives its base
    with pytest.raises(ValueError, match="give base"):
        zero(dense)
