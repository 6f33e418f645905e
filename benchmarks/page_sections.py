"""The figures part of each section of docs/benchmarks.md, one function per kind of record (``make_page.py``).

Every function takes a record's ``figures`` (see :mod:`results`) and returns Markdown lines. Figures a record
lacks (``None``, as in records transcribed from an older page) print as ``-``.
"""

from __future__ import annotations

LENGTHS = ("5", "15", "30", "45")
METRICS = ("L2Q", "L2P", "NPSS")
# JSON objects are written with sorted keys, so the order of rows lives here
BVH_ROWS = ("keyfill read", "numpy loadtxt (floor)", "bvhio readAsBvh", "bvh Bvh() + floats", "keyfill write",
            "bvhio writeBvh")
SPLIT = ("start-up (keyfill complete --help)", "read (io.load)", "compute (complete, cubic)", "write (io.save)",
         "rest (end to end minus the above)")
VIZ_ROWS = ("preview GIF side (CLI)", "preview GIF 3d (CLI)", "plot PNG, 6 panels (CLI)", "plot SVG, 6 panels (CLI)",
            "plot PDF, 6 panels (CLI)", "plot PNG, 3 files x 6 panels (CLI)", "start-up + read (keyfill info, CLI)",
            "preview GIF side (library)", "matplotlib FuncAnimation + PillowWriter (peer)")
CONFIGS = ("alone", "pin low", "pin high", "contact low", "contact high", "pin + contact")
METHODS = ("real", "zero-velocity", "interpolation", "linear", "cubic", "velocity", "gan", "transformer")
LAYOUTS = ("in-filling, key every 5", "in-filling, key every 10", "in-filling, key every 15",
           "blending, 10 + gap 15 + 10", "blending, 10 + gap 30 + 10")
KEY_KINDS = {"full": "whole keys", "root": "root-only keys (5.1)", "half": "half-body keys (5.2)",
             "plane": "2-D keys (5.3)", "sketch": "2-D sketch keys, bones stretched (5.3)"}


def in_order(mapping: dict, preferred=()) -> list:
    """The keys of ``mapping``: those in ``preferred`` in its order, then the others (numbers by value)."""
    rest = sorted((k for k in mapping if k not in preferred), key=lambda k: (not k.isdigit(), int(k) if k.isdigit()
                                                                             else 0, k))
    return [k for k in preferred if k in mapping] + rest


def num(value, digits: int = 2, scale: float = 1.0) -> str:
    """``value * scale`` with ``digits`` decimals (thousands separated), or ``-`` when it is missing."""
    return "-" if value is None else f"{value * scale:,.{digits}f}"


def sci(value) -> str:
    """``value`` in two-digit scientific notation, or ``-``."""
    return "-" if value is None else f"{value:.1e}"


def verdict(met: bool) -> str:
    """``met`` or a bold ``missed``."""
    return "met" if met else "**missed**"


def table(header: list[str], rows: list[list[str]]) -> list[str]:
    """A Markdown table."""
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    return lines + ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]


def median_best(timing: dict | None, digits: int = 1) -> str:
    """``median (best)`` of a ``{"median", "best"}`` timing in ms."""
    if not timing:
        return "-"
    best = timing.get("best")
    return num(timing.get("median"), digits) + ("" if best is None else f" ({num(best, digits)})")


# --- files and the command line ------------------------------------------------------------------------------


def bvh_io(f: dict) -> list[str]:
    """BVH read and write rows."""
    size = "" if f.get("bytes") is None else f"{f['bytes'] / 1e6:.1f} MB, "
    lines = [(f"File `{f.get('file')}`: {size}{num(f.get('frames'), 0)} frames, {f.get('joints')} joints, "
             f"{f.get('channels')} channels; medians of {f.get('repeat')} runs in one process."), ""]
    rows = [[name, num(r.get("seconds"), 3), num(r.get("cpu_seconds"), 3), num(r.get("mb_per_s"), 1),
             num(r.get("x_keyfill_read"), 2)] for name, r in ((n, f["rows"][n]) for n in in_order(f["rows"],
                                                                                                 BVH_ROWS))]
    return lines + table(["reader / writer", "wall s", "CPU s", "MB/s", "x keyfill read"], rows)


def complete(f: dict) -> list[str]:
    """``keyfill complete --method cubic`` end to end and its split."""
    inp = f["input"]
    size = "" if inp.get("bytes") is None else f", {inp['bytes'] / 1e6:.1f} MB in, {f['output_bytes'] / 1e6:.1f} MB out"
    runs = f.get("end_to_end_runs")
    runs = "" if not runs else f" Runs (s): {', '.join(num(t, 2) for t in runs)}."
    lines = [(f"`{f['timed_command']}`: {num(inp['frames'], 0)} frames, {inp['joints']} joints, "
              f"{num(inp['keys'], 0)} keys{size}; a subprocess per run, medians of {f['repeat']} after a cold first "
              f"run ({num(f.get('first_run_seconds'), 3)} s) and a warm-up.{runs}"), ""]
    rows = [["end to end", num(f["end_to_end_seconds"], 3), num(f.get("end_to_end_cpu_seconds"), 3)]]
    cpu = f.get("split_cpu_seconds") or {}
    split = f["split_seconds"]
    rows += [[name, num(split[name], 3), num(cpu.get(name), 3) if name in cpu else ""]
             for name in in_order(split, SPLIT)]
    learned = f.get("learned_startup")
    if learned:
        sec = learned["seconds"]
        rows.append([f"cubic / transformer / gan, {learned['frames']}-frame human file (new process)",
                     " / ".join(num(sec[m], 3) for m in ("cubic", "transformer", "gan")), ""])
    return lines + table(["", "wall s", "CPU s"], rows)


