"""Pictures: `keyfill plot` (animation curves) and `keyfill preview` (stick figures).

Motions are built in code (a small walker, the hopping lamp) so every check
knows what the picture must hold; the rendered files are read back with
Pillow and checked for size, frame count, timing and pixels.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from conftest import DATA, shared_path
from PIL import Image, ImageSequence

from keyfill import io
from keyfill import rotations as R
from keyfill.characters import lamp
from keyfill.cli.main import main
from keyfill.errors import DataError, UsageError
from keyfill.io import bvh
from keyfill.motion import Keys, Motion, Skeleton
from keyfill.viz import curves as C
from keyfill.viz import frame_range, gif, scene
from keyfill.viz import stick as S
from keyfill.viz.palette import Palette

WALKER_CHANNELS = ("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation")


def walker(frames: int = 24, swing: float = 0.6, speed: float = 4.0, keys=(0, 8, 16, 23)) -> Motion:
    """A 7-joint walker (cm, Y up) that moves along +Z and swings its legs."""
    sk = Skeleton(
        names=("Hips", "Spine", "Head", "LeftUpLeg", "LeftLeg", "RightUpLeg", "RightLeg"),
        parents=np.array([-1, 0, 1, 0, 3, 0, 5]),
        offsets=np.array([[0, 90, 0], [0, 20, 0], [0, 30, 0], [10, -5, 0], [0, -40, 0], [-10, -5, 0], [0, -40, 0]],
                         dtype=float),
        channels=(WALKER_CHANNELS,) + (("Zrotation", "Xrotation", "Yrotation"),) * 6,
        end_sites=((2, np.array([0.0, 15.0, 0.0])), (4, np.array([0.0, -40.0, 0.0])),
                   (6, np.array([0.0, -40.0, 0.0]))),
    )
    t = np.arange(frames) / 30.0
    angles = np.zeros((frames, 7, 3))
    phase = 2 * np.pi * 1.5 * t
    angles[:, 3, 1] = swing * np.sin(phase)  # ZXY order: slot 1 is X
    angles[:, 5, 1] = -swing * np.sin(phase)
    angles[:, 4, 1] = 0.5 * swing * (1 - np.cos(phase))
    angles[:, 6, 1] = 0.5 * swing * (1 + np.cos(phase))
    angles[:, 1, 0] = 0.1 * np.sin(phase)
    angles[:, 0, 2] = 0.05 * np.sin(phase)  # the pelvis turns a little
    rot = R.euler_to_quat(angles, "ZXY")
    pos = np.broadcast_to(sk.offsets, (frames, 7, 3)).copy()
    pos[:, 0, 2] = speed * np.arange(frames)
    pos[:, 0, 1] = 90 + 2 * np.cos(2 * phase)
    return Motion(sk, 30.0, rot, pos, keys=Keys(keys) if keys else None)


def lamp_hop(frames: int = 30, height: float = 0.12) -> Motion:
    """The hopping lamp: one hop of 0.3 m along +X with keys at take-off, apex and landing."""
    t = np.linspace(0.0, 1.0, frames)
    v = np.zeros((frames, 6))
    v[:, 0] = 0.3 * t
    v[:, 1] = 4 * height * t * (1 - t)
    v[:, 2] = 0.2 * np.sin(2 * np.pi * t)
    v[:, 3] = 0.4 - 0.5 * np.sin(np.pi * t)
    v[:, 4] = -0.9 + 0.6 * np.sin(np.pi * t)
    v[:, 5] = 0.8 - 0.3 * np.cos(2 * np.pi * t)
    return lamp.from_variables(v, 30.0, keys=Keys([0, frames // 2, frames - 1]))


def pixels(path) -> np.ndarray:
    return np.asarray(Image.open(path).convert("RGB"), dtype=np.int16)


def gif_frames(path) -> tuple[list[np.ndarray], list[int]]:
    im = Image.open(path)
    frames, delays = [], []
    for f in ImageSequence.Iterator(im):
        frames.append(np.asarray(f.convert("RGB"), dtype=np.int16))
        delays.append(f.info["duration"])
    return frames, delays


def changed(a: np.ndarray, b: np.ndarray) -> int:
    """Number of pixels that differ between two RGB pictures."""
    return int(np.any(a != b, axis=-1).sum())


# --- plot --------------------------------------------------------------------


def test_channel_curves_are_the_bvh_channel_values():
    motion = io.load(DATA / "bvhtoolbox_test_freebvh_mixamo.bvh")
    curves = C.channel_curves(motion)
    expected = bvh.pose_to_channels(motion)  # what the BVH writer would write: degrees, file order
    assert curves.values.shape == expected.shape
    np.testing.assert_allclose(curves.values, expected, atol=1e-9)
    assert curves.names[:4] == ("mixamorig:Hips.Xposition", "mixamorig:Hips.Yposition",
                                "mixamorig:Hips.Zposition", "mixamorig:Hips.Zrotation")
    assert curves.units[0] == "cm" and curves.units[3] == "deg"


def test_position_curves_are_world_positions():
    motion = walker()
    curves = C.position_curves(motion)
    world = motion.world_positions()
    j = motion.skeleton.index("LeftLeg")
    np.testing.assert_allclose(curves.values[:, curves.names.index("LeftLeg.y")], world[:, j, 1])
    assert curves.values.shape == (24, 21)


def test_lamp_curves_are_the_six_variables_in_degrees():
    motion = lamp_hop()
    curves = C.lamp_curves(motion)
    assert curves.names == tuple(v.name for v in lamp.VARIABLES)
    assert curves.units == ("m", "m", "deg", "deg", "deg", "deg")
    np.testing.assert_allclose(curves.values[:, 1], lamp.to_variables(motion)[:, 1])
    np.testing.assert_allclose(np.deg2rad(curves.values[:, 3]), lamp.to_variables(motion)[:, 3])
    assert C.lamp_curves(walker()) is None


def test_panel_selection():
    motion = walker()
    curves = C.channel_curves(motion)
    # 23 animated channels: more than a figure shows by default, so the first moving joint's;
    # Hips.Xposition stays at the rest offset and is no animation variable.
    assert curves.animated.sum() == 23
    sel = C.select_panels(curves, motion)
    assert [curves.names[i] for i in sel] == ["Hips.Yposition", "Hips.Zposition", "Hips.Zrotation",
                                              "Hips.Xrotation", "Hips.Yrotation"]
    sel = C.select_panels(curves, motion, joints=["LeftLeg,RightLeg"], channels=["Xrotation"])
    assert [curves.names[i] for i in sel] == ["LeftLeg.Xrotation", "RightLeg.Xrotation"]
    sel = C.select_panels(curves, motion, channels=["hips.zposition", "Head.Yrotation"])
    assert [curves.names[i] for i in sel] == ["Hips.Zposition", "Head.Yrotation"]
    with pytest.raises(UsageError, match="unknown joint 'Knee'; joints are: Hips, Spine"):
        C.select_panels(curves, motion, joints=["Knee"])
    with pytest.raises(UsageError, match=r"unknown channel 'Wrotation'; valid: .*LeftLeg\.Xrotation"):
        C.select_panels(curves, motion, joints=["LeftLeg"], channels=["Wrotation"])


def test_default_panels_of_a_human_are_the_first_moving_joint():
    motion = io.load(DATA / "bvhtoolbox_test_freebvh_mixamo.bvh")
    curves = C.channel_curves(motion)
    sel = C.select_panels(curves, motion)
    assert {curves.joints[i] for i in sel} == {"mixamorig:Hips"}
    assert len(sel) == 6


def test_plot_png_size_and_content(tmp_path):
    info = C.plot([lamp_hop()], ["truth"], tmp_path / "a.png")
    assert info.panels == tuple(v.name for v in lamp.VARIABLES)
    im = Image.open(tmp_path / "a.png")
    assert im.format == "PNG" and 600 <= im.width <= 1000 and 700 <= im.height <= 1200
    a = pixels(tmp_path / "a.png")
    # A different motion gives a different picture, and the keys' circles show.
    C.plot([lamp_hop(height=0.2)], ["truth"], tmp_path / "b.png")
    assert changed(a, pixels(tmp_path / "b.png")) > 1000
    C.plot([lamp_hop().replace(keys=None)], ["truth"], tmp_path / "c.png")
    assert changed(a, pixels(tmp_path / "c.png")) > 100
    # A second file adds its colour (orange) to the picture.
    C.plot([lamp_hop(), lamp_hop(height=0.2)], ["truth", "other"], tmp_path / "d.png")
    d = pixels(tmp_path / "d.png")
    orange = np.all(np.abs(d - [255, 127, 14]) < 8, axis=-1).sum()
    assert orange > 500 and np.all(np.abs(a - [255, 127, 14]) < 8, axis=-1).sum() == 0


def test_plot_is_byte_for_byte_deterministic(tmp_path):
    for ext in ("png", "svg", "pdf"):
        C.plot([walker()], ["w"], tmp_path / f"1.{ext}", joints=["Hips"])
        C.plot([walker()], ["w"], tmp_path / f"2.{ext}", joints=["Hips"])
        one, two = (tmp_path / f"1.{ext}").read_bytes(), (tmp_path / f"2.{ext}").read_bytes()
        assert one == two, ext
        assert b"Matplotlib v" not in one and b"CreationDate" not in one


def test_pictures_ignore_the_users_matplotlib_settings(tmp_path):
    import matplotlib

    C.plot([walker()], ["w"], tmp_path / "a.png", joints=["Hips"])
    S.preview([walker()], ["w"], tmp_path / "a.gif", size=(96, 80), frames=":4")
    with matplotlib.rc_context({"lines.linewidth": 5, "font.size": 20, "axes.prop_cycle": matplotlib.cycler(
            color=["k"]), "figure.facecolor": "black"}):
        C.plot([walker()], ["w"], tmp_path / "b.png", joints=["Hips"])
        S.preview([walker()], ["w"], tmp_path / "b.gif", size=(96, 80), frames=":4")
    assert (tmp_path / "a.png").read_bytes() == (tmp_path / "b.png").read_bytes()
    assert (tmp_path / "a.gif").read_bytes() == (tmp_path / "b.gif").read_bytes()


def test_plot_frame_range_keeps_file_numbering(tmp_path):
    info = C.plot([walker()], ["w"], tmp_path / "r.png", frames="5:15", joints=["Hips"])
    assert info.frames == (5, 14)
    np.testing.assert_array_equal(frame_range("-4:", 24), [20, 21, 22, 23])
    np.testing.assert_array_equal(frame_range(None, 3), [0, 1, 2])


def test_plot_of_files_with_different_variables_fails(tmp_path):
    with pytest.raises(DataError, match="lamp: has no Hips.Yposition"):
        C.plot([walker(), lamp_hop()], ["walker", "lamp"], tmp_path / "x.png")
    assert not any(tmp_path.iterdir())


# --- preview geometry ------------------------------------------------------------


def test_limb_sides():
    left = ["LeftUpLeg", "mixamorig:LeftHand", "UpperArm_L", "l_knee", "LHipJoint", "Foot.L"]
    right = ["RightArm", "Hand_R", "RThumb", "r_elbow"]
    centre = ["Hips", "Spine1", "Head", "LowerBack", "joint_Root", "Leg", "LUMBAR", "Root"]
    assert [scene.limb_side(n) for n in left] == [-1] * len(left)
    assert [scene.limb_side(n) for n in right] == [1] * len(right)
    assert [scene.limb_side(n) for n in centre] == [0] * len(centre)


def test_bones_skip_translated_joints_and_include_end_sites():
    motion = walker()
    f = scene.figure_points(motion)
    J = motion.num_joints
    assert f.points.shape == (24, J + 3, 3)
    bones = {tuple(b) for b in f.bones.tolist()}
    assert bones == {(0, 1), (1, 2), (0, 3), (3, 4), (0, 5), (5, 6), (2, J), (4, J + 1), (6, J + 2)}
    # A static root above a translated hips (Bandai's layout) gets no bone to the hips.
    sk = motion.skeleton
    rooted = Skeleton(("Root",) + sk.names, np.concatenate([[-1], sk.parents + 1]),
                      np.vstack([[0, 0, 0], sk.offsets]), ((),) + sk.channels)
    m = Motion(rooted, 30, np.concatenate([R.quat_identity((24, 1)), motion.rotations], axis=1),
               np.concatenate([np.zeros((24, 1, 3)), motion.positions], axis=1))
    assert (0, 1) not in {tuple(b) for b in scene.figure_points(m).bones.tolist()}


def test_lamp_figure_has_base_plate_and_shade():
    motion = lamp_hop()
    f = scene.figure_points(motion)
    assert len(f.bones) == 3 + 4  # base-leg-neck-head chain, plate, two shade sides and its rim
    plate = f.points[:, f.bones[3]]
    np.testing.assert_allclose(np.linalg.norm(plate[:, 0] - plate[:, 1], axis=-1), lamp.DIMENSIONS.base_length)


def test_cameras():
    motion = walker()
    f = scene.figure_points(motion)
    h = scene.travel_axis(f.points, f.used, "Y")
    np.testing.assert_array_equal(h, [0, 0, 1])  # walks along +Z
    side = scene.make_camera("side", h, "Y")
    np.testing.assert_allclose(side.right, [0, 0, 1])
    np.testing.assert_allclose(side.up, [0, 1, 0])
    top = scene.make_camera("top", h, "Y")
    np.testing.assert_allclose(np.cross(top.right, top.up), [0, 1, 0], atol=1e-12)  # seen from above
    front = scene.make_camera("front", h, "Y")
    np.testing.assert_allclose(np.cross(front.right, front.up), [0, 0, 1], atol=1e-12)  # faces the walker
    backwards = motion.replace(positions=motion.positions * [1, 1, -1])
    fb = scene.figure_points(backwards)
    np.testing.assert_array_equal(scene.travel_axis(fb.points, fb.used, "Y"), [0, 0, -1])
    for view in scene.VIEWS:
        cam = scene.make_camera(view, np.array([0.0, -1.0, 0.0]), "Z")
        assert abs(np.linalg.norm(cam.right) - 1) < 1e-12 and abs(cam.right @ cam.up) < 1e-12


def test_gif_timing_and_step():
    delays = gif.delays_ms(30, 30.0)
    assert set(delays) == {30, 40} and sum(delays) == 1000
    assert gif.gif_step(30.0) == 1 and gif.gif_step(120.0) == 3 and gif.gif_step(120.0, 5) == 5
    assert sum(gif.delays_ms(40, 120.0, 3)) == 1000


def test_palette_keeps_flat_colours_exact():
    rng = np.random.default_rng(0)
    a = np.full((40, 60, 3), 255, dtype=np.uint8)
    a[10:20, 5:50] = (31, 119, 180)
    a[25:30] = rng.integers(0, 256, size=(5, 60, 3))
    pal = Palette([Image.fromarray(a)], 16, required=[(51, 51, 51)])
    out = np.asarray(pal.apply(Image.fromarray(a)).convert("RGB"))
    assert np.array_equal(out[:10], a[:10]) and np.array_equal(out[10:20, 5:50], a[10:20, 5:50])
    assert (51, 51, 51) in {tuple(c) for c in pal.rgb.tolist()}


# --- preview outputs -------------------------------------------------------------


def test_preview_gif_frames_timing_and_motion(tmp_path):
    info = S.preview([walker()], ["w"], tmp_path / "w.gif", size=(160, 120))
    frames, delays = gif_frames(tmp_path / "w.gif")
    assert len(frames) == 24 and info.frames == tuple(range(24))
    assert frames[0].shape == (120, 160, 3)
    assert sum(delays) == 800  # 24 frames at 30 fps
    # Every frame differs from the next (the figure moves) ...
    assert min(changed(a, b) for a, b in itertools.pairwise(frames)) > 20
    # ... while the fixed camera keeps the ground where it was: the bottom rows, below the feet, never change.
    ground_rows = [np.flatnonzero(np.all(np.abs(f - [176, 176, 176]) < 12, axis=-1).sum(axis=1) > 40) for f in frames]
    assert all(np.array_equal(r, ground_rows[0]) for r in ground_rows) and len(ground_rows[0])
    # Keys are pink: at key frame 8 the figure is drawn in the key colour, at frame 4 only ghosts are pink.
    pink = [np.all(np.abs(f - [231, 41, 138]) < 10, axis=-1).sum() for f in frames]
    assert pink[8] > 3 * pink[4] and pink[4] == 0


def test_preview_gif_step_fps_and_frames(tmp_path):
    info = S.preview([walker()], ["w"], tmp_path / "w.gif", size=(96, 80), frames="4:20", step=3, fps=15)
    frames, delays = gif_frames(tmp_path / "w.gif")
    assert info.frames == (4, 7, 10, 13, 16, 19) and len(frames) == 6
    assert sum(delays) == 1200 and info.fps == 5.0  # every 3rd frame at 15 fps: 6 frames of 0.2 s


def test_preview_differs_between_inputs_and_is_deterministic(tmp_path):
    S.preview([walker()], ["w"], tmp_path / "a.gif", size=(128, 96))
    S.preview([walker()], ["w"], tmp_path / "b.gif", size=(128, 96))
    assert (tmp_path / "a.gif").read_bytes() == (tmp_path / "b.gif").read_bytes()
    S.preview([walker(swing=0.2)], ["w"], tmp_path / "c.gif", size=(128, 96))
    fa, _ = gif_frames(tmp_path / "a.gif")
    fc, _ = gif_frames(tmp_path / "c.gif")
    assert changed(fa[5], fc[5]) > 20
    S.preview([walker()], ["w"], tmp_path / "a.png", size=(128, 96))
    S.preview([walker()], ["w"], tmp_path / "b.png", size=(128, 96))
    assert (tmp_path / "a.png").read_bytes() == (tmp_path / "b.png").read_bytes()


def test_preview_filmstrip(tmp_path):
    info = S.preview([walker()], ["w"], tmp_path / "s.png", size=(100, 120), view="3d")
    assert info.kind == "filmstrip" and len(info.frames) == 8 and info.frames[0] == 0 and info.frames[-1] == 23
    im = pixels(tmp_path / "s.png")
    assert im.shape == (120 + 8, 8 * 104 + 4, 3)
    cells = [im[4:124, 4 + i * 104: 104 + i * 104] for i in range(8)]
    assert min(changed(a, b) for a, b in itertools.pairwise(cells)) > 20
    info = S.preview([walker()], ["w"], tmp_path / "t.png", size=(100, 120), step=2)
    assert len(info.frames) == 12
    assert pixels(tmp_path / "t.png").shape == (2 * 124 + 4, 8 * 104 + 4, 3)  # two rows of 8


@pytest.mark.parametrize("name", ["strip.png", "anim.gif", "still.png"])
@pytest.mark.parametrize("motion", ["walker", "lamp"])
def test_preview_reports_the_size_of_the_file_written_and_default_pictures_are_readable(tmp_path, capsys, name,
                                                                                        motion):
    """--json's size is the written file's (a filmstrip: the whole sheet); frame_size one frame; default frames are
    at least 300 px on each side (a filmstrip frame 300 px tall), also for a wide lamp hop."""
    src = tmp_path / "m.usda"
    io.save(walker() if motion == "walker" else lamp_hop(), src)
    out = tmp_path / name
    trail = ["--trail", "LeftLeg" if motion == "walker" else "head"] if name == "still.png" else []
    code = main(["preview", str(src), "-o", str(out), "--json", *trail])
    d = __import__("json").loads(capsys.readouterr().out)
    assert code == 0
    with Image.open(out) as im:
        written = im.size
        frames = getattr(im, "n_frames", 1)
    assert tuple(d["size"]) == written
    w, h = d["frame_size"]
    if name == "strip.png":
        assert h == S.STRIP_HEIGHT >= 300 and d["kind"] == "filmstrip"
        cols = min(S.STRIP_COLUMNS, d["frames"])
        rows = -(-d["frames"] // cols)
        assert written == (cols * (w + 4) + 4, rows * (h + 4) + 4)  # the cells and their 4 px gaps
    else:
        assert (w, h) == written and min(written) >= S.MIN_SIDE >= 300
        assert frames == (d["frames"] if name == "anim.gif" else 1)
    code = main(["preview", str(src), "-o", str(tmp_path / ("again_" + name)), *trail])
    assert code == 0 and f"{written[0]}x{written[1]} px" in capsys.readouterr().err


def test_preview_trail_still_shows_the_path(tmp_path):
    before = walker()
    after = walker(swing=0.9)
    info = S.preview([before, after], ["before", "after"], tmp_path / "t.png", trail=["LeftLeg"], size=(300, 200))
    assert info.kind == "still" and info.frames == (0, 8, 16, 23)  # the ghosted keys
    both = pixels(tmp_path / "t.png")
    assert both.shape == (200, 300, 3)
    r, g, b = both[..., 0], both[..., 1], both[..., 2]
    blue, orange = (b > r + 60).sum(), (r > b + 100) & (g > b + 40)
    assert blue > 100 and orange.sum() > 100
    S.preview([before], ["before"], tmp_path / "one.png", trail=["LeftLeg"], size=(300, 200))
    assert changed(both, pixels(tmp_path / "one.png")) > 100


def test_preview_lamp_has_a_ground_line_and_humans_a_grid(tmp_path):
    lamp_r = S.StickRenderer([lamp_hop()], ["lamp"], "3d", (200, 160), 0)
    human_r = S.StickRenderer([walker()], ["w"], "3d", (200, 160), 0)
    side_r = S.StickRenderer([walker()], ["w"], "side", (200, 160), 0)
    assert not lamp_r.ground_is_grid and human_r.ground_is_grid and not side_r.ground_is_grid
    assert len(lamp_r.ground) == 1 and len(human_r.ground) >= 6
    grey = [np.all(np.abs(r.render(None).astype(int)[..., :3] - c) < 20, axis=-1).sum()
            for r, c in ((lamp_r, 176), (human_r, 210))]
    assert grey[1] > 3 * grey[0] > 0  # a grid of 6 or more lines, a single line


# --- command line ------------------------------------------------------------------


@pytest.fixture
def files(tmp_path):
    io.save(walker(), tmp_path / "walk.usda", sparse=False)
    io.save(lamp_hop(), tmp_path / "lamp.usda")
    empty = walker().frames(slice(0, 0))
    io.save(empty, tmp_path / "empty.bvh")
    return tmp_path


def test_cli_plot_and_preview(files, capsys):
    out = files / "out"
    out.mkdir()
    assert main(["plot", str(files / "lamp.usda"), str(files / "lamp.usda"), "--labels", "truth,cubic",
                 "-o", str(out / "lamp.svg"), "--json"]) == 0
    assert '"truth"' in capsys.readouterr().out and (out / "lamp.svg").stat().st_size > 10_000
    assert main(["preview", str(files / "walk.usda"), "-o", str(out / "walk.gif"), "--size", "96x64",
                 "--keys", "0,12", "--view", "top"]) == 0
    frames, _ = gif_frames(out / "walk.gif")
    assert len(frames) == 24 and frames[0].shape == (64, 96, 3)
    assert main(["preview", str(files / "walk.usda"), "-o", str(out / "hand.png"), "--trail", "LeftLeg"]) == 0
    assert "still of the LeftLeg trail" in capsys.readouterr().err


@pytest.mark.parametrize(
    "args, message, code",
    [
        (["plot", "walk.usda", "--channels", "Qrotation"], "unknown channel 'Qrotation'; valid:", 2),
        (["plot", "walk.usda", "--joints", "Knee"], "unknown joint 'Knee'; joints are: Hips, Spine", 2),
        (["plot", "walk.usda", "--frames", "30:40"], "--frames 30:40 selects no frame of walk (frames 0-23)", 2),
        (["plot", "empty.bvh"], "empty.bvh: the motion has no frames", 1),
        (["plot", "walk.usda", "--labels", "a,b"], "--labels gives 2 names for 1 files", 2),
        (["preview", "walk.usda", "--trail", "Knee"], "unknown joint 'Knee'", 2),
        (["preview", "walk.usda", "--frames", "5:2"], "selects no frame", 2),
        (["preview", "empty.bvh"], "empty.bvh: the motion has no frames", 1),
        (["preview", "walk.usda", "--size", "8x8"], "each side must be 16 to 8192 pixels", 2),
        (["preview", "walk.usda", "--step", "0"], "--step must be between 1 and 10,000,000", 2),
    ],
)
def test_cli_bad_input(files, capsys, args, message, code):
    out = files / ("out.png" if args[0] == "plot" else "out.gif")
    argv = [args[0], str(files / args[1]), "-o", str(out)] + args[2:]
    assert main(argv) == code
    err = capsys.readouterr().err
    assert err.startswith("keyfill: error: ") and message in err and err.count("\n") == 1
    assert sorted(p.name for p in files.iterdir()) == ["empty.bvh", "lamp.usda", "walk.usda"]  # no output


@pytest.mark.parametrize("command, suffix", [("plot", ".gif"), ("plot", ".jpg"), ("preview", ".svg"),
                                             ("preview", "")])
def test_cli_unsupported_suffix(files, capsys, command, suffix):
    assert main([command, str(files / "walk.usda"), "-o", str(files / f"out{suffix}")]) == 2
    err = capsys.readouterr().err
    assert "unsupported picture type" in err and "expected ." in err
    assert not (files / f"out{suffix}").exists()


def test_bandai_walk_preview(tmp_path):
    path = shared_path("bvh_fixtures", "dataset-1_walk_normal_002.bvh")
    motion = io.load(path)
    f = scene.figure_points(motion)
    hips = motion.skeleton.index("Hips")
    assert not any(b[1] == hips for b in f.bones.tolist())  # root motion is not a bone
    assert len(f.bones) == 20 + len(motion.skeleton.end_sites)
    curves = C.channel_curves(motion)  # the default panels: the pelvis, not the static joint_Root
    assert {curves.joints[i] for i in C.select_panels(curves, motion)} == {"Hips"}
    info = S.preview([motion], ["walk"], tmp_path / "walk.gif")
    frames, delays = gif_frames(tmp_path / "walk.gif")
    assert len(frames) == 31 and abs(sum(delays) - 1033) <= 10 and info.size == (frames[0].shape[1], frames[0].shape[0])


def _figure_rows(cell: np.ndarray) -> int:
    """The height in pixels of what is drawn in the file's colours (not white, grey ground or text)."""
    rgb = cell.astype(int)
    coloured = (np.abs(rgb - rgb.mean(axis=-1, keepdims=True)).max(axis=-1) > 40)  # saturated: a figure
    rows = np.flatnonzero(coloured.any(axis=1))
    return 0 if not len(rows) else int(rows[-1] - rows[0] + 1)


