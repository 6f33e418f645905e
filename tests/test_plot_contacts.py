"""`keyfill plot --contacts`: foot contact bands under the curves.

The human example's keys (examples/human/keys_15.usda, a Bandai walk keyed every 15 frames) completed with
cubic: a walk whose feet are planted at the start and again around each step, so every foot joint has
contact intervals and free frames. The drawn bars are checked against :func:`keyfill.characters.feet.contacts`.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from keyfill import interpolate, io
from keyfill.characters import feet
from keyfill.characters.retarget import make_rig
from keyfill.cli.main import main
from keyfill.errors import DataError
from keyfill.viz import curves as C

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


@pytest.fixture(scope="module")
def walk():
    keys = io.load(EXAMPLES / "human" / "keys_15.usda")
    return interpolate.cubic(keys, keys.keys)


def pixels(path) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(path).convert("RGB"), dtype=np.int16)


def runs(column: np.ndarray, first: int = 0) -> list[tuple[int, int]]:
    """``[(first frame, last frame), ...]`` of the runs of True, numbered from ``first``."""
    edges = np.diff(np.pad(column.astype(np.int8), 1))
    return [(int(a) + first, int(b) - 1 + first) for a, b in zip(np.flatnonzero(edges == 1),
                                                                   np.flatnonzero(edges == -1))]


def drawn(ax) -> dict[str, list[tuple[int, int]]]:
    """Per row name (the y tick label), the bars' frame spans ``(first, last)`` from their drawn rectangles
    (each frame a cell from ``t - 0.5`` to ``t + 0.5``)."""
    names = {round(t): label.get_text() for t, label in zip(ax.get_yticks(), ax.get_yticklabels())}
    out = {name: [] for name in names.values()}
    for p in ax.patches:
        x0, y0 = p.get_x(), p.get_y() + p.get_height() / 2
        name = names[round(y0)]
        assert p.get_gid() == name
        out[name].append((round(x0 + 0.5), round(x0 + p.get_width() - 0.5)))
    return {name: sorted(spans) for name, spans in out.items()}


def test_bands_are_the_contacts_of_each_file(walk):
    rig = make_rig(walk.skeleton)
    cols = feet.contact_joints(rig)
    names = [walk.skeleton.names[j] for _, j in cols]
    labels = feet.contacts(walk, rig, keys=walk.keys)
    expected = {name: runs(labels[:, k]) for k, name in enumerate(names)}
    # a walk: every foot joint is down at the start, lifts, and comes down again
    assert names == ["Foot_L", "Toes_L", "Foot_R", "Toes_R"]
    assert all(len(v) >= 2 and v[0][0] == 0 for v in expected.values()), expected
    assert 0.2 < labels.mean() < 0.8
    lifted = walk.replace(positions=walk.positions.copy())
    lifted.positions[:, walk.skeleton.index("Hips"), 1] += 30.0  # 30 cm up: no foot touches the ground
    fig, info = C.figure([walk, lifted], ["cubic", "lifted"], contacts=True, ground=0.0)
    bands = {ax.get_label(): ax for ax in fig.axes if ax.get_label().startswith("contacts: ")}
    assert list(bands) == ["contacts: cubic", "contacts: lifted"]
    a, b = bands["contacts: cubic"], bands["contacts: lifted"]
    # one row per foot joint, top to bottom in contact_joints' order; the bars are the contact intervals
    assert [t.get_text() for t in a.get_yticklabels()][::-1] == names
    grounded = feet.contacts(walk, rig, ground=0.0, keys=walk.keys)
    assert drawn(a) == {name: runs(grounded[:, k]) for k, name in enumerate(names)}
    assert drawn(b) == {name: [] for name in names}
    assert info.contacts[0] == {name: [list(s) for s in runs(grounded[:, k])] for k, name in enumerate(names)}
    # the bands sit under the curves, the first file's above the second's, on the curves' frames
    curves = [ax for ax in fig.axes if ax not in (a, b) and ax.get_visible() and ax.axison]
    lowest = min(ax.get_position().y0 for ax in curves)
    assert a.get_position().y1 < lowest and b.get_position().y1 < a.get_position().y0
    assert a.get_xlim() == curves[0].get_xlim()
    assert a.get_title(loc="left") == "cubic: foot contacts"


def test_bands_of_a_frame_range_keep_the_file_numbering_and_the_ground(walk):
    rig = make_rig(walk.skeleton)
    names = [walk.skeleton.names[j] for _, j in feet.contact_joints(rig)]
    labels = feet.contacts(walk, rig, keys=walk.keys)  # the ground from all the keys, not only those shown
    fig, _ = C.figure([walk], ["cubic"], contacts=True, frames="20:70")
    (ax,) = [ax for ax in fig.axes if ax.get_label() == "contacts: cubic"]
    assert drawn(ax) == {name: runs(labels[20:70, k], first=20) for k, name in enumerate(names)}
    assert any(s[0] == 20 for spans in drawn(ax).values() for s in spans)  # a contact cut at the range's start


def test_bands_lie_under_each_column_of_panels(walk):
    fig, _ = C.figure([walk], ["cubic"], contacts=True, positions=True, joints=["Toes_L", "Toes_R"],
                      channels=["y", "z"])
    by_label = {ax.get_label(): ax for ax in fig.axes}
    first, second = by_label["contacts: cubic"], by_label["contacts: cubic, column 2"]
    assert len(first.patches) > 0 and len(second.patches) == len(first.patches)
    curves = [ax for ax in fig.axes if not ax.get_label().startswith("contacts")]
    for band in (first, second):  # the column above it: same x extent, same frames
        above = [ax for ax in curves if abs(ax.get_position().x0 - band.get_position().x0) < 1e-9]
        assert len(above) == 2 and above[0].get_position().width == pytest.approx(band.get_position().width)
        assert band.get_xlim() == above[0].get_xlim()
    assert first.get_position().x0 < second.get_position().x0


def test_bands_need_legs(walk):
    from test_viz import lamp_hop, walker

    with pytest.raises(DataError, match=r"contacts needs a skeleton with legs: lamp: found no joint for the "
                                        r"humanoid roles hips, .*foot_l"):
        C.figure([lamp_hop()], ["lamp"], contacts=True)
    with pytest.raises(DataError, match="contacts needs a skeleton with legs: walker: .*foot_l"):
        C.figure([walk, walker()], ["cubic", "walker"], contacts=True, joints=["Hips"])


def test_cli_plot_contacts(walk, tmp_path, capsys):
    io.save(walk, tmp_path / "walk.usda")
    out = tmp_path / "walk.png"
    assert main(["plot", str(tmp_path / "walk.usda"), "--contacts", "--positions", "--joints", "Toes_L",
                 "--channels", "y", "-o", str(out), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    rig = make_rig(walk.skeleton)
    labels = feet.contacts(walk, rig, keys=walk.keys)
    toe = next(k for k, (role, _) in enumerate(feet.contact_joints(rig)) if role == "toe_l")
    assert summary["contacts"][0]["label"] == "walk"
    assert summary["contacts"][0]["joints"]["Toes_L"] == [list(s) for s in runs(labels[:, toe])]
    # the picture: the curve's panel, and under it the band, taller than without it and shaded in blue
    assert main(["plot", str(tmp_path / "walk.usda"), "--positions", "--joints", "Toes_L", "--channels", "y",
                 "-o", str(tmp_path / "plain.png")]) == 0
    with_bands, plain = pixels(out), pixels(tmp_path / "plain.png")
    extra = with_bands.shape[0] - plain.shape[0]
    assert extra > 100 and with_bands.shape[1] == plain.shape[1]
    blue = np.all(np.abs(with_bands[-extra:] - [64, 140, 195]) < 24, axis=-1).sum()  # the file colour at alpha 0.85
    assert blue > 2000
    # --ground and --rig-map only with --contacts
    assert main(["plot", str(tmp_path / "walk.usda"), "--ground", "0", "-o", str(tmp_path / "g.png")]) == 2
    assert "--ground needs --contacts" in capsys.readouterr().err


def test_cli_plot_contacts_of_the_lamp_is_one_error_line(tmp_path, capsys):
    lamp = EXAMPLES / "lamp" / "keys.usda"
    assert main(["plot", str(lamp), "--contacts", "-o", str(tmp_path / "lamp.png")]) == 1
    err = capsys.readouterr().err
    assert err.startswith("keyfill: error: --contacts needs a skeleton with legs: keys: found no joint for the "
                          "humanoid roles hips, ") and err.count("\n") == 1
    assert "foot_l" in err and "--rig-map" in err
    assert not any(tmp_path.iterdir())
