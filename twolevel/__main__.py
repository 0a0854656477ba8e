"""``python -m twolevel`` is the ``twolevel`` command."""

from twolevel.cli import main

main()