def test_a_filmstrip_of_a_long_walk_follows_the_figures(tmp_path):
    """A 12 m walk framed whole drew figures about a fifth of the frame's height (the issue: 70 px of 300); the
    camera follows them now: every cell shows them at least a third of its height, at one scale."""
    long_walk = walker(frames=300, speed=4.0, keys=(0, 100, 200, 299))  # 4 cm a frame: 12 m
    info = S.preview([long_walk, walker(frames=300, speed=4.0, swing=0.3, keys=None)], ["a", "b"],
                     tmp_path / "s.png")
    W, H = info.frame_size
    im = pixels(tmp_path / "s.png")
    heights = [_figure_rows(im[4:4 + H, 4 + i * (W + 4): 4 + i * (W + 4) + W]) for i in range(len(info.frames))]
    assert min(heights) >= H / 3, heights
    assert max(heights) - min(heights) <= 0.12 * H  # the same scale in every cell (the walker bobs 2 cm)
    assert {0, 100, 200, 299} <= set(info.frames)  # the keys are among the frames shown
    # framed whole (the old picture) the figures were small: the check above can fail
    r = S.StickRenderer([long_walk], ["a"], "side", None, -S.STRIP_HEIGHT)
    assert r.centers is None
    assert (r.ax.get_ylim()[1] - r.ax.get_ylim()[0]) > 3 * 160  # the 160 cm figure under a third of the view


