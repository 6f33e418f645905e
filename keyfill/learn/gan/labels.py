"""Per-clip labels the second recipe's training draws on: foot contacts and content groups.

* :func:`clip_contacts`: each clip's foot contact labels ``(T_c, n)`` bool, from
  :func:`keyfill.characters.feet.contacts` (the labels ``keyfill complete --feet``
  and the benchmarks use), columns in the order of
  :func:`keyfill.characters.feet.contact_joints`; the foot-sliding term of
  ``GanConfig.foot_weight`` holds these joints still where the real clip does.
* :func:`content_groups`: an integer per clip naming what it shows, so that
  in-clip windows and the discriminator's real crops can be drawn equally from
  every content (a corpus of many walks and few raise-ups otherwise teaches
  the discriminator that everything walks).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

#: ``dataset-2_walk-turn-left_feminine_001``: the Bandai-Namco naming, content second
_BANDAI = re.compile(r"^dataset-\d+_(?P<content>[^_]+)_[^_]+_\d+$")


def content_of(file: str) -> str:
    """What a clip shows, from its file name: Bandai-Namco's content field, else the name without a trailing
    number (``run_03.bvh`` -> ``run``)."""
    stem = Path(file).stem
    m = _BANDAI.match(stem)
    return m["content"] if m else re.sub(r"[_\-. ]*\d+$", "", stem) or stem


def content_groups(corpus, clips) -> np.ndarray:
    """``(C,)`` int: a group per clip of ``clips`` (indices into ``corpus``), equal for clips of one content."""
    names = [content_of(corpus.files[int(i)]) for i in clips]
    order = {n: g for g, n in enumerate(sorted(set(names)))}
    return np.array([order[n] for n in names], dtype=np.int64)


def clip_contacts(corpus, clips) -> tuple[tuple[np.ndarray, ...], np.ndarray]:
    """``(labels, joints)``: per clip of ``clips`` the ``(T_c, n)`` bool contact labels, and the ``(n,)`` joint
    indices of their columns. A skeleton without recognisable legs gives ``n = 0`` columns."""
    from keyfill.characters.feet import contact_joints, contacts
    from keyfill.characters.retarget import make_rig
    from keyfill.errors import KeyfillError
    from keyfill.learn.windows import window_motion

    try:
        rig = make_rig(corpus.skeleton)
        joints = np.array([j for _, j in contact_joints(rig)], dtype=np.int64)
    except KeyfillError:
        return tuple(np.zeros((int(corpus.starts[i + 1] - corpus.starts[i]), 0), bool) for i in clips), \
            np.zeros(0, dtype=np.int64)
    out = []
    for i in clips:
        q, root = corpus.clip(int(i))
        out.append(contacts(window_motion(corpus.skeleton, q, root, float(corpus.fps)), rig))
    return tuple(out), joints
