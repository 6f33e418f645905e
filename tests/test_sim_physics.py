"""Physical sanity of the simulated lamp, the annealing search and the hop extraction."""

from __future__ import annotations

import math

import numpy as np
import pytest

from keyfill.characters.lamp import to_variables
from keyfill.sim.controller import REFERENCE, Controller
from keyfill.sim.extract import extract
from keyfill.sim.hops import analyse, energy, link_clearances, satisfactory
from keyfill.sim.physics import LampWorld
from keyfill.sim.search import accept_probability, anneal, run_generator, temperature
from keyfill.sim.settings import Settings

SETTINGS = Settings()


@pytest.fixture(scope="module")
def world():
    with LampWorld(SETTINGS) as w:
        yield w


@pytest.fixture(scope="module")
def runs(world):
    """The first three accepted of some short annealing runs (5 iterations each)."""
    accepted = []
    for r in range(10):
        res = anneal(seed=0, run=r, iterations=5, settings=SETTINGS, world=world)
        if res.accepted:
            accepted.append(res)
        if len(accepted) == 3:
            return accepted
    pytest.fail("fewer than 3 of 10 short runs were accepted")


def test_short_runs_hop_three_times_without_falling(runs):
    s = SETTINGS
    for res in runs:
        assert res.episodes == 6
        assert 0.0 <= res.w_e <= 1.0
        ep, hops = res.episode, res.hops
        assert math.isfinite(res.energy)
        assert res.energy == pytest.approx(-(1 - res.w_e) * hops.distance - res.w_e * hops.max_height)
        assert hops.count == 3 and not hops.fell and satisfactory(hops, s) is None
        assert hops.distance >= s.min_distance and hops.max_height >= s.min_height
        clear = link_clearances(ep.states, s.dimensions)
        base = clear[:, 0]
        # Resting on the ground at the start and the end; only the base ever touches it.
        assert base[0] <= s.contact_tolerance and base[-1] <= s.contact_tolerance
        assert abs(ep.states[-1, 2]) <= s.max_final_tilt
        assert clear[:, 1:].min() > 0.0
        for a, b in zip(hops.liftoffs, hops.landings):
            assert base[a] <= s.contact_tolerance < base[a + 1]  # liftoff: last sample on the ground
            assert base[b] <= s.contact_tolerance < base[b - 1]  # landing: first sample back on it
            assert base[a + 1 : b].min() > s.contact_tolerance  # all of the hop in the air
            assert (b - a) * s.time_step >= s.min_air_time
            assert base[a:b].max() > 0.01  # a real hop, not a skid
        assert np.all(hops.landings[:-1] < hops.liftoffs[1:])  # one hop at a time
        # Joint limits hold; Bullet enforces them as constraints that give by a few hundredths of a radian on impact.
        angles = ep.states[:, 3:]
        assert np.all(angles >= np.array(s.lower_limits) - 0.05)
        assert np.all(angles <= np.array(s.upper_limits) + 0.05)
        assert np.all(np.isfinite(ep.states))


def test_extracted_keys_sit_at_liftoff_in_the_air_and_at_landing(runs):
    s = SETTINGS
    for res in runs:
        seq = extract(res.episode, res.hops, run_generator(0, res.run, stream=1), s)
        m = seq.motion
        assert m.num_frames == 3 * 25 + 2 * 6 == 87 and m.fps == s.fps
        assert seq.liftoff_frames.tolist() == [0, 31, 62]
        assert seq.landing_frames.tolist() == [24, 55, 86]
        assert np.all((seq.air_frames > seq.liftoff_frames) & (seq.air_frames < seq.landing_frames))
        assert sorted(m.keys.to_list()) == m.keys.to_list() and len(m.keys) == 9
        assert set(m.keys.to_list()) == set(seq.liftoff_frames) | set(seq.air_frames) | set(seq.landing_frames)
        values = to_variables(m)
        # Liftoff and landing frames are exactly the simulated samples.
        np.testing.assert_allclose(values[seq.liftoff_frames], res.episode.states[res.hops.liftoffs], atol=1e-12)
        np.testing.assert_allclose(values[seq.landing_frames], res.episode.states[res.hops.landings], atol=1e-12)
        clear = link_clearances(values, s.dimensions)[:, 0]
        assert np.all(clear[seq.liftoff_frames] <= s.contact_tolerance)
        assert np.all(clear[seq.landing_frames] <= s.contact_tolerance)
        assert np.all(clear[seq.air_frames] > s.contact_tolerance)
        # Frames are evenly spaced in time within each hop and increase overall.
        t = seq.frame_times
        assert np.all(np.diff(t) > 0)
        hop = t[seq.liftoff_frames[0] : seq.landing_frames[0] + 1]
        np.testing.assert_allclose(np.diff(hop), np.diff(hop)[0])