def blender_interop(f: dict) -> list[str]:
    """Worst bone-head deviation per fixture and format."""
    formats = sorted({r["format"] for r in f["rows"]}, key=("bvh", "usda", "usdc").index)
    by_file: dict[str, dict] = {}
    for r in f["rows"]:
        by_file.setdefault(r["file"], {"frames x joints": f"{r['frames']} x {r['joints']}"})[r["format"]] = r
    header = ["fixture", "frames x joints"] + [f"{fmt.upper()}: worst (units) / height" for fmt in formats]
    rows = [[name, v["frames x joints"]] + [f"{sci(v[fmt]['worst'])} / {sci(v[fmt]['relative'])}" for fmt in formats]
            for name, v in by_file.items()]
    return [f"Blender {f['blender']}; bound {f['bound']:g} of the skeleton's rest height.", ""] + table(header, rows)


def convert_memory(f: dict) -> list[str]:
    """Peak memory of ``keyfill convert`` per output format."""
    lines = [(f"A {f['file_mb']} MiB BVH ({num(f['frames'], 0)} frames, CMU skeleton); the fixed overhead (a 4-frame "
             f"file) is {f['overhead_mb']} MiB; medians of {f['repeat']}."), ""]
    rows = [[f"`.{fmt}`", num(r["peak_mb"], 0), num(r["peak_over_file"], 1), num(r["peak_minus_overhead_over_file"], 1),
             num(r["seconds"], 0), num(r["output_mb"], 0)]
            for fmt, r in ((fmt, f["outputs"][fmt]) for fmt in in_order(f["outputs"], ("usda", "bvh")))]
    return lines + table(["convert to", "peak RSS MiB", "/ file", "beyond the overhead / file", "wall s",
                          "output MiB"], rows)


def viz(f: dict) -> list[str]:
    """``keyfill preview`` and ``plot`` timings; the in-process split of a GIF in one sentence."""
    res = f["results"]
    rows = []
    for name in (n for n in VIZ_ROWS if n in res):
        r = res[name]
        size = "" if r.get("bytes") is None else f"{r['bytes'] / 1000:,.0f} kB"
        goal = f"< {r['goal_s']:g} s" if "goal_s" in r else ""
        rows.append([name, num(r.get("seconds")), num(r.get("cpu_seconds")), size, goal])
    stages = [name for name in res if name.startswith("  ")]  # the split of one GIF: setup, frames, encoding
    stages.sort(key=lambda name: ("setup" not in name, "encoding" in name))
    split = "; ".join(f"{name.strip()} {num(res[name]['cpu_seconds'])} CPU-s" for name in stages)
    speedup = res.get("matplotlib FuncAnimation + PillowWriter (peer)", {}).get("keyfill_speedup_cpu")
    text = f"Medians of {f['repeat']} runs."
    text += f" keyfill's GIF takes {speedup:.1f}x less CPU than matplotlib's own route." if speedup else ""
    text += f" Where the library's GIF goes: {split}." if split else ""
    return [text, ""] + table(["what", "wall s", "CPU s", "output", "goal"], rows)


# --- the lamp ------------------------------------------------------------------------------------------------


def simulate(f: dict) -> list[str]:
    """Where the simulator's speed comes from (sections 1-5 of the script)."""
    c, r, e, a, t = f["control"], f["resets"], f["early_stop"], f["annealing"], f["time_step"]
    rows = [["keyfill's PD torques (TORQUE_CONTROL) vs pybullet POSITION_CONTROL",
             f"{num(c['torque_us_per_step'], 1)} vs {num(c['position_us_per_step'], 1)} us per step"],
            ["`restoreState` per episode vs a new connection and world", (f"{num(r['restore_us'], 0)} us vs "
             f"{num(r['rebuild_ms'], 0)} ms")],
            ["early termination of falls", (f"{num(e['stopped']['ms'], 0)} ms ({num(e['stopped']['steps'], 0)} steps) "
             f"vs {num(e['full']['ms'], 0)} ms ({num(e['full']['steps'], 0)} steps) per fallen episode")],
            [f"annealing, {a['iterations']} iterations per run, one process",
             f"{num(a['median_s_per_run'], 1)} s per run, {num(a['episodes_per_s'], 0)} episodes/s"]]
    ref = t["reference"]
    rows += [[f"time step 1/{s['hz']} s, {s['iterations']} solver iterations", (f"{num(s['ms_per_episode'], 1)} ms "
              f"per episode; median error of hop distance {num(s['distance_error_cm'], 1)} cm, of height "
              f"{num(s['height_error_mm'], 1)} mm against 1/{ref['hz']} s, {ref['iterations']} iterations")]
             for s in t["rows"] if s["iterations"] == t["shipped_iterations"]]
    return table(["choice", "measured"], rows)


