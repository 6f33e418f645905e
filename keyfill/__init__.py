"""keyfill: keyframe in-betweening for character animation.

The library behind the ``keyfill`` command. One data type flows through it:
``keyfill.io.load(path) -> Motion``; methods in ``keyfill.sim``,
``keyfill.learn`` and ``keyfill.edit`` take and return ``Motion``;
``keyfill.io.save(motion, path)`` writes it.
"""

__version__ = "0.1.0"

from keyfill.motion import Keys, Motion, Skeleton  # noqa: E402

__all__ = ["Keys", "Motion", "Skeleton", "__version__"]
