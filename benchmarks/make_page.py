"""Build docs/benchmarks.md from the records in benchmarks/results/*.json (``--check``: exit 1 if it differs).

The page is the current figures against their goals: a goals table, then one section per record (what is
measured, the command that reproduces it, the machine, date and load it was measured on, the figures and the
goals with met or missed). Nothing on it is typed by hand: to change a figure, rerun the script that makes it
(it rewrites its record) and then this one. The history of the figures is CHANGELOG.md.

    python3 benchmarks/make_page.py            # write docs/benchmarks.md
    python3 benchmarks/make_page.py --check    # exit 1 if docs/benchmarks.md is not what the records give
"""

from __future__ import annotations

import argparse
import difflib
import os
import re
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

import page_sections as S
from results import RESULTS, ROOT, read_records

PAGE = ROOT / "docs" / "benchmarks.md"


@dataclass(frozen=True)
class Section:
    """How a kind of record is shown: its title (``{variant}``: the record name's part after the first ``-``),
    what it measures, and the function that renders its figures."""

    title: str
    about: str
    render: object


SECTIONS = {
    "bvh_io": Section(
        "BVH read and write", "keyfill's BVH reader and writer on a 20 MB concatenation of Bandai-Namco dataset-1 "
        "clips, against bvhio, the `bvh` package and a bare `np.loadtxt` of the numbers, in one process.",
        S.bvh_io),
    "complete": Section(
        "`keyfill complete --method cubic` end to end", "The command as a subprocess on 10,000 frames of 22 joints, "
        "process start included, and the same work split into start-up, read, compute and write.", S.complete),
    "blender_interop": Section(
        "Blender reads keyfill's files", "Blender (the `bpy` wheel) imports keyfill's BVH, USDA and USDC output of "
        "every shared fixture; its bone heads are compared with keyfill's forward kinematics.", S.blender_interop),
    "simulate-dataset": Section(
        "`keyfill simulate`: the hopping-lamp dataset", "A full build of 300 simulated 3-hop lamp sequences "
        "(pybullet, PD control, simulated annealing; Zhang & van de Panne 2018), two worker processes.",
        S.simulate_dataset),
    "simulate": Section(
        "`keyfill simulate`: where the speed comes from", "The simulator's choices, each timed against its "
        "alternative, and the accuracy the time step costs.", S.simulate),
    "arnn-tables": Section(
        "ARNN: Tables 1 and 2 of Zhang & van de Panne 2018", "keyfill's rows of the paper's tables on the test split "
        "of the simulated lamp data (sequences 240-299), with all keys and with 1-2 keys deleted, beside the "
        "splines.", S.arnn_tables),
    "arnn-inference": Section(
        "ARNN: inference", "Completing the 3-hop example `examples/lamp/keys.usda` with the model loaded once.",
        S.arnn_inference),
    "tangent_qp": Section(
        "Tangent-space editing: Table 3 of Ciccone et al. 2019", "Milliseconds per move edit (reduction, sampling, "
        "Jacobians, QPs, iterations) for 24-168 optimised DOF, 2, 7 and 20 frames between keys and the paper's six "
        "constraint configurations, on the Bandai walk and the lamp; each edit is checked (target, keys, pins, "
        "contacts).", S.tangent_qp),
    "transformer_quality": Section(
        "Transformer quality: `{variant}`", "The LaFAN1 in-betweening protocol on Bandai-Namco dataset-2 with the "
        "`normal` style held out, beside zero-velocity, interpolation, cubic and the velocity pre-fill; the ratios "
        "to interpolation against SSMCT (Duan et al. 2021, issue 6) and Qin et al. 2022 (issue 14).",
        S.transformer_quality),
    "transformer": Section(
        "Transformer inference: `{variant}`", "The LaFAN1 layout with a 30-frame transition: the network alone and "
        "`complete_windows` (numpy windows in and out), 1 and 10 windows, in one process.", S.transformer),
    "viz": Section(
        "Pictures: `keyfill preview` and `keyfill plot`", "A 300-frame GIF of a Bandai walk and plots of 10,000 "
        "frames, process start included, and the same GIF in one process against matplotlib's `FuncAnimation`.",
        S.viz),
    "gan_speed": Section(
        "Generative tweening speed: `{variant}`", "`complete_motion` and both exact-key steps with the model loaded, "
        "512 to 4,096 frames, on 1 and 2 threads.", S.gan_speed),
    "gan_quality": Section(
        "Generative tweening quality: `{variant}`", "On held-out Bandai-Namco clips (styles the model never saw): "
        "the path predictor (the paper's Table 2), key errors before post-processing (Table 4), and the realism of "
        "what `keyfill complete` writes.", S.gan_quality),
    "gan_dna": Section(
        "Motion DNA and partial keys: `{variant}`", "Eqs. 11-12's DNA errors, key errors for whole, root-only, "
        "half-body and 2-D keys, and the variety of 4 DNAs against 4 noise seeds, on the held-out clips.",
        S.gan_dna),
    "batch": Section(
        "Batch completion and the ONNX runtime", "One `keyfill complete IN/ -o OUT/` over many lamp files against "
        "single calls; start-up, latency and parity of onnxruntime against torch.", S.batch),
    "batch_rerun": Section(
        "A batch re-run with nothing changed", "`keyfill complete IN/ -o OUT/ --method cubic` over 1,000 tiny generated "
        "BVH files, then again unchanged: every output skipped by the output folder's record (docs/batch.md).",
        None),
    "retarget": Section(
        "The human models on other rigs and frame rates", "Held-out Bandai-Namco dataset-2 clips retargeted onto the "
        "Mixamo and CMU fixture rigs, completed on each rig by cubic and by the shipped transformer and gan through "
        "retargeting (docs/retarget.md).", S.retarget),
    "match": Section(
        "In-betweens matched from real motion", "`--method match` against cubic and the shipped models on held-out "
        "clips, its variety over seeds, the guard, and the library's speed (docs/match.md).", S.match),
    "transformer_start": Section(
        "The transformer started from a matched in-between: `{variant}`", "A transformer's weights handed "
        "`--method match`'s raw in-between in place of their pre-fill, against match and the same model from its "
        "pre-fill on held-out clips, keys every 30 and 60 (issue 46; the shipped model never trained on such "
        "starts).",
        S.transformer_start),
    "gan_match": Section(
        "The gan on a matched base: `{variant}`", "A generator correcting `--method match`'s in-between (issue 45), "
        "per seed and as a distribution against cubic, match alone and the shipped gan and transformer on held-out "
        "clips, keys every 60 and 120; Motion DNA's pull and speed (docs/gan.md, \"On a matched base\").",
        S.gan_match),
    "feet": Section(
        "Feet on the ground: raw and locked", "Every method with its feet free and locked (`keyfill complete --feet "
        "lock`), on held-out clips of styles no shipped model saw (docs/feet.md).", S.feet),
    "formats": Section(
        "Motion file formats: glTF, USD and BVH", "`keyfill.io.save` and `load` of a 10,000-frame 22-joint motion "
        "(the Bandai walk fixture tiled) in each format, in one process (docs/formats.md).", S.formats),
    "scale": Section(
        "Long takes: every command from 1k to 1M frames", "CPU time and peak memory of `complete` (each method), "
        "`convert` between every pair of formats and `info` on Bandai-Namco dataset-1 clips joined into takes of "
        "1,000 to 1,000,000 frames, each a new process (issue 44; docs/formats.md, \"Long takes\").", S.scale),
    "convert_memory": Section(
        "`keyfill convert` of a big file: memory", "Peak resident memory (`wait4`) of converting a generated 150 MB "
        "BVH to USD and to BVH, beside the fixed overhead of converting a 4-frame file.", S.convert_memory),
}
CHECKS = Section("Checks that are no benchmark script", "Goals measured by tests, training runs and `make` "
                 "targets; each row has its own command and machine.", S.checks)