def simulate_dataset(f: dict) -> list[str]:
    """A full dataset build, in one sentence."""
    rate = f.get("acceptance_rate")
    return [(f"{num(f['sequences'], 0)} sequences from {num(f.get('runs'), 0)} runs "
            f"({'-' if rate is None else f'{100 * rate:.0f} %'} accepted) with {f['workers']} worker"
             f"{'s' * (f['workers'] != 1)}, "
            f"{f['iterations']} annealing iterations per run: {num(f['wall_s'], 1, 1 / 60)} min wall, "
            f"{num(f.get('cpu_s'), 1, 1 / 60)} CPU-min, {num(f.get('episodes'), 0)} episodes, "
            f"{num(f.get('episodes_per_s_per_core'), 0)} episodes/s per core, "
            f"{num(f.get('sequences_per_hour'), 0)} sequences/hour.")]


def arnn_tables(f: dict) -> list[str]:
    """Tables 1-2 of Zhang & van de Panne 2018: keyfill's rows."""
    cubic = next(r for r in f["rows"] if r["label"] == "cubic")
    rows = []
    for r in f["rows"]:
        cells = [r["label"]]
        for part in ("all_keys", "deleted_keys"):
            s = r[part]
            cells += [num(s["key"], 5), num(s["frame"], 5), num(s["total"], 5),
                      num(s["frame"] / cubic[part]["frame"], 2)]
        train = ""
        if r.get("epochs"):
            cpu = "" if r.get("train_cpu_minutes") is None else f"{r['train_cpu_minutes']} CPU-min, "
            train = f"{r['epochs']} epochs, {cpu}{r['train_minutes']} min wall"
        rows.append(cells + [train])
    header = ["method", "key", "frame", "total", "frame / cubic", "key (1-2 deleted)", "frame (1-2 deleted)",
              "total (1-2 deleted)", "frame / cubic (1-2 deleted)", "training"]
    return [(f"{f['test_sequences']} test sequences of `{f['data']}`; losses on the standardised variables; "
            f"key deletions drawn with seed {f['seed']}."), ""] + table(header, rows)


def arnn_inference(f: dict) -> list[str]:
    """ARNN inference timings, medians (best)."""
    return [(f"{f['frames']} frames, {f['keys']} keys, {f['threads']} torch thread(s), model "
            f"`{f['model'] or 'built-in'}`; medians in ms (best): the network alone (`predict`) "
            f"{median_best(f['network_ms'], 2)}, the whole method (`complete(..., \"arnn\")`) "
            f"{median_best(f['complete_ms'], 2)}, cubic in the same run {median_best(f['cubic_ms'], 2)}, loading the "
            f"model folder {median_best(f['load_ms'], 2)}, `keyfill complete --method arnn` as a new process "
            f"{median_best(f['cli_ms'], 0)}.")]


# --- editing -------------------------------------------------------------------------------------------------


def _qp_cell(cell: dict) -> str:
    text = f"{num(cell['median_ms'], 1)} / {num(cell['median_cpu_ms'], 1)} ({cell['paper_ms']:g})"
    text = text if cell["met"] else f"**{text}**"
    return text + (f" {cell['failed']} unreached" if cell["failed"] else "")


def tangent_qp(f: dict) -> list[str]:
    """Table 3 of Ciccone et al. 2019: every configuration, length and DOF count."""
    dofs = in_order({d: 0 for by_len in f["bandai"].values() for cells in by_len.values() for d in cells})
    rows = []
    for config in in_order(f["bandai"], CONFIGS):
        by_length = f["bandai"][config]
        rows += [[config, length] + [_qp_cell(by_length[length][d]) for d in dofs] for length in in_order(by_length)]
    for row in rows:  # the lamp's cells beside the Bandai walk's "alone" rows
        row.append(_qp_cell(f["lamp"][row[1]]) if row[0] == "alone" and row[1] in f["lamp"] else "-")
    tangents = "unified tangents" if f["unified"] else "the paper's segment-only tangents"
    return [(f"Cells: median wall-clock / CPU ms per edit over {f['edits']} edits (the paper's ms, Mosek on an "
            f"i7-4930K); **bold**: above a tenth of the goal's figure; \"unreached\": edits that stopped short of "
            f"the target. {tangents.capitalize()}; solver {f['solver']}."), ""] + table(
        ["configuration", "frames"] + [f"{d} DOF" for d in dofs] + ["lamp, 24 DOF"], rows)


