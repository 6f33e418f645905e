"""The ``keyfill`` command line: one thin module per subcommand (see ``main.py``).

Commands parse options, import heavy backends inside the function, call one
library function and report. They never print tracebacks (``--debug`` does).
"""
