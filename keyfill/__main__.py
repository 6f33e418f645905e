"""``python -m keyfill``: the same as the ``keyfill`` command."""

from keyfill.cli.main import entry_point

entry_point()