def test_a_short_motion_is_framed_whole(tmp_path):
    r = S.StickRenderer([walker()], ["w"], "side", None, -S.STRIP_HEIGHT, follow=True)
    assert r.centers is None  # 24 frames of a walk: the figures fill the frame already


def test_filmstrip_frames_are_the_keys_then_the_middles_of_the_widest_gaps():
    assert S.strip_frames(24, []) == [0, 3, 7, 10, 13, 16, 20, 23]
    assert S.strip_frames(273, [0, 68, 137, 205, 272]) == [0, 34, 68, 102, 137, 171, 205, 272]
    assert S.strip_frames(300, range(0, 300, 10)) == [0, 40, 80, 120, 170, 210, 250, 290]  # 8 of 30 keys
    assert S.strip_frames(3, [1]) == [0, 1, 2] and S.strip_frames(100, [50])[:2] == [0, 12]


def test_a_plot_of_four_joints_with_several_panels_each_has_four_columns(tmp_path):
    """_layout gives one column per joint for up to 4 joints; the fourth had no panel width (KeyError: 4, found
    by the option fuzzer: plot CMU --positions, whose default joints are 4)."""
    cmu = io.load(DATA / "cmu_02_03_cgspeed_first4frames.bvh")
    info = C.plot([cmu], ["cmu"], tmp_path / "p.png", positions=True,
                  joints=["Hips", "LHipJoint", "LeftUpLeg", "LowerBack"])
    assert len(info.panels) == 12 and (tmp_path / "p.png").is_file()
