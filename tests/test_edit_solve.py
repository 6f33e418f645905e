"""Tangent-space optimisation: the guarantees of edit-tangents and pose, each checked on values."""

from __future__ import annotations

import numpy as np
import pytest
from test_edit_character import character
from test_usd_curves import pxr_values

from keyfill.edit import edits, qp, solve
from keyfill.edit.checks import LIMIT_SAMPLES_PER_FRAME
from keyfill.edit.fit import fit
from keyfill.edit.rig import Point
from keyfill.edit.session import WorkingCurves
from keyfill.errors import FormatError, InfeasibleError
from keyfill.io import usd_curves

#: pins and contacts around a reach of the left hand; the elbow limit is active
GUARDED = """
pins = [{joint = "Head", offset = [0, 16, 0]}]

[limits]
"LowerArm_L.Yrotation" = [0, 71]
"UpperArm_L" = [-120, 120]

[stiffness]
Spine = 3

[[contact]]
joint = "Toes_L"
frames = [10, 20]

[[contact]]
joint = "Toes_R"
frames = [0, 40]

[[edit]]
joint = "Hand_L"
offset = [8, 0, 0]
frame = 15
move = [0, 12, 10]

[[edit]]
joint = "Hand_L"
frame = 35
move = [-4, 3, 6]
"""


@pytest.fixture(scope="module")
def curves():
    m = character()
    return fit(m, m.keys)


def load(tmp_path, curves, text, name="e.toml", mode="tangents"):
    path = tmp_path / name
    path.write_text(text)
    return edits.load(path, curves, mode=mode)


@pytest.fixture(scope="module")
def guarded(curves, tmp_path_factory):
    ef = load(tmp_path_factory.mktemp("edit"), curves, GUARDED)
    out, reports = solve.edit_tangents(curves, ef)
    return ef, out, reports


@pytest.mark.parametrize("mode", ["tangents", "pose"])
def test_a_point_nothing_can_move_is_refused(tmp_path, curves, mode):
    """Every control that moves the hand is fixed by a pin on the hand itself."""
    text = """
pins = [{joint = "Hand_L"}]

[[edit]]
joint = "Hand_L"
frame = 15
move = [0, 5, 0]
"""
    if mode == "pose":
        text = text.replace("frame = 15", "frame = 20")
    ef = load(tmp_path, curves, text, mode=mode)
    run = solve.edit_tangents if mode == "tangents" else solve.pose
    with pytest.raises(InfeasibleError, match="nothing can move the point"):
        run(curves, ef)


def world(curves, points, times):
    return WorkingCurves(curves).states(points, times)


def test_edits_reach_their_targets(curves, guarded):
    ef, out, reports = guarded
    eps = 1e-4 * solve.character_size(curves.skeleton)
    assert [r.reached for r in reports] == [True, True]
    before = world(curves, [ef.edits[0].point, ef.edits[1].point], [15.0, 35.0])
    after = world(out, [ef.edits[0].point, ef.edits[1].point], [15.0, 35.0])
    np.testing.assert_allclose(after[0][0][0] - before[0][0][0], [0, 12, 10], atol=10 * eps)
    np.testing.assert_allclose(after[1][0][1] - before[1][0][1], [-4, 3, 6], atol=10 * eps)
    assert reports[0].optimised_tangents == 2 * reports[0].optimised_controls > 0
    assert "contact Toes_L frames 10-20" in reports[0].constraints


def test_keys_never_change_and_no_key_is_added(curves, guarded):
    _, out, _ = guarded
    np.testing.assert_array_equal(out.times, curves.times)
    np.testing.assert_array_equal(out.values, curves.values)
    assert out.controls == curves.controls
    assert not np.array_equal(out.out_tan, curves.out_tan)  # only tangents moved


