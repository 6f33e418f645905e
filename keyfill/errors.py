"""The errors keyfill raises.

Every error keyfill expects (bad files, bad options, infeasible edits, broken
model files) is a :class:`KeyfillError`. Its message is one line that makes
sense on its own; the CLI prints it as ``keyfill: error: <message>`` and exits
with :attr:`KeyfillError.exit_code`. Anything else is a bug and shows a
traceback only with ``--debug``.

Errors about an argument name it as the library does (``batch_size must be at
least 1``) and list it in :attr:`KeyfillError.params`, so that a Python caller
reads the parameter it passed; the CLI writes each listed parameter as the
command-line flag that gives it (``--batch-size must be at least 1``, see
:func:`keyfill.cli.common.flag_words`) where the message first names it, as a
whole word: a message names each listed parameter before any other use of the
same word (``frames 30:40 selects no frame of walk (frames 0-23)``). Errors
built from other errors keep their ``params``.
"""

from __future__ import annotations


class KeyfillError(Exception):
    """Base of all expected errors. ``exit_code`` 1: the work failed.

    ``params``: the names of the function parameters the message names (e.g. ``("key_every",)``), which the
    CLI rewrites as its flags; empty when the message names none.
    """

    exit_code = 1

    def __init__(self, message: str = "", *, params: str | tuple[str, ...] = ()):
        super().__init__(message)
        self.params = (params,) if isinstance(params, str) else tuple(params)


class UsageError(KeyfillError):
    """Options that cannot work together or with this input (exit code 2)."""

    exit_code = 2


class NoSuchFile(UsageError):
    """A path the caller names that is no file, or not the kind needed (exit code 2, as every usage error: in
    every command a missing path is a usage error, found before any work). ``path`` leads the message."""

    def __init__(self, path: object, what: str = "no such file", *, params: str | tuple[str, ...] = ()):
        super().__init__(f"{path}: {what}", params=params)
        self.path = path
        self.line = None


class OutputError(KeyfillError):
    """An output that cannot be written: a read-only folder, a full disk, a file-size limit (exit code 1).
    ``path`` is the output's own name, never the temporary file keyfill wrote first; it leads the message."""

    def __init__(self, path: object, reason: str, *, params: str | tuple[str, ...] = ()):
        super().__init__(f"{path}: cannot write the output ({reason})", params=params)
        self.path = path
        self.line = None


class FormatError(KeyfillError):
    """A file that cannot be read as what it claims to be.

    ``path`` and ``line`` (1-based) are put in front of the message when known.
    """

    def __init__(self, message: str, path: object = None, line: int | None = None, *,
                 params: str | tuple[str, ...] = ()):
        where = ""
        if path is not None:
            where = f"{path}"
            if line is not None:
                where += f":{line}"
            where += ": "
        super().__init__(where + message, params=params)
        self.path = path
        self.line = line


class DataError(KeyfillError):
    """Valid files whose content cannot be used for the requested work."""


class ModelError(KeyfillError):
    """A model file that is not a keyfill model, is damaged, or does not fit the input."""


class InfeasibleError(KeyfillError):
    """An edit or search whose constraints cannot all be met."""


class BatchFailed(KeyfillError):
    """Some inputs of a batch command failed. Each was reported on its own line already, so the CLI
    prints nothing more for this error (``reported``) and exits with 1."""

    reported = True