# --- the transformer -----------------------------------------------------------------------------------------


def _scores(by_length: dict, metric: str, digits: int) -> list[str]:
    return [num(by_length[n].get(metric), digits) if n in by_length else "-" for n in LENGTHS]


def _ratio(f: dict, method: str, metric: str, n: str) -> float:
    scores = f["inbetweening"]
    return scores[method][n][metric] / scores["interpolation"][n][metric]


def transformer_quality(f: dict) -> list[str]:
    """The LaFAN1 table, its ratios against SSMCT and Qin et al., and other key layouts."""
    p = f["protocol"]
    held = f.get("test_pattern", "*_normal_*")
    lines = [(f"LaFAN1 protocol: {num(p['test_windows'], 0)} test windows of the {p['test_clips']} held-out clips "
             f"`{held}`, statistics from {num(p['train_windows'], 0)} windows of {num(p['train_clips'], 0)} clips of "
             f"the other styles of their folder; transitions of 5-45 frames."), ""]
    header = ["method"] + [f"{m} {n}" for m in METRICS for n in LENGTHS] + ["skating cm/s", "jitter m/s^3"]
    rows = []
    for method in in_order(f["inbetweening"], METHODS):
        by_length = f["inbetweening"][method]
        realism = [" / ".join(num(by_length[n].get(k), 1 if k == "skate" else 0) for n in LENGTHS)
                   for k in ("skate", "jitter")]
        rows.append([method] + _scores(by_length, "L2Q", 4) + _scores(by_length, "L2P", 4)
                    + _scores(by_length, "NPSS", 5) + realism)
    fair = " / the fair anchor (issue 46: the Delta-Interpolator's at 5-30, Qin's first stage at 45)" \
        if "fair" in f else ""
    lines += table(header, rows) + ["", ("Ratios to interpolation, each cell: the transformer's / cubic's / SSMCT's "
                                        f"/ Qin et al. 2022's headline{fair} (the papers' data is LaFAN1, so ratios, "
                                        "not values, are compared; at 45 frames SSMCT's 30-frame ratio); **bold**: a "
                                        "paper's ratio the transformer misses:"), ""]
    return lines + _ratio_table(f) + [""] + _layouts_table(f)


def _paper(ratio: float | None, mine: float, digits: int) -> str:
    return "-" if ratio is None else (num(ratio, digits) if mine <= ratio else f"**{num(ratio, digits)}**")


def _ratio_table(f: dict) -> list[str]:
    rows = []
    for m in METRICS:
        cells = []
        for n in LENGTHS:
            mine = _ratio(f, "transformer", m, n)
            fair = f" / {_paper(f['fair'][m].get(n), mine, 3)}" if "fair" in f else ""
            cells.append(f"{num(mine, 3)} / {num(_ratio(f, 'cubic', m, n), 3)} / {_paper(f['ssmct'][m][n], mine, 3)}"
                         f" / {_paper(f['qin'][m].get(n), mine, 2)}{fair}")
        rows.append([m] + cells)
    return table(["metric"] + [f"{n} frames" for n in LENGTHS], rows)


def _layouts_table(f: dict) -> list[str]:
    methods = [m for m in ("cubic", "velocity", "transformer") if m in next(iter(f["layouts"].values()))]
    rows = []
    for name in in_order(f["layouts"], LAYOUTS):
        res = f["layouts"][name]
        rows.append([name] + [", ".join(num(res[m][metric] / res["interpolation"][metric], 3) for m in methods)
                              for metric in METRICS])
    return ([("Other key layouts of the same windows (every frame between the first and last key that is not a key "
             "is scored):"), ""]
            + table(["layout"] + [f"{metric} / interp: {', '.join(methods)}" for metric in METRICS], rows))


def transformer(f: dict) -> list[str]:
    """Inference speed per thread count and batch."""
    rows = [[r["threads"], f"{r['batch']} x 30", num(r["network_ms"], 1), num(r["complete_ms"], 1),
             num(r.get("onnx_complete_ms"), 1), num(r["goal_ms"], 0), num(r["paper_ms"], 0)] for r in f["results"]]
    rate = f.get("matmul_gflops_1_thread")
    return [(f"Model: {f['model']}; {f['frames']} frames in (10 context, 30 to fill, 1 key); medians of "
            f"{f['repeat']} calls; one thread's float32 matrix products: "
            f"{'-' if rate is None else f'{rate:.0f}'} GFLOP/s."), ""] + table(
        ["torch threads", "batch x frames", "network ms", "complete ms", "onnxruntime ms (1 thread)", "goal ms",
         "paper ms (i7-8700K)"], rows)


# --- the gan -------------------------------------------------------------------------------------------------