def test_limits_hold_at_every_sampled_time(curves, guarded):
    ef, out, reports = guarded
    t = np.arange(0, curves.times[-1] + 1e-9, 1 / LIMIT_SAMPLES_PER_FRAME)  # 10 samples per frame
    cols = sorted(ef.limits)
    vals = out.evaluate(t, cols)
    low = np.array([ef.limits[c][0] for c in cols])
    high = np.array([ef.limits[c][1] for c in cols])
    assert np.all(vals >= low - 1e-12) and np.all(vals <= high + 1e-12)
    # the elbow limit mattered: without it the same edits go past 71 degrees
    free = ef.__class__(**{**ef.__dict__, "limits": {}})
    unlimited, _ = solve.edit_tangents(curves, free)
    elbow = curves.control_index("LowerArm_L.Yrotation")
    assert unlimited.evaluate(t, [elbow]).max() > np.radians(71) + 1e-3
    assert min(r.worst_limit_margin for r in reports) >= 0


def test_pins_and_contacts_stay_within_epsilon(curves, guarded):
    ef, out, reports = guarded
    eps = 1e-4 * solve.character_size(curves.skeleton)
    frames = np.arange(41.0)
    pin = ef.pins[0]
    old, new = world(curves, [pin], frames)[0], world(out, [pin], frames)[0]
    assert np.linalg.norm(new[0] - old[0], axis=-1).max() <= eps
    for c in ef.contacts:
        f = frames[(frames >= c.start) & (frames <= c.end)]
        pos = world(out, [c.point], f)[0][0]
        assert np.linalg.norm(pos - pos[0], axis=-1).max() <= eps  # the feet of the input stand still
    assert max(r.worst_pin_violation for r in reports) <= eps
    assert max(r.worst_contact_violation for r in reports) <= eps


def test_results_are_deterministic(curves, guarded, tmp_path):
    ef, out, _ = guarded
    again, _ = solve.edit_tangents(curves, ef)
    for name in ("in_tan", "out_tan", "broken"):
        np.testing.assert_array_equal(getattr(again, name), getattr(out, name))
    for name, result in (("a", out), ("b", again)):  # one file name: the animation takes the output's stem
        (tmp_path / name).mkdir()
        usd_curves.save(result, tmp_path / name / "out.usda")
    assert (tmp_path / "a" / "out.usda").read_bytes() == (tmp_path / "b" / "out.usda").read_bytes()


def test_output_curves_evaluate_the_same_in_pxr(guarded, tmp_path):
    _, out, _ = guarded
    usd_curves.save(out, tmp_path / "out.usdc")
    t = np.linspace(0, 40, 401)
    assert np.abs(pxr_values(tmp_path / "out.usdc", out, t) - out.evaluate(t)).max() < 1e-6


def test_unified_keys_stay_unified(curves, guarded):
    _, out, _ = guarded
    assert not out.broken.any()
    slope_in = out.in_tan[..., 1] / out.in_tan[..., 0]
    slope_out = out.out_tan[..., 1] / out.out_tan[..., 0]
    np.testing.assert_allclose(slope_in[1:-1], slope_out[1:-1], rtol=1e-9, atol=1e-12)


def test_qp_agrees_across_backends(curves, tmp_path, monkeypatch):
    programs = []
    real = qp.solve

    def spy(program, solver="daqp"):
        programs.append(program)
        return real(program, solver)

    monkeypatch.setattr(qp, "solve", spy)
    spine = np.degrees(curves.values[:, curves.control_index("Spine.Xrotation")])
    tight = f'"Spine.Xrotation" = [{spine.min() - 0.5}, {spine.max() + 0.5}]\n'
    ef = load(tmp_path, curves, GUARDED.replace("[limits]\n", "[limits]\n" + tight))
    solve.edit_tangents(curves, ef, best_effort=True)
    monkeypatch.setattr(qp, "solve", real)
    assert programs
    for program in programs[:3]:
        assert program.G.shape[0] > 0 and np.isfinite(program.lb).any()
        x = {s: qp.solve(program, s).x for s in ("daqp", "quadprog")}
        x["piqp"] = qp.solve(program, "piqp", eps_abs=1e-12, eps_rel=1e-12).x  # interior point: tighten
        scale = max(1.0, np.abs(x["daqp"]).max())
        assert np.abs(x["daqp"] - x["quadprog"]).max() <= 1e-6 * scale
        assert np.abs(x["daqp"] - x["piqp"]).max() <= 1e-6 * scale
    # and the whole edit comes out the same with another backend
    a, _ = solve.edit_tangents(curves, ef, solver="daqp")
    b, _ = solve.edit_tangents(curves, ef, solver="quadprog")
    np.testing.assert_allclose(a.out_tan, b.out_tan, atol=1e-6)
    np.testing.assert_allclose(a.in_tan, b.in_tan, atol=1e-6)


