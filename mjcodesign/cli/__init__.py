"""Command line: argument parsing, calls into the library, printing. Nothing else lives here.

The entry point is :func:`mjcodesign.cli.main.main` (the ``mjcodesign`` script, ``python -m
mjcodesign.cli`` or ``python -m mjcodesign.cli.main``). This package imports none of its modules, so
that ``python -m mjcodesign.cli.main`` does not find itself already imported (runpy would then warn on
stderr, a second line after a refusal's one).
"""

__all__ = []  # the entry point is mjcodesign.cli.main.main