def gan_speed(f: dict) -> list[str]:
    """gan inference per length and thread count."""
    by_frames: dict[int, dict] = {}
    for r in f["rows"]:
        by_frames.setdefault(r["frames"], {"keys": r["keys"]})[r["threads"]] = r
    threads = sorted({r["threads"] for r in f["rows"]})
    rows = [[num(n, 0), v["keys"]] + [median_best(v[t]["complete_ms"]) if t in v else "-" for t in threads]
            for n, v in sorted(by_frames.items())]
    load = f["rows"][0]["load_ms"]
    return [(f"Keys every {f['gap']} frames and on the last; medians of {f['repeat']} calls (best in brackets); "
            f"loading the model folder: {median_best(load, 0)} ms."), ""] + table(
        ["frames", "keys"] + [f"{t} thread{'s' * (t > 1)} ms" for t in threads], rows)


def _sampled_rows(s: dict, paper: dict) -> list[list[str]]:
    rows = []
    for kind in in_order(s["key_errors"], tuple(KEY_KINDS)):
        e = s["key_errors"][kind]
        rows.append([f"key error before post-processing, {KEY_KINDS.get(kind, kind)}: joints / root (cm)",
                     f"{num(e['joints_cm'], 1)} / {num(e['root_cm'], 0)}",
                     f"{paper['key_joints_cm']} / {paper['key_root_cm']}" if kind == "full" and "key_joints_cm" in paper
                     else ""])
    if "dna_error_1_cm" in s:
        rows += [["DNA error, Eq. 11 / Eq. 12 (cm)", f"{num(s['dna_error_1_cm'], 2)} / {num(s['dna_error_2_cm'], 2)}",
                  f"{paper['dna_error_1_cm']} / {paper['dna_error_2_cm']}"]]
    v = s["variety_cm"]
    rows.append(["variety through the same keys: 4 noise seeds / 4 DNAs (cm)",
                 f"{num(v['seeds'], 1)} / {num(v.get('dnas'), 2)}", ""])
    if "dna_pull_cm" in s:  # records from before the figure existed have none
        pull = s["dna_pull_cm"]
        rows.append(["DNA pull: Eq. 11 error to the DNA given / to another DNA (cm)",
                     f"{num(pull['own'], 2)} / {num(pull['other'], 2)}", ""])
    return rows


def gan_quality(f: dict) -> list[str]:
    """Table 2 (path predictor), Table 4 (key errors) and realism of one gan model on one held-out set."""
    s, paper = f["sampled"], f["paper"]
    p = f.get("path_cm")  # none for a model with a base (its root path is the keys' interpolation)
    rows = [["path predictor error per frame / after 64 / after 128 frames (cm)",
             f"{num(p['1'])} / {num(p['64'], 1)} / {num(p['128'], 1)}" if p else "none (the base's root path)",
             f"{paper['path_cm_per_frame']} per frame, {paper['path_cm_2s']} after 2.1 s (60 fps)"]]
    if "key_errors_every" in f:
        e = f["key_errors_every"]
        rows.append([(f"key errors before post-processing, keys every {e['gap']} frames of {e['clips']} clips: "
                     "joints / root (cm)"), f"{num(e['joints_cm'], 1)} / {num(e['root_cm'], 1)}", "goal: 5 / 30"])
    held = f.get("test_pattern", "*_normal_*")
    layouts = (f"{s['sequences']} key layouts of {num(s['frames'], 0)} frames over them" if s else
               "a matched base: no Table 4 layouts (they jump between clips, which a library search does not follow)")
    lines = [f"Held-out clips `{held}`; {layouts}.", ""]
    lines += table(["figure", "measured", "paper"], rows + (_sampled_rows(s, paper) if s else []))
    gaps = in_order(f["realism"])
    methods = [m for m in in_order(f["realism"][gaps[0]], METHODS) if m != "linear"]  # linear: the feet section
    realism = []
    for m in methods:
        row = [m]
        for gap in gaps:
            r = f["realism"][gap].get(m)
            row += ["-"] * 3 if r is None else [num(r["foot_skating_cm_s"], 1), num(r["jitter_m_s3"], 1),
                                                 num(r.get("gap_error_cm"), 2)]
        realism.append(row + [num(max(f["realism"][g][m]["range_violations_pct"] for g in gaps if m in f["realism"][g]), 2)])
    head = ["method"] + [f"{what}, keys every {gap}" for gap in gaps for what in ("skating cm/s", "jitter m/s^3",
                                                                                 "gap error cm")]
    clips = ", ".join(f"{f['realism'][g]['real']['clips']} clips at keys every {g}" for g in gaps if "real" in f["realism"][g])
    bones = max(r["bone_error_cm"] for g in gaps for r in f["realism"][g].values())
    return lines + ["", f"Realism of whole clips ({clips}; largest bone-length error {num(bones, 2)} cm):", ""] + \
        table(head + ["range violations %"], realism)


def gan_dna(f: dict) -> list[str]:
    """Motion DNA and partial-key figures."""
    return [(f"{f['sequences']} key layouts of {num(f['frames'], 0)} frames over {f.get('clips') or '-'} held-out "
            "clips."), ""] + table(["figure", "measured", "paper"], _sampled_rows(f, f["paper"]))


# --- batch and ONNX ------------------------------------------------------------------------------------------