def test_a_small_move_is_reached_in_one_step(curves, tmp_path):
    """The Jacobian J_s = ds/dc dc/dtheta is right: the linear step lands on a small target."""
    text = "tolerance = 1e-9\n[[edit]]\njoint = 'Hand_L'\noffset = [8, 0, 0]\nframe = 14\nmove = [0.05, -0.08, 0.06]\n"
    ef = load(tmp_path, curves, text)
    one = solve.Settings(max_iterations=1)
    _, (r,) = solve.edit_tangents(curves, ef, best_effort=True, settings=one)
    assert r.iterations == 1 and r.distance < 1e-3 * 0.11  # error second order in the 0.11 cm move


def test_the_reduction_of_section_3_3(curves, tmp_path):
    base = "[[edit]]\njoint = 'Hand_L'\nframe = 15\nmove = [0, 2, 0]\n"
    names = lambda r: r.constraints
    _, (alone,) = solve.edit_tangents(curves, load(tmp_path, curves, base))
    # case 2: the hips lie on the hand's chain; pinning them removes their controls
    _, (hips,) = solve.edit_tangents(curves, load(tmp_path, curves, "pins = ['Hips']\n" + base))
    assert hips.optimised_controls == alone.optimised_controls - 3 and names(hips) == []
    # with its orientation pinned too, all six hip controls go; then a foot shares no
    # control with what is left (case 1) and is ignored
    pins = "pins = [{joint = 'Hips', orientation = true}, 'Toes_L']\n"
    _, (feet,) = solve.edit_tangents(curves, load(tmp_path, curves, pins + base))
    assert feet.optimised_controls == alone.optimised_controls - 6 and names(feet) == []
    # case 3: the right hand shares the spine: kept, its arm joins the optimisation
    _, (right,) = solve.edit_tangents(curves, load(tmp_path, curves, "pins = ['Hand_R']\n" + base))
    assert right.optimised_controls == alone.optimised_controls + 9 and names(right) == ["pin Hand_R"]
    assert right.worst_pin_violation <= 1e-4 * solve.character_size(curves.skeleton)


def test_break_tangents_changes_only_the_segment(curves, tmp_path):
    text = "[[edit]]\njoint = 'Hand_L'\nframe = 15\nmove = [0, 5, 3]\nbreak_tangents = true\n"
    ef = load(tmp_path, curves, text)
    out, (r,) = solve.edit_tangents(curves, ef)
    assert r.reached
    t_out = np.concatenate([np.linspace(0, 10, 31), np.linspace(20, 40, 61)])
    np.testing.assert_allclose(out.evaluate(t_out), curves.evaluate(t_out), atol=1e-12)
    changed = np.flatnonzero(np.abs(out.out_tan[1] - curves.out_tan[1]).max(axis=1) > 0)
    assert len(changed) and out.broken[1, changed].all() and out.broken[2, changed].all()


