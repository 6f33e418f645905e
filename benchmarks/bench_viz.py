"""Speed of ``keyfill preview`` (a 300-frame GIF) and ``keyfill plot`` (10,000 frames).

Goals (issue 7): a 300-frame, 22-joint GIF in under 10 s; a plot of 10,000
frames in under 3 s, on this machine, process start included. The work is
single-threaded, so on an idle machine the wall time is about the CPU time;
on the shared 2-core machine under load the wall time can be twice that, so
both are printed and judged.

Inputs (Bandai-Namco dataset-1, read from ``data/bandai1/`` or unpacked there
from ``../shared/data/corpora/``, see ``bench_bvh_io.py``; skipped without it):

* GIF: the first 300 frames of ``dataset-1_walk_not-confident_001.bvh``
  (22 joints, 30 fps), written once to ``data/bench/walk300.bvh``;
* plot: the first 10,000 frames of the clips concatenated
  (``data/bench/bandai1_concat_10000f.bvh``, shared with ``bench_complete.py``).

Measured, each the median of ``--repeat`` runs:

* ``keyfill preview walk300.bvh -o OUT.gif`` (side and 3d view) and
  ``keyfill plot concat.bvh -o OUT.png`` (default panels: the root's six
  channels; also three files overlaid, and as SVG and PDF) as subprocesses,
  process start and file reading included;
* the same preview in-process, split into setup, drawing + palette mapping
  and GIF encoding, against a peer in the same run: matplotlib's own animation route
  (``FuncAnimation`` updating the same stick-figure line data every frame,
  saved with ``PillowWriter``) for the same frames, size and camera.

The run is recorded in ``benchmarks/results/viz.json`` (``results.py``; not with
``--no-record``): ``repeat`` and ``results``, per row ``seconds``, ``cpu_seconds`` and,
where they apply, ``bytes``, ``goal_s``, ``ms_per_frame`` and ``keyfill_speedup_cpu``.
The goals are judged by wall time.

    .venv/bin/python benchmarks/bench_viz.py
    .venv/bin/python benchmarks/bench_viz.py --repeat 7 --json
"""

from __future__ import annotations

import argparse
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import results
from bench_bvh_io import BENCH_DIR, Skipped, bandai1_clips, concatenated_bvh, median_times

GIF_GOAL_S = 10.0
PLOT_GOAL_S = 3.0
GIF_FRAMES = 300
PLOT_FRAMES = 10_000
WALK_CLIP = "dataset-1_walk_not-confident_001.bvh"


def keyfill_command() -> list[str]:
    script = Path(sys.executable).with_name("keyfill")
    return [str(script)] if script.exists() else [sys.executable, "-m", "keyfill"]


def walk300() -> Path:
    """The first 300 frames of one Bandai walk, written once under data/bench/."""
    from keyfill import io

    path = BENCH_DIR / "walk300.bvh"
    if not path.is_file():
        clip = next((c for c in bandai1_clips() if c.name == WALK_CLIP), None)
        if clip is None:
            raise Skipped(f"{WALK_CLIP} is not in the corpus")
        motion = io.load(clip)
        if motion.num_frames < GIF_FRAMES:
            raise Skipped(f"{WALK_CLIP} has {motion.num_frames} frames, fewer than {GIF_FRAMES}")
        BENCH_DIR.mkdir(parents=True, exist_ok=True)
        io.save(motion.frames(slice(0, GIF_FRAMES)), path)
    return path