def batch(f: dict) -> list[str]:
    """Batch against single calls; ONNX start-up, latency and parity."""
    lines = []
    if "batch" in f:
        b = f["batch"]
        lines += [(f"`{b['batch_command']}` on {num(b['files'], 0)} lamp files, beside {b['single_sample']} single "
                  "calls:"), ""] + table(["", "wall", "per file"], [
            ["one batch command", f"{num(b['batch_wall_s'], 1)} s ({num(b['batch_cpu_s'], 1)} CPU-s)",
             f"{num(b['batch_per_file_s'], 3)} s"],
            ["single calls (median, best)", f"{num(b['single_median_s'])} s, {num(b['single_best_s'])} s",
             f"{num(b['single_median_s'])} s"],
            ["ratio", "", f"{num(b['ratio'], 0)}x"]]) + [""]
    s, lat = f["startup"], f["latency"]
    rows = [[f"start-up of `keyfill complete --method {m}` (s)", num(s[f"{m}_torch"]["median_s"]),
             num(s[f"{m}_onnx"]["median_s"]), num(s[f"{m}_onnx_over_torch"])] for m in ("arnn", "transformer")]
    rows += [[f"1 x 30 frames, {m} network, one thread (ms; best)", median_best(lat[f"{m}_1x30_torch_ms"]),
              median_best(lat[f"{m}_1x30_onnx_ms"]), num(lat[f"{m}_1x30_onnx_ms"]["median"]
                                                         / lat[f"{m}_1x30_torch_ms"]["median"])]
             for m in ("transformer", "arnn")]
    lines += table(["", "torch", "onnxruntime", "onnx / torch"], rows)
    return lines + ["", (f"Parity, onnxruntime against torch: transformer {sci(lat['transformer_parity_relative'])} of "
                        f"the output's largest magnitude, ARNN {sci(lat['arnn_parity_relative_to_std'])} of the "
                        "variables' standard deviation.")]


# --- checks that are no benchmark script ---------------------------------------------------------------------


def checks(goals: list[dict]) -> list[str]:
    """Goals checked by tests, training runs and make targets, each with its own command and machine."""
    rows = [[g["issue"], g["goal"], f"`{g['command']}`" if g.get("command") else "", f"{g['date']}, {g['machine']}",
             g["measured"], verdict(g["met"])] for g in goals]
    return table(["issue", "goal", "command", "measured on", "measured", ""], rows)


def retarget(f: dict) -> list[str]:
    """Gap errors through retargeting per rig (each cell: 30 / 60 / 120 fps), the learned methods beside cubic."""
    cols = [("cubic", "15"), ("transformer", "15"), ("cubic", "30"), ("transformer", "30"), ("cubic", "60"),
            ("gan", "60")]
    rows = []
    for rig, by_fps in f["gap_error_cm"].items():
        fps_list = sorted(by_fps, key=int)
        cells = []
        for method, step in cols:
            values = " / ".join(num(by_fps[fps][method][step]) for fps in fps_list)
            ratio = f["ratio_to_cubic"][rig][fps_list[0]][method][step]
            cells.append(values if method == "cubic" else f"{values} ({num(ratio)}x)")
        rows.append([rig] + cells)
    rt, sp = f["round_trip"], f["speed"]
    fps_text = " / ".join(sorted(next(iter(f["gap_error_cm"].values())), key=int))
    return [(f"{f['clips']} held-out `normal` clips (at most {f['max_frames']} frames), mean error of the mapped "
             f"joints over non-key frames in cm of the rig's units at {fps_text} fps (ratio to cubic's at 30); keys "
             "every N frames at 30 fps, at the same times at the other rates. Round trip Bandai -> Mixamo -> "
             f"Bandai: at most {num(rt['max_error_cm'])} cm ({num(100 * rt['max_share_of_height'])} % of the "
             f"height). One transformer completion of {sp['frames']:,} frames at {sp['fps']} fps: "
             f"{num(sp['total_s'])} s, of which the bridge {num(100 * sp['bridge_share'], 0)} % beyond the model's "
             f"own {num(sp['model_s'])} s."), ""] + table(["rig"] + [f"{m} @{s}" for m, s in cols], rows)


def feet(f: dict) -> list[str]:
    """Foot skating, jitter and gap error of each method raw -> locked, per style set and key spacing."""
    methods = ("linear", "cubic", "transformer", "gan")
    rows = []
    for name, by_gap in f["scores"].items():
        for gap, row in by_gap.items():
            real = row["real"]
            cells = [f"{num(real['foot_skating_cm_s'], 1)}, {num(real['jitter_m_s3'], 0)}"]
            for m in methods:
                if m not in row:
                    cells.append("-")
                    continue
                r, lk = row[m]["raw"], row[m]["locked"]
                cells.append(f"{num(r['foot_skating_cm_s'], 1)} -> {num(lk['foot_skating_cm_s'], 1)}, "
                             f"{num(r['jitter_m_s3'], 0)} -> {num(lk['jitter_m_s3'], 0)}, "
                             f"{num(r['gap_error_cm'])} -> {num(lk['gap_error_cm'])}")
            rows.append([name, gap] + cells)
    sp = f["speed"]
    return [(f"Each cell: foot skating (cm/s), jitter (m/s^3) and gap error (cm), raw -> locked; real clips: skating, "
             f"jitter. {', '.join(f'{k}: {v}' for k, v in f['clips'].items())} clips of {f['seconds']} s. "
             f"`lock_feet` on {sp['frames']:,} frames: {num(1e3 * sp['lock_s'], 1)} ms against the gan "
             f"completion's {num(1e3 * sp['complete_s'], 1)} ms."), ""] + table(
        ["held-out style", "keys every", "real"] + list(methods), rows)


