"""``keyfill train``: a group of model trainers, one subcommand per model kind."""

from __future__ import annotations

import click

from keyfill.cli.main import LazyGroup

#: subcommand -> "module:attribute"; a trainer appears once its module exists.
TRAINERS = {
    "transformer": "keyfill.cli.train_transformer:transformer",
    "arnn": "keyfill.cli.train_arnn:arnn",
}


@click.group(cls=LazyGroup, lazy=TRAINERS)
def train():
    """Train an in-betweening model on a corpus of motion files.

    \b
    Examples:
      keyfill train transformer bandai2/data --exclude '*_normal_*' -o models/bandai2-transformer
      keyfill train transformer clips/ -o models/small --config small.json --epochs 5
      keyfill train arnn data/hops -o models/lamp-arnn
    """