def cli_time(args: list[str], repeat: int) -> dict:
    """Median wall and CPU seconds (user + system of the child) of ``keyfill -q ARGS``."""
    walls, cpus = [], []
    for _ in range(repeat):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        start = time.perf_counter()
        subprocess.run(keyfill_command() + ["-q"] + args, check=True, capture_output=True)
        walls.append(time.perf_counter() - start)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpus.append(after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
    return {"seconds": statistics.median(walls), "cpu_seconds": statistics.median(cpus)}


def matplotlib_animation_peer(motion, size, out: Path) -> tuple[float, float]:
    """Wall and CPU seconds for matplotlib's FuncAnimation + PillowWriter to write the same stick-figure GIF."""
    from matplotlib.animation import FuncAnimation, PillowWriter
    from matplotlib.collections import LineCollection

    from keyfill.viz import stick, style

    r = stick.StickRenderer([motion], ["walk"], "side", size, stick.GIF_SIDE)  # same camera and limits
    fig = style.new_figure(size[0] / 100, size[1] / 100, dpi=100)
    ax = fig.add_axes((0, 0, 1, 1))
    ax.set_axis_off()
    ax.set_xlim(r.ax.get_xlim())
    ax.set_ylim(r.ax.get_ylim())
    lines = ax.add_collection(LineCollection([], colors=r.colors[0], linewidths=3.0, capstyle="round"))
    text = ax.text(0.015, 0.975, "", transform=ax.transAxes, va="top")

    def update(t):
        lines.set_segments(r._screen(0, t))
        text.set_text(f"frame {t}")
        return lines, text

    start, cpu = time.perf_counter(), time.process_time()
    FuncAnimation(fig, update, frames=motion.num_frames, blit=False).save(out, writer=PillowWriter(fps=motion.fps))
    return time.perf_counter() - start, time.process_time() - cpu


def gif_split(motion, out: Path, repeat: int) -> dict:
    """Median seconds of the three stages of a GIF preview, done by hand with the library's parts."""
    from keyfill.viz import gif, stick
    from keyfill.viz.palette import Palette

    def setup():
        return stick.StickRenderer([motion], ["walk"], "side", None, stick.GIF_SIDE)

    def frames(r):
        palette = Palette([r.render(t, r.bracketing_keys(t), r.frame_label(t)) for t in (0, 150, 299)],
                              required=r.palette_colors())
        return [palette.apply(r.render(t, r.bracketing_keys(t), r.frame_label(t))) for t in range(motion.num_frames)]

    wall_setup, cpu_setup, r = median_times(setup, repeat)
    wall_frames, cpu_frames, images = median_times(lambda: frames(r), repeat)
    wall_write, cpu_write, _ = median_times(
        lambda: gif.write_gif(images, out, gif.delays_ms(len(images), motion.fps)), repeat)
    per = 1000 / motion.num_frames
    return {
        "  setup: FK, camera, figure, static layer": {"seconds": wall_setup, "cpu_seconds": cpu_setup},
        "  300 frames: draw + exact palette mapping": {"seconds": wall_frames, "cpu_seconds": cpu_frames,
                                                        "ms_per_frame": wall_frames * per},
        "  GIF encoding (Pillow, changed rectangles)": {"seconds": wall_write, "cpu_seconds": cpu_write,
                                                         "ms_per_frame": wall_write * per},
    }


def run(repeat: int) -> dict:
    from keyfill import io
    from keyfill.viz import stick

    walk = walk300()
    concat = concatenated_bvh(frames=PLOT_FRAMES)
    rows: dict[str, dict] = {}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for view in ("side", "3d"):
            out = tmp / f"walk_{view}.gif"
            row = cli_time(["preview", str(walk), "-o", str(out), "--view", view, "--key-every", "30"], repeat)
            rows[f"preview GIF {view} (CLI)"] = {**row, "goal_s": GIF_GOAL_S, "bytes": out.stat().st_size}
        out = tmp / "plot.png"
        row = cli_time(["plot", str(concat), "-o", str(out), "--key-every", "100"], repeat)
        rows["plot PNG, 6 panels (CLI)"] = {**row, "goal_s": PLOT_GOAL_S, "bytes": out.stat().st_size}
        for ext in ("svg", "pdf"):
            out = tmp / f"plot.{ext}"
            row = cli_time(["plot", str(concat), "-o", str(out)], repeat)
            rows[f"plot {ext.upper()}, 6 panels (CLI)"] = {**row, "goal_s": PLOT_GOAL_S, "bytes": out.stat().st_size}
        out = tmp / "plot3.png"
        row = cli_time(["plot", str(concat), str(concat), str(concat), "--joints", "Hips", "-o", str(out)], repeat)
        rows["plot PNG, 3 files x 6 panels (CLI)"] = {**row, "goal_s": PLOT_GOAL_S, "bytes": out.stat().st_size}
        rows["start-up + read (keyfill info, CLI)"] = cli_time(["info", str(walk)], repeat)

        motion = io.load(walk)
        wall, cpu, info = median_times(lambda: stick.preview([motion], ["walk"], tmp / "lib.gif"), repeat)
        rows["preview GIF side (library)"] = {"seconds": wall, "cpu_seconds": cpu,
                                              "bytes": (tmp / "lib.gif").stat().st_size}
        peer = [matplotlib_animation_peer(motion, info.size, tmp / "peer.gif") for _ in range(max(1, repeat // 2))]
        walls, cpus = zip(*peer)
        rows["matplotlib FuncAnimation + PillowWriter (peer)"] = {
            "seconds": statistics.median(walls), "cpu_seconds": statistics.median(cpus),
            "bytes": (tmp / "peer.gif").stat().st_size,
            "keyfill_speedup_cpu": statistics.median(cpus) / cpu,
        }
        rows.update(gif_split(motion, tmp / "split.gif", repeat))
    return rows


def goals(rows: dict) -> list[dict]:
    """Issue 7's goals, by wall time: the side-view GIF and the PNG plot through the CLI."""
    gif, plot = rows["preview GIF side (CLI)"]["seconds"], rows["plot PNG, 6 panels (CLI)"]["seconds"]
    return [results.goal(7, f"{GIF_FRAMES}-frame, 22-joint GIF under {GIF_GOAL_S:g} s", f"{gif:.2f} s",
                         gif < GIF_GOAL_S),
            results.goal(7, f"`plot` of {PLOT_FRAMES:,} frames under {PLOT_GOAL_S:g} s", f"{plot:.2f} s",
                         plot < PLOT_GOAL_S)]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=5, help="runs per measurement (median reported)")
    parser.add_argument("--json", action="store_true", help="print the record as JSON")
    results.add_option(parser)
    args = parser.parse_args()
    bench = results.Run()
    try:
        rows = run(args.repeat)
    except Skipped as e:
        print(f"skipped: {e}")
        return 0
    record = bench.record("viz", {"repeat": args.repeat, "results": rows}, goals(rows), write=not args.no_record)
    if args.json:
        print(results.dumps(record), end="")
        return 0
    print(f"{results.summary(record)}; medians of {args.repeat} runs")
    print(f"  {'':48} {'wall s':>7} {'cpu s':>7}")
    for name, row in rows.items():
        goal = ""
        if "goal_s" in row:
            verdict = {True: "met", False: "MISSED"}
            goal = (f"  goal < {row['goal_s']:.0f} s: wall {verdict[row['seconds'] < row['goal_s']]},"
                    f" CPU {verdict[row['cpu_seconds'] < row['goal_s']]}")
        extra = f"  {row['bytes'] / 1000:.0f} kB" if "bytes" in row else ""
        speed = f"  keyfill uses {row['keyfill_speedup_cpu']:.1f}x less CPU" if "keyfill_speedup_cpu" in row else ""
        per = f"  {row['ms_per_frame']:.1f} ms/frame" if "ms_per_frame" in row else ""
        print(f"  {name:<48} {row['seconds']:7.2f} {row['cpu_seconds']:7.2f}{per}{extra}{goal}{speed}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