@pytest.mark.parametrize("frames, break_tangents", [("[0, 10]", "true"), ("[30, 40]", "false")])
def test_a_contact_on_a_segment_that_does_not_change_is_dropped(curves, tmp_path, frames, break_tangents):
    """Issue 15: a contact outside the segments an edit changes holds nothing, so its leg stays out of C.

    It shares the hips' rotations with the hand (case 3), which used to add the leg's controls to
    the optimisation although no sample looked at the leg: indexing them crashed (IndexError).
    """
    edit = f"[[edit]]\njoint = 'Hand_L'\nframe = 15\nmove = [0, 6, 3]\nbreak_tangents = {break_tangents}\n"
    contact = f"[[contact]]\njoint = 'Toes_L'\nframes = {frames}\n"
    alone, (ra,) = solve.edit_tangents(curves, load(tmp_path, curves, "pins = ['Hips']\n" + edit))
    out, (r,) = solve.edit_tangents(curves, load(tmp_path, curves, "pins = ['Hips']\n" + contact + edit))
    assert r.reached and r.constraints == [] and r.optimised_controls == ra.optimised_controls
    np.testing.assert_array_equal(out.out_tan, alone.out_tan)
    np.testing.assert_array_equal(out.in_tan, alone.in_tan)
    legs = [i for i, c in enumerate(curves.controls) if "Leg" in curves.skeleton.names[c.joint]]
    np.testing.assert_array_equal(out.out_tan[:, legs], curves.out_tan[:, legs])


def test_orientation_targets(curves, tmp_path):
    from keyfill import rotations as R

    hand = Point(curves.skeleton.index("Hand_L"), orientation=True)
    ((pos, rot),) = world(curves, [hand], [25.0])
    turn = R.quat_to_matrix(R.quat_from_rotvec(np.radians([0.0, 0.0, 15.0])))
    q = R.quat_from_matrix(turn @ rot[0])
    text = f"[[edit]]\njoint = 'Hand_L'\nframe = 25\ntarget = {pos[0].tolist()}\norientation = {q.tolist()}\n"
    out, (r,) = solve.edit_tangents(curves, load(tmp_path, curves, text))
    ((p2, r2),) = world(out, [hand], [25.0])
    assert r.reached and np.linalg.norm(p2[0] - pos[0]) < 0.2
    assert np.degrees(R.quat_angle(R.quat_from_matrix(r2[0]), q)) < 0.1


def test_an_unreachable_target_names_the_constraints_in_the_way(curves, tmp_path):
    text = """
[[contact]]
joint = "Toes_L"
frames = [10, 20]

[[contact]]
joint = "Toes_R"
frames = [10, 20]

[[edit]]
joint = "Hips"
frame = 15
move = [0, 40, 0]
"""
    ef = load(tmp_path, curves, text)
    with pytest.raises(InfeasibleError, match="cannot reach its target.*contact Toes_"):
        solve.edit_tangents(curves, ef)
    _, (r,) = solve.edit_tangents(curves, ef, best_effort=True)
    eps = 1e-4 * solve.character_size(curves.skeleton)
    assert not r.reached and 1.0 < r.distance < 40.0  # legs stretch as far as they go
    assert r.worst_contact_violation <= eps


def test_timing_edit_rescales_widths_and_keeps_slopes(curves, tmp_path):
    text = "[[edit]]\nframe = 14\ntiming = 2.0\njoint = 'Hand_L'\n"
    out, (r,) = solve.edit_tangents(curves, load(tmp_path, curves, text))
    moved = np.abs(out.out_tan[1, :, 0] - curves.out_tan[1, :, 0]) > 0
    assert r.kind == "timing" and r.optimised_tangents > 0 and moved.any()
    np.testing.assert_allclose(out.out_tan[1, moved, 0], curves.out_tan[1, moved, 0] + 2.0 * 0.4)
    np.testing.assert_allclose(out.in_tan[2, moved, 0], curves.in_tan[2, moved, 0] + 2.0 * 0.6)
    np.testing.assert_allclose(
        out.out_tan[1, :, 1] / out.out_tan[1, :, 0], curves.out_tan[1, :, 1] / curves.out_tan[1, :, 0]
    )
    np.testing.assert_array_equal(out.values, curves.values)
    assert not np.allclose(out.evaluate([14.0]), curves.evaluate([14.0]))