ORDER = list(SECTIONS) + ["checks"]

INTRO = """\
# keyfill benchmarks

<!-- Made by benchmarks/make_page.py from benchmarks/results/*.json (rerun a script or edit a record, then it); do not edit. -->

The current figures against their goals, one section per record in [`benchmarks/results/`](../benchmarks/results/)
([benchmarks/README.md](../benchmarks/README.md): the scripts and records; [CHANGELOG.md](../CHANGELOG.md): history).
Run from the repository root; loads are 1-minute averages before and after (above 1 on 2 cores: other work shared them).
*Transcribed* records were measured earlier and copied from this page; the others were written by their script.
"""


def kind(name: str) -> str:
    """The section kind of a record name: the name itself if it has a section, else the part before ``-``."""
    return name if name in SECTIONS or name == "checks" else name.split("-", 1)[0]


def ordered(records: dict[str, dict]) -> list[dict]:
    """Records in page order: by kind as in ``ORDER`` (unknown kinds last), then by name."""
    def key(record):
        k = kind(record["name"])
        return (ORDER.index(k) if k in ORDER else len(ORDER), record["name"])
    return sorted(records.values(), key=key)


def section_of(record: dict) -> Section:
    """The section of a record, or a plain one (goals only) for a kind this page does not know."""
    k = kind(record["name"])
    if k == "checks":
        return CHECKS
    return SECTIONS.get(k, Section(f"`{record['name']}`", "A record this page has no table for.", None))


def title(record: dict) -> str:
    """The section heading of a record."""
    variant = record["name"].split("-", 1)[1] if "-" in record["name"] else ""
    return section_of(record).title.format(variant=variant)


def slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces to hyphens."""
    return re.sub(r"[^\w\- ]", "", heading.lower()).replace(" ", "-")


def load_text(load: dict) -> str:
    """``load 0.91 before, 1.20 after`` from a record's 1-, 5- and 15-minute averages (1-minute shown)."""
    before, after = load.get("before") or [None], load.get("after") or [None]
    if before[0] is None and after[0] is None:
        return "load not recorded"
    return f"load {S.num(before[0])} before, {S.num(after[0])} after"


def machine_text(machine: dict) -> str:
    """``AMD EPYC, 2 cores, Python 3.11.7, torch 2.13.0+cpu`` from a record's machine."""
    parts = [machine.get("cpu") or "CPU not recorded"]
    if machine.get("cores"):
        parts.append(f"{machine['cores']} cores")
    parts += [f"{lib if lib != 'python' else 'Python'} {machine[lib]}" for lib in ("python", "torch", "numpy")
              if machine.get(lib)]
    return ", ".join(parts)


def provenance(record: dict) -> list[str]:
    """List items: how to reproduce a record, and where and when it was measured (with its note)."""
    lines = [f"* Reproduce: `{record['command']}`"] if record.get("command") else []
    if record["source"] == "run":
        at = f"at commit {record['commit'][:10]}" if record.get("commit") else "outside git"
        dirty = record.get("dirty") or []
        at += f" with uncommitted changes in {len(dirty)} file{'s' * (len(dirty) > 1)} of keyfill/" if dirty else ""
        source = f"written by `{record['script']}` {at} in {S.num(record.get('wall_seconds'), 0)} s"
    else:
        source = record["source"]
    note = f" Note: {record['note']}." if record.get("note") else ""
    if record.get("machine"):
        lines.append(f"* Measured {record['date']} on {machine_text(record['machine'])}; "
                     f"{load_text(record['load_average'])}; {source}.{note}")
    else:
        lines.append(f"* Source: {source}.{note}")
    return lines


def section(record: dict) -> list[str]:
    """One record's section: a list (what, how, where, the figures' setting), then the figures' tables; its goals
    are in the table at the top, which links here (one place for each)."""
    sec = section_of(record)
    body = []
    if sec.render:
        body = sec.render(record["goals"] if kind(record["name"]) == "checks" else record["figures"])
    items = [f"* {sec.about}"] + provenance(record)
    if body and body[0] and not body[0].startswith("|"):
        items.append(f"* {body[0]}")
        body = body[1:]
    if body and body[0]:
        body = [""] + body
    return [f"## {title(record)}"] + items + body + [""]


def goals_table(records: list[dict]) -> list[str]:
    """Every goal of every record, by issue, with a link to its section."""
    rows = []
    for record in records:
        link = f"[{record['name']}](#{slug(title(record))})"
        rows += [(int(g["issue"].split(",")[0]), g["issue"], g["goal"], g["measured"], S.verdict(g["met"]), link)
                 for g in record["goals"]]
    rows.sort(key=lambda row: row[0])
    return ["## Goals at a glance"] + S.table(["issue", "goal", "measured", "", "section"],
                                                  [list(row[1:]) for row in rows]) + [""]


def render(records: dict[str, dict]) -> str:
    """The whole page from the records (by name)."""
    records = ordered(records)
    lines = [INTRO] + goals_table(records)
    for record in records:
        lines += section(record)
    return "\n".join(lines).rstrip("\n") + "\n"


def write_page(text: str, page: Path) -> None:
    """Write the page atomically (a temporary file beside it, then a rename)."""
    fd, tmp = tempfile.mkstemp(prefix=f".{page.name}.", dir=page.parent)
    with os.fdopen(fd, "w", encoding="utf-8") as f:
        f.write(text)
    os.chmod(tmp, 0o644)
    os.replace(tmp, page)


def check(results: Path = RESULTS, page: Path = PAGE) -> list[str]:
    """The differences between ``page`` and what ``results`` give (a unified diff; empty when they agree)."""
    want = render(read_records(results))
    have = page.read_text(encoding="utf-8") if page.is_file() else ""
    return list(difflib.unified_diff(have.splitlines(), want.splitlines(), str(page), "from the records",
                                     lineterm=""))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--results", type=Path, default=RESULTS, help="folder of records (default benchmarks/results)")
    ap.add_argument("--page", type=Path, default=PAGE, help="the page (default docs/benchmarks.md)")
    ap.add_argument("--check", action="store_true", help="write nothing; exit 1 if the page differs")
    args = ap.parse_args(argv)
    if args.check:
        diff = check(args.results, args.page)
        if diff:
            print("\n".join(diff[:40]), file=sys.stderr)
            print(f"{args.page} is not what {args.results} gives: run python3 benchmarks/make_page.py",
                  file=sys.stderr)
            return 1
        return 0
    write_page(render(read_records(args.results)), args.page)
    return 0


if __name__ == "__main__":
    sys.exit(main())
