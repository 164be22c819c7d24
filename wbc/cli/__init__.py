"""The ``wbc`` command."""

from wbc.cli.main import main

__all__ = ["main"]
