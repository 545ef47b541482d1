"""Command line: argument parsing, calls into the library, printing. Nothing else lives here."""

from mjcodesign.cli.main import main

__all__ = ["main"]
