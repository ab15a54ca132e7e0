"""One module per ``stablemarks`` sub-command.

Each module defines ``NAME`` (the sub-command), ``HELP`` (one line), ``add_arguments(parser)`` and
``run(args) -> int``. :mod:`stablemarks.cli` discovers them, so adding a command means adding a file.
Commands parse, call the library, and report; they hold no method logic.
"""
