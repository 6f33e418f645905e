"""keyfill's human models for the Bandai-Namco skeleton (CC BY-NC 4.0): one folder per model.

keyfill finds them through the ``keyfill.models`` entry points of this distribution (see its
pyproject.toml and ``keyfill.learn.installed_models``); each names one of the paths below.
"""

from pathlib import Path

_HERE = Path(__file__).resolve().parent
#: the transformer ``keyfill complete --method transformer`` uses without --model
BANDAI2_TRANSFORMER = _HERE / "bandai2-transformer"
#: the gan for whole keys (``--method gan`` without --model)
BANDAI2_GAN = _HERE / "bandai2-gan"
#: the gan for partial keys (``--key-joints``, ``--key-positions``, ``--key-plane``)
BANDAI2_GAN_PARTIAL = _HERE / "bandai2-gan-partial"
#: the motion library ``--method match`` uses without --library (and the guard's index for it)
BANDAI2_LIBRARY = _HERE / "bandai2-library"
