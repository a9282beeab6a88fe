"""``leafview presets``: the built-in presets, one a line (name and file)."""

from __future__ import annotations

import argparse

from leafview.cli.args import EXIT_OK
from leafview.resources import builtin_presets

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """``leafview presets`` takes no options."""


def run(args: argparse.Namespace) -> int:
    """Print every built-in preset's name and path."""
    for name, path in builtin_presets().items():
        print(f"{name:14s} {path}")
    return EXIT_OK
