"""``keyfill simulate``: build the physics-based hopping-lamp dataset."""

from __future__ import annotations

import click

from keyfill.cli.common import emit_json, progress, say
from keyfill.limits import CONNECT_SECONDS

DEFAULT_ITERATIONS = 200


@click.command()
@click.option("-o", "--output", "folder", required=True, type=click.Path(file_okay=False),
              help="Dataset folder (created if needed; an unfinished one is resumed).")
@click.option("--count", default=300, show_default=True, type=int, help="Accepted sequences to make.")
@click.option("--seed", default=0, show_default=True, type=int,
              help="Dataset seed; run r draws its randomness from (seed, r) only.")
@click.option("--iterations", default=DEFAULT_ITERATIONS, show_default=True, type=int,
              help="Simulated-annealing iterations per run (the paper used 1000).")
@click.option("--workers", type=int,
              help="Local worker processes [default: one per core]; with --scheduler, runs kept in flight "
                   "[default: the cluster's threads].")
@click.option("--format", "fmt", type=click.Choice(["usd", "bvh"]), default="usd", show_default=True,
              help="Motion file format of the sequences (.usda or .bvh).")
@click.option("--scheduler", metavar="ADDRESS", help="Run on a Dask distributed cluster, e.g. tcp://host:8786.")
@click.option("--connect-timeout", default=CONNECT_SECONDS, show_default=True, type=float, metavar="SECONDS",
              help="Give up reaching the --scheduler after this long.")
@click.option("--max-runs", type=int, help="Stop after this many annealing runs [default: 20 x count + 20].")
@click.option("--force", is_flag=True, help="Replace a folder made with another configuration.")
@click.option("--json", "as_json", is_flag=True, help="Print a summary as JSON on stdout.")
def simulate(folder, count, seed, iterations, workers, fmt, scheduler, connect_timeout, max_runs, force, as_json):
    """Simulate a hopping lamp and write keyframed 3-hop sequences to a folder.

    Each annealing run (Zhang & van de Panne 2018, Algorithm 1) tunes a
    4-state pose controller of a planar lamp in pybullet for one random
    weighting of hop distance against hop height; a run whose best episode
    has three clean hops and no fall becomes one sequence: 87 frames (25
    per hop, 6 per pause) with keys at each liftoff, one in-air pose and
    each landing. The folder gets one motion file per sequence,
    manifest.jsonl (keys, controller, distance, height, ...) and
    runs.jsonl (every run, for resuming).

    The same seed gives byte-identical files with any --workers or
    --scheduler. Running the same command again resumes an interrupted
    build; a folder made with another seed, format, iteration count or
    simulation version is refused unless --force is given.

    \b
    Examples:
      keyfill simulate -o data/hops --count 300 --seed 0
      keyfill simulate -o data/hops_bvh --count 20 --format bvh --workers 2
      keyfill simulate -o data/hops --scheduler tcp://10.0.0.5:8786 --json
    """
    from keyfill.sim.runner import check_arguments
    from keyfill.sim.runner import simulate as build

    check_arguments(count, seed, iterations, workers, fmt, max_runs, connect_timeout)

    with progress(total=count, unit="seq", desc="sequences") as bar:

        def on_run(outcome, sequences, runs):
            bar.n = min(sequences, count)
            bar.set_postfix_str(f"{sequences} accepted / {runs} tried", refresh=False)
            bar.refresh()

        summary = build(folder, count, seed=seed, iterations=iterations, workers=workers, fmt=fmt,
                        scheduler=scheduler, force=force, max_runs=max_runs, connect_timeout=connect_timeout,
                        on_run=on_run)
    info = summary.to_dict()
    if as_json:  # docs/json.md: the dataset folder is the output
        emit_json({**{k: v for k, v in info.items() if k != "folder"}, "input": None, "output": str(info["folder"])})
    elif info.get("already_done"):
        say(f"{folder} already holds {info['sequences']} sequences; nothing to do")
    else:
        say(f"wrote {info['sequences']} sequences to {folder} ({info['runs']} runs, "
            f"{100 * info['acceptance_rate']:.0f}% accepted; {info['new_runs']} runs now in {info['seconds']:.1f} s, "
            f"{info['episodes_per_second']:.0f} episodes/s)")
