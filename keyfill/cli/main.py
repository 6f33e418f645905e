"""The ``keyfill`` command group: global options, lazy subcommands, error reporting."""

from __future__ import annotations

import errno
import importlib
import importlib.util
import os
import signal
import sys

from keyfill.cli import signals

signals.catch_early()  # first, so that a signal while the rest loads is noted, not a traceback (signals.py)

# Set before numpy is first imported. The commands do single-threaded numpy
# work on small matrices (torch keeps its own threads); an OpenBLAS thread pool
# only adds start-up time and, on a 2-core machine, competes with the work:
# `keyfill complete` on 10,000 frames takes 0.79 instead of 0.91 s with it.
# A value the user has set wins.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import click

from keyfill import __version__
from keyfill.errors import KeyfillError

#: modules of the optional extras (pyproject.toml) -> the extra that installs them
EXTRAS = {"torch": "train", "pybullet": "sim", "dask": "dask", "distributed": "dask", "onnx": "onnx",
          "onnxscript": "onnx"}

#: subcommand -> "module:attribute". Modules are imported only when used, so
#: ``keyfill info`` never pays for torch or pybullet.
COMMANDS = {
    "info": "keyfill.cli.info:info",
    "convert": "keyfill.cli.convert:convert",
    "retarget": "keyfill.cli.retarget:retarget",
    "complete": "keyfill.cli.complete:complete",
    "simulate": "keyfill.cli.simulate:simulate",
    "train": "keyfill.cli.train:train",
    "evaluate": "keyfill.cli.evaluate:evaluate",
    "edit-tangents": "keyfill.cli.edit_tangents:edit_tangents",
    "pose": "keyfill.cli.pose:pose",
    "plot": "keyfill.cli.plot:plot",
    "preview": "keyfill.cli.preview:preview",
    "export": "keyfill.cli.export:export",
    "library": "keyfill.cli.library:library",
}


class SuggestingGroup(click.Group):
    """A group whose unknown command suggests the close names of :meth:`list_commands` (click suggests only
    among the commands added to a group; ours are found on first use)."""

    def resolve_command(self, ctx, args):
        try:
            return super().resolve_command(ctx, args)
        except click.UsageError as e:
            from keyfill.cli.common import did_you_mean

            hint = did_you_mean(click.utils.make_str(args[0]), self.list_commands(ctx))
            if not hint or not e.message.startswith("No such command"):
                raise
            raise click.UsageError(e.message + hint, ctx) from None


class LazyGroup(SuggestingGroup):
    """A click group whose subcommands live in modules imported on first use."""

    def __init__(self, *args, lazy: dict[str, str] | None = None, **kwargs):
        super().__init__(*args, **kwargs)
        self.lazy = dict(lazy or {})

    def _available(self) -> list[str]:
        return [n for n, target in self.lazy.items() if importlib.util.find_spec(target.split(":")[0]) is not None]

    def list_commands(self, ctx):
        return sorted(set(super().list_commands(ctx)) | set(self._available()))

    def invoke(self, ctx):
        try:
            return super().invoke(ctx)
        except KeyboardInterrupt as e:  # as click's Abort, which prints no blank line before ours, "interrupted"
            raise click.exceptions.Abort() from e

    def get_command(self, ctx, name):
        from keyfill.cli.common import with_global_options

        if name in self.lazy and name in self._available():
            module, attr = self.lazy[name].split(":")
            return with_global_options(getattr(importlib.import_module(module), attr))
        return super().get_command(ctx, name)


@click.group(
    cls=LazyGroup,
    lazy=COMMANDS,
    context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100},
)
@click.option("-q", "--quiet", count=True, help="Print less (no progress bars).")
@click.option("-v", "--verbose", count=True, help="Print more.")
@click.option("--debug", is_flag=True, help="Show Python tracebacks for errors.")
@click.version_option(__version__, prog_name="keyfill")
@click.pass_context
def cli(ctx, quiet, verbose, debug):
    """keyfill fills in the frames between keyframes of character animation.

    It reads and writes BVH, USD and glTF files (and reads FBX) and offers spline baselines,
    learned in-betweening (ARNN, transformer, generative-tweening GAN; many
    files at once, ONNX export; the human models on any humanoid rig through
    retargeting, feet locked on request), a physics-based hopping-lamp dataset
    and tangent-space editing of Bezier curves, all on one Motion data type.

    \b
    Examples:
      keyfill info walk.bvh
      keyfill convert walk.bvh walk.usda
      keyfill complete keys.usda -o filled.bvh --method cubic

    \b
    Exit codes: 0 success, 1 the work failed, 2 usage error,
    128 + N signal N (130 Ctrl-C, 143 SIGTERM, 129 SIGHUP).
    Interrupted at any moment, a command removes its temporary files and
    leaves each output whole or absent; an interrupted batch records what it
    finished and the same command again does the rest (docs/robustness.md).
    """
    ctx.ensure_object(dict)
    ctx.obj["verbosity"] = verbose - quiet
    ctx.obj["debug"] = debug


#: set by :func:`main` when the command line asks for ``--json``: errors are then also a JSON object on stdout
_json_errors = False