def test_pose_moves_a_key_and_keeps_pins(curves, tmp_path):
    text = "pins = ['Head', 'Hand_R']\n[[edit]]\njoint = 'Hand_L'\nmove = [0, 10, 5]\n"
    with pytest.raises(FormatError, match="needs one of 'frame' or 'time'"):
        load(tmp_path, curves, text, mode="pose")  # no frame in the file and none given
    path = tmp_path / "p.toml"
    path.write_text(text)
    ef = edits.load(path, curves, mode="pose", frame=20)
    out, (r,) = solve.pose(curves, ef)
    hand, head, rhand = (Point(curves.skeleton.index(n)) for n in ("Hand_L", "Head", "Hand_R"))
    before = world(curves, [hand, head, rhand], [20.0])
    after = world(out, [hand, head, rhand], [20.0])
    eps = 1e-4 * solve.character_size(curves.skeleton)
    assert r.reached and r.kind == "pose"
    np.testing.assert_allclose(after[0][0][0] - before[0][0][0], [0, 10, 5], atol=0.2)
    assert np.linalg.norm(after[1][0] - before[1][0]) <= eps and np.linalg.norm(after[2][0] - before[2][0]) <= eps
    changed = np.flatnonzero(np.any(out.values != curves.values, axis=1))
    assert changed.tolist() == [2]  # only the key at frame 20
    np.testing.assert_array_equal(out.out_tan, curves.out_tan)


def test_a_case_2_pin_stays_fixed_when_a_contact_brings_its_chain(curves, tmp_path):
    """Pinned hips leave the optimisation (case 2) and stay out when a foot contact adds the leg (case 3)."""
    text = "pins = ['Hips']\n[[contact]]\njoint = 'Toes_L'\nframes = [10, 20]\n" + (
        "[[edit]]\njoint = 'Hand_L'\nframe = 15\nmove = [0, 6, 3]\n"
    )
    out, (r,) = solve.edit_tangents(curves, load(tmp_path, curves, text))
    assert r.reached and r.worst_pin_violation == 0.0
    for axis in "XYZ":
        c = curves.control_index(f"Hips.{axis}position")
        np.testing.assert_array_equal(out.out_tan[:, c], curves.out_tan[:, c])
    assert "contact Toes_L frames 10-20" in r.constraints  # the hips' rotations still move the leg


def test_a_wobbling_contact_is_not_made_worse(tmp_path):
    """Captured feet wobble while planted: the contact holds them no further from still than they were."""
    from keyfill import rotations as R

    m = character()
    j = m.skeleton.index("UpperLeg_L")
    wobble = np.radians(0.5) * np.sin(2 * np.pi * (np.arange(m.num_frames) - 10) / 10)
    rot = m.rotations.copy()
    rot[:, j] = R.quat_mul(rot[:, j], R.quat_from_rotvec(np.stack([wobble, 0 * wobble, 0 * wobble], -1)))
    c = fit(m.replace(rotations=rot), m.keys)
    text = "pins = ['Hips']\n[[contact]]\njoint = 'Toes_L'\nframes = [10, 20]\n" + (
        "[[edit]]\njoint = 'Hand_L'\nframe = 15\nmove = [0, 6, 3]\n"
    )
    ef = load(tmp_path, c, text)
    out, (r,) = solve.edit_tangents(c, ef)
    toe = ef.contacts[0].point
    f = np.arange(10.0, 21.0)
    before, after = world(c, [toe], f)[0][0], world(out, [toe], f)[0][0]
    still = before[0] + (f - 10)[:, None] / 10 * (before[-1] - before[0])
    wobble_before = np.linalg.norm(before - still, axis=-1)
    assert wobble_before.max() > 0.3  # cm: the input's foot is not still
    eps = 1e-4 * solve.character_size(c.skeleton)
    assert np.all(np.linalg.norm(after - still, axis=-1) <= wobble_before + eps)
    assert r.reached and r.worst_contact_violation <= eps and r.constraints == ["contact Toes_L frames 10-20"]
