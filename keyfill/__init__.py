"""keyfill: keyframe in-betweening for character animation.

The library behind the ``keyfill`` command. One data type flows through it:
``keyfill.io.load(path) -> Motion``; methods in ``keyfill.sim``,
``keyfill.learn`` and ``keyfill.edit`` take and return ``Motion``;
``keyfill.io.save(motion, path)`` writes it.

``Keys``, ``Motion`` and ``Skeleton`` are imported on first use, so that
importing the package (as the ``keyfill`` command does first) loads no numpy.
"""

from typing import TYPE_CHECKING

if TYPE_CHECKING:  # type checkers see the real classes; at run time __getattr__ imports them
    from keyfill.motion import Keys, Motion, Skeleton

__version__ = "0.1.0"

__all__ = ["Keys", "Motion", "Skeleton", "__version__"]


def __getattr__(name: str):
    if name in ("Keys", "Motion", "Skeleton"):
        from keyfill import motion

        return getattr(motion, name)
    raise AttributeError(f"module 'keyfill' has no attribute {name!r}")
