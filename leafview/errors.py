"""Errors shared by the command-line front ends."""

from __future__ import annotations

__all__ = ["UsageError"]


class UsageError(Exception):
    """Bad command-line input (arguments, paths, files); ``leafview`` reports it with exit code 2
    and writes nothing."""