def test_resets_are_exact(world):
    """An episode does not depend on what the world simulated before, nor on the world."""
    rng = np.random.default_rng(0)
    first = world.simulate(REFERENCE)
    for _ in range(3):
        world.simulate(REFERENCE.neighbour(rng, SETTINGS))
    again = world.simulate(REFERENCE)
    assert np.array_equal(first.states, again.states)
    with LampWorld(SETTINGS) as fresh:
        assert np.array_equal(fresh.simulate(REFERENCE).states, first.states)


def test_a_lamp_that_flips_over_is_a_fall(world):
    # Throw the leg far back and the head forward as hard as the motors allow, again and again.
    wild = Controller([0.05, 0.05, 0.05, 0.05], [[1.3, 2.6, 1.8], [-1.3, -2.6, -1.8]] * 2)
    ep = world.simulate(wild)
    hops = analyse(ep, SETTINGS)
    assert hops.fell and energy(hops, 0.5) == math.inf
    assert satisfactory(hops, SETTINGS) == "fell over"


def test_neighbour_moves_one_duration_and_one_angle_per_pose():
    rng = np.random.default_rng(4)
    s = SETTINGS
    start = Controller([0.2, 0.2, 0.2, 0.2], np.zeros((4, 3)))
    for _ in range(20):
        n = start.neighbour(rng, s)
        dd = n.durations - start.durations
        assert np.count_nonzero(dd) == 1 and abs(dd[dd != 0][0]) == pytest.approx(0.007)
        dp = n.poses - start.poses
        assert np.all(np.count_nonzero(dp, axis=1) == 1)
        np.testing.assert_allclose(np.abs(dp).sum(axis=1), 0.5)
    edge = Controller([0.02, 0.6, 0.2, 0.2], [s.upper_limits] * 4)
    for _ in range(20):
        n = edge.neighbour(rng, s)
        assert np.all(n.durations >= s.min_duration) and np.all(n.durations <= s.max_duration)
        assert np.all(n.poses <= np.array(s.upper_limits))


def test_annealing_schedule_and_acceptance():
    assert temperature(0, SETTINGS) == 2.0
    assert temperature(1000, SETTINGS) == pytest.approx(1.0, abs=1e-3)  # 0.999307 halves T every 1000 steps
    assert accept_probability(-0.1, 1.5) == 1.0
    assert accept_probability(0.3, 1.5) == pytest.approx(math.exp(-0.2))
    assert accept_probability(math.inf, 1.5) == 0.0
    assert accept_probability(-math.inf, 1.5) == 1.0
    assert accept_probability(math.nan, 1.5) == 0.0


def test_runs_depend_only_on_seed_and_run(world):
    a = anneal(seed=7, run=3, iterations=3, settings=SETTINGS, world=world)
    b = anneal(seed=7, run=3, iterations=3, settings=SETTINGS)  # its own world
    c = anneal(seed=8, run=3, iterations=3, settings=SETTINGS, world=world)
    assert a.w_e == b.w_e and a.accepted == b.accepted
    if a.accepted:
        assert np.array_equal(a.episode.states, b.episode.states)
        assert np.array_equal(a.controller.poses, b.controller.poses)
    assert a.w_e != c.w_e