def realism_table(f: dict, methods: tuple[str, ...], note: str) -> list[str]:
    """Held-out realism per method (``f["quality"]``: set -> keys every -> method -> skating, jitter, gap
    error, and the real clips'), one row per set and key spacing."""
    rows = []
    for name, by_gap in f["quality"].items():
        real = by_gap["real"]
        for gap in (g for g in by_gap if g != "real"):
            cells = [f"{num(real['foot_skating_cm_s'], 1)}, {num(real['jitter_m_s3'], 0)}"]
            for m in methods:
                r = by_gap[gap][m]
                cells.append(f"{num(r['foot_skating_cm_s'], 1)}, {num(r['jitter_m_s3'], 0)}, {num(r['gap_error_cm'])}")
            rows.append([name, gap] + cells)
    out = [(f"Each cell: foot skating (cm/s), jitter (m/s^3), gap error (cm); real clips: skating, jitter. "
            f"{', '.join(f'{k}: {v}' for k, v in f['clips'].items())} clips. {note}"), ""]
    return out + table(["held-out clips", "keys every", "real"] + list(methods), rows) + [""]


def transformer_start(f: dict) -> list[str]:
    """The shipped transformer started from match's in-between against match and its pre-fill."""
    return realism_table(f, ("cubic", "transformer", "match raw", "match", "transformer from match"),
                         f"`match raw`: `--feet free`; `match`: its default (feet locked); `transformer`: "
                         f"`{f['model']}` from its pre-fill; `transformer from match`: its correction added to "
                         "`match raw`, feet free.")


def gan_match(f: dict) -> list[str]:
    """The gan on a matched base as a generator: realism per seed against the baselines, variety, DNA, speed."""
    feet = f.get("feet", "free")
    match = f.get("match", "match raw")
    rows = []
    for name, by_gap in f["quality"].items():
        real = by_gap["real"]
        for gap in sorted((g for g in by_gap if g != "real"), key=int):
            r = by_gap[gap]

            def cell(v):
                return f"{num(v['foot_skating_cm_s'], 1)}, {num(v['jitter_m_s3'], 0)}, {num(v['gap_error_cm'])}"

            seeds = list(r["seeds"].values())
            rows.append([name, gap, f"{num(real['foot_skating_cm_s'], 1)}, {num(real['jitter_m_s3'], 0)}",
                         *(cell(r[m]) if m in r else "" for m in ("cubic", match, "gan", "transformer")),
                         cell(seeds[0]), " / ".join(num(s["gap_error_cm"]) for s in seeds[1:]),
                         num(r["pairwise_cm"], 1), num(r["best_of_5_cm"])])
    locked = "the feet of match and of the model locked (their default), the others' free" if feet == "lock" \
        else "feet free"
    out = [(f"Each cell: foot skating (cm/s), jitter (m/s^3), gap error (cm); {locked}, guard off; real clips: "
            f"skating, jitter. {', '.join(f'{k}: {v}' for k, v in f['clips'].items())} clips. `gan`: the shipped "
            f"spline-base model; `{f['model']}`: seed 0, then the gap errors of seeds 1-4, the mean pairwise distance of "
            "the five seeds' in-betweens and the best of their gap errors (the transformer fills gaps of at most 63 "
            "frames)."), ""]
    out += table(["held-out clips", "keys every", "real", "cubic", match, "gan", "transformer", "seed 0",
                  "seeds 1-4 (cm)", "pairwise (cm)", "best of 5 (cm)"], rows) + [""]
    dna = "; ".join(f"{name}: Eq. 11 error {num(d['eq11_own_cm'])} cm to the DNA given, {num(d['eq11_other_cm'])} to "
                    f"the other, the DNA moves the in-between {num(d['dna_change_cm'])} cm and the seed "
                    f"{num(d['seed_change_cm'])} cm, gap error {num(d['gap_error_cm'])} cm" for name, d in f["dna"].items())
    sp = f["speed"]
    return out + [(f"Motion DNA (keys every 60, a run's and a wave's): {dna}. Speed: {sp['frames']:,} frames keyed "
                  f"every {sp['key_every']} in {num(sp['median_s'], 3)} s on {sp['threads']} thread (median of "
                  f"{len(sp['runs'])}, library search included).")]


