"""The ``twolevel`` command (and ``python -m twolevel``): SIGINT, SIGTERM and SIGHUP are handled
(:mod:`twolevel.interruption`) before anything else is imported, so an interruption during the
imports of the command line is reported in one line, never as a traceback, and the process exits
with the shell's code for the signal (130 for Ctrl-C)."""

from __future__ import annotations

import sys

from twolevel import interruption


def main() -> None:
    """Console-script entry point: install the signal handling, import the command line, run it."""
    interruption.install()
    try:
        with interruption.deferred():  # importing typer, rich and twolevel's command line
            from twolevel.cli import main as cli_main
        interruption.checkpoint()
    except KeyboardInterrupt as exc:
        signum = getattr(exc, "signum", None)
        sys.stderr.write(f"twolevel: {interruption.describe(signum)}\n")
        sys.exit(interruption.exit_code(signum))
    cli_main()


if __name__ == "__main__":
    main()
