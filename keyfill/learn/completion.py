"""What every in-betweening method takes and gives: :class:`CompleteOptions` and :class:`Completion`.

A method is a function ``complete(motion, keys, options) -> Completion``
(see :mod:`keyfill.learn.registry`). It reads only the key frames of
``motion`` (and, for learned methods, a model folder) and returns a motion
with every frame filled and ``keys`` attached.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from keyfill.errors import UsageError
from keyfill.limits import check_seed
from keyfill.motion import Motion


@dataclass(frozen=True)
class CompleteOptions:
    """Options of a completion.

    Attributes:
        model: path of a model folder (learned methods), or None for the model shipped with keyfill.
        exact_keys: make frames at keys equal the input keys exactly.
        seed: seed for any randomness (e.g. dropout sampling, GAN noise).
        device: torch device for learned methods (``"cpu"``, ``"cuda"``).
        runtime: ``"torch"``, ``"onnx"`` (an exported graph through onnxruntime, no torch) or ``"auto"``
            (onnx when onnxruntime is installed and the model folder holds an exported graph);
            see :mod:`keyfill.learn.onnx`.
        dna: Motion DNA source ``"FILE[:FRAMES]"`` (methods with the ``dna`` capability).
        dna_count: how many representative poses the Motion DNA takes (None: one per 3 s of gap).
        rig_map: a TOML file of humanoid role -> joint name(s) for methods that serve any humanoid rig
            (:mod:`keyfill.learn.rig_bridge`); None maps the roles from the skeleton's names and hierarchy.
        feet: ``"lock"`` holds the feet still where they touch the ground
            (:func:`keyfill.characters.feet.lock_feet`), ``"free"`` leaves the method's output as it is;
            None: the method's own default (``"lock"`` for ``match``, whose real steps locking keeps planted;
            ``"free"`` for the others: docs/feet.md and docs/match.md say why).
        ground: the ground's height along the up axis (skeleton units) for ``feet``; None: from the keys.
        library: a motion library folder (``keyfill library build``) for the methods that take one
            (``match``); None: the shipped library.
        guard: what human methods do with gaps unlike anything their model or library knows
            (:mod:`keyfill.learn.library.guard`): ``"fallback"`` fills them with the cubic spline and reports
            them, ``"warn"`` reports them only, ``"off"`` does not score them; None: ``"fallback"``.
    """

    model: str | None = None
    exact_keys: bool = True
    seed: int = 0
    device: str = "cpu"
    runtime: str = "auto"
    dna: str | None = None
    dna_count: int | None = None
    rig_map: str | None = None
    feet: str | None = None
    ground: float | None = None
    library: str | None = None
    guard: str | None = None

    def __post_init__(self):
        check_seed(self.seed)
        if self.feet not in (None, "lock", "free"):
            raise UsageError(f"feet is lock or free, not {self.feet!r}", params="feet")
        if self.guard not in (None, "fallback", "warn", "off"):
            raise UsageError(f"guard is fallback, warn or off, not {self.guard!r}", params="guard")
        if self.ground is not None and not (isinstance(self.ground, (int, float)) and math.isfinite(self.ground)):
            raise UsageError(f"ground must be a finite number, not {self.ground!r}", params="ground")


@dataclass
class Completion:
    """The result of a completion: the filled motion and a JSON-ready report."""

    motion: Motion
    info: dict = field(default_factory=dict)