def match(f: dict) -> list[str]:
    """``--method match`` against the spline and the shipped models; variety; the guard; speed."""
    out = realism_table(f, ("cubic", "transformer", "gan", "match raw", "match"),
                        "`match raw`: `--feet free`; `match`: its default (feet locked).")
    var = [[name, num(v["pairwise_cm"], 1), num(v["best_of_5_gap_error_cm"]),
            "; ".join(f"{num(s['foot_skating_cm_s'], 1)}, {num(s['jitter_m_s3'], 0)}, {num(s['gap_error_cm'])}"
                      for s in v["seeds"].values())] for name, v in f["variety"].items()]
    out += ["Variety at keys every 60 (seeds 0-4):", ""] + table(
        ["held-out clips", "mean pairwise distance (cm)", "best-of-5 gap error (cm)", "per seed: skating, jitter, error"],
        var) + [""]
    guard = []
    for gap, row in f["guard"]["unknown"].items():
        for m, v in row.items():
            k = f["guard"]["known"][gap][m]
            guard.append([gap, m, num(v["cubic_gap_error_cm"]), num(v["off_gap_error_cm"]), num(v["guard_gap_error_cm"]),
                          num(v["flagged_pct"], 0), num(k["changed_pct"], 1), num(k["gap_error_change_pct"], 1)])
    out += [("The guard: unknown actions (dataset-1 call, dance, kick, punch, respond, slash) and the known held-out "
             "clips (normal, dataset-2):"), ""] + table(
        ["keys every", "method", "cubic (cm)", "guard off (cm)", "guard on (cm)", "unknown gaps flagged (%)",
         "known gaps changed (%)", "known error change (%)"], guard) + [""]
    sp = f["speed"]
    text = (f"Speed: a gap's search {num(sp['gap_search_ms']['median'], 1)} ms (median of {sp['gap_search_ms']['gaps']}); "
            f"{sp['frames']:,} frames with keys every 60: {num(sp['complete_warm_s']['median'])} s in process, "
            f"{num(sp['complete_cold_s']['median'])} s as a fresh `keyfill complete`; the shipped library "
            f"({sp['library_frames']:,} frames) {num(sp['library_resident_mib'], 0)} MiB resident")
    if "build" in f:
        b = f["build"]
        text += f"; building the library of dataset-2 ({b['clips']:,} clips) {num(b['seconds'], 1)} s on {b['workers']} workers"
    return out + [text + "."]


def formats(f: dict) -> list[str]:
    """Write and read seconds and file size per format."""
    rows = [[suffix, num(r["write_s"], 3), num(r["read_s"], 3), num(r["bytes"] / 1e6, 1)]
            for suffix, r in f["formats"].items()]
    return [f"Medians of {f['repeat']} runs after a warm-up."] + [""] + table(
        ["format", "write s", "read s", "MB"], rows)


def scale(f: dict) -> list[str]:
    """Every command on long takes: CPU seconds and peak memory per frame count, the fitted exponents, the
    memory over the motion's arrays, the start-up, and the log-log plot."""
    counts = [str(n) for n in f["frames"]]
    lines = [(f"{f['joints']} joints, keys every {f['key_every']} frames; CPU seconds (user + system) and peak "
              f"resident MiB of one command as a child process (median of {f['repeat']} runs below 100k frames, "
              "one run from 100k on). *Exponent*: the slope of log CPU time against log frames from 10k frames on "
              "(below, the fixed start-up hides the per-frame cost); *memory*: the peak beyond the row's own peak "
              "at the fewest frames (the fixed amount) over the motion's float64 arrays (56 bytes per joint and "
              "frame), at the most frames."), ""]
    if f.get("plot"):
        lines += [f"![CPU seconds against frames, log-log]({f['plot'].removeprefix('docs/')})", ""]
    rows = []
    for name, r in f["rows"].items():
        cpu = [num(r["cpu_seconds"].get(n), 2) for n in counts]
        rows.append([name, *cpu, num(r.get("exponent"), 2), num(r["fixed_mib"], 0),
                     num(r["peak_mib"][counts[-1]], 0), num(r["memory"], 2)])
    top = f"{int(counts[-1]):,}"
    header = ["command", *[f"CPU s, {int(n):,} frames" for n in counts], "exponent", "fixed MiB",
              f"peak MiB, {top}", f"memory (x the motion's {num(next(iter(f['rows'].values()))['motion_mib'], 0)} MiB)"]
    lines += table(header, rows)
    if f.get("merged"):
        lines += ["", "Rows re-measured later replace the first run's (each row's `commit` in the record says when): "
                  + "; ".join(f"`{c}`" for c in f["merged"]) + "."]
    start = f.get("startup")
    if start:
        lines += ["", f"Start-up: `keyfill complete` of a {start['frames']}-frame human BVH, keys every 15, a new "
                      f"process, median wall seconds of {start['repeat']}: "
                  + ", ".join(f"{m} {num(v, 3)} s" for m, v in start["seconds"].items()) + "."]
    return lines