def _error(message: str, exit_code: int = 1, file=None, line: int | None = None) -> None:
    """The one ``keyfill: error:`` line on stderr; with ``--json`` also ``{"error": {...}}`` on stdout
    (docs/json.md)."""
    message = " ".join(str(message).split())
    click.echo(f"keyfill: error: {message}", err=True)
    if _json_errors:
        import json

        error = {"message": message, "file": None if file is None else str(file), "line": line,
                 "exit_code": exit_code}
        try:
            click.echo(json.dumps({"error": error}, indent=2, sort_keys=True))
        except OSError:  # standard output is what failed (a full disk): the line on stderr says so
            _drop_stdout()


def _drop_stdout() -> None:
    """Point standard output at the null device, so that Python's flush at exit does not fail a second time."""
    try:
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, sys.stdout.fileno())
        os.close(null)
    except (OSError, ValueError, AttributeError):  # no real file behind sys.stdout (a test's capture)
        pass


#: errors of a write that the disk refused (full, over a quota or the file-size limit, failing)
_DISK_FULL = {errno.ENOSPC, errno.EFBIG, errno.EDQUOT, errno.EIO}


def _interrupted(error: BaseException | None) -> int:
    """The line and exit code (128 + the signal) of an interrupted command; ``error`` the interrupt raised, if
    any (its ``detail`` completes the line)."""
    signum = getattr(error, "signum", None) or (signals.received[0] if signals.received else signal.SIGINT)
    word = "interrupted" if signum == signal.SIGINT else "terminated"
    detail = getattr(error, "detail", None)
    _error(f"{word}: {detail}" if detail else word, 128 + signum)
    return 128 + signum


def _progress_bar(description: str, total: int, unit: str):
    """The CLI's progress listener: a tqdm bar on a terminal, shown once a task has taken 2 s (tqdm is imported
    only then: :class:`~keyfill.cli.common.DelayedBar`)."""
    from keyfill.cli.common import DelayedBar, progress

    return DelayedBar(lambda done: progress(total=total, initial=done, desc=description, unit=unit.strip() or "it",
                                            unit_scale=unit.strip() == "B", leave=False), delay=2.0)


def _note(message: str) -> None:
    """The CLI's listener of :func:`keyfill.progress.note`: one line on stderr, silent with ``-q``."""
    from keyfill.cli.common import say

    say(f"keyfill: note: {' '.join(message.split())}")


def main(argv: list[str] | None = None) -> int:
    """Run the CLI; returns the exit code (also used by ``python -m keyfill``)."""
    global _json_errors
    args = list(sys.argv[1:] if argv is None else argv)
    # looked for before parsing, so that errors of the parsing itself obey them (before or after the subcommand)
    options = args[:args.index("--")] if "--" in args else args
    debug = "--debug" in options
    _json_errors = "--json" in options
    from keyfill import progress

    progress.listen(_progress_bar)
    progress.listen_notes(_note)
    try:
        with signals.catching():
            code = _main(args, debug)
            late = signals.ending()  # a signal that something swallowed, or that came after the work
            if late is not None and code not in {128 + s for s in signals.SIGNALS}:
                code = _interrupted(signals.Interrupted(late))
            return code
    finally:
        progress.listen(None)
        progress.listen_notes(None)


def _main(args: list[str], debug: bool) -> int:
    try:
        signals.check()
        cli.main(args=args, prog_name="keyfill", standalone_mode=False)
        return 0
    except click.exceptions.Exit as e:
        return e.exit_code
    except click.exceptions.Abort as e:  # click turns Ctrl-C (and our other signals) into Abort: its cause
        return _interrupted(e.__cause__)
    except click.UsageError as e:
        if debug:
            raise
        if type(e).__name__ == "NoArgsIsHelpError" and e.ctx is not None:
            # bare `keyfill` (or a group without a command): the help, as it is written, not one squashed line
            click.echo(e.ctx.get_help())
            return 2
        cmd = e.ctx.command_path if e.ctx is not None else "keyfill"
        _error(f"{e.format_message()} (see '{cmd} --help')", 2)
        return 2
    except KeyfillError as e:
        if debug:
            raise
        if not getattr(e, "reported", False):
            from keyfill.cli.common import flag_words

            _error(flag_words(str(e), getattr(e, "params", ())), e.exit_code, getattr(e, "path", None),
                   getattr(e, "line", None))
        return e.exit_code
    except KeyboardInterrupt as e:
        return _interrupted(e)
    except BrokenPipeError:
        return 1
    except ModuleNotFoundError as e:  # an extra the base install leaves out (pyproject.toml)
        if debug:
            raise
        extra = EXTRAS.get((e.name or "").split(".")[0])
        if extra is None:
            _error(f"internal error: {type(e).__name__}: {e} (run with --debug for the traceback)")
            return 1
        _error(f"this needs {e.name.split('.')[0]}, which the base install leaves out: pip install 'keyfill[{extra}]'")
        return 1
    except Exception as e:  # a bug: say so in one line unless --debug
        if debug:
            raise
        if isinstance(e, OSError) and e.filename is None and e.errno in _DISK_FULL:
            # a write to standard output (files are written through atomic_output, which names them)
            _drop_stdout()
            _error(f"cannot write standard output ({e.strerror})")
            return 1
        if isinstance(e, OSError) and e.errno == errno.ENAMETOOLONG and e.filename is not None:
            # a path given (or made from one given) that no file system holds: a usage error, like a missing path
            _error(f"{e.filename}: {e.strerror.lower()}", 2)
            return 2
        _error(f"internal error: {type(e).__name__}: {e} (run with --debug for the traceback)")
        return 1


def entry_point() -> None:
    """Console-script entry point."""
    sys.exit(main())
