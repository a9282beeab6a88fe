"""Where the shaders and assets live: inside the installed wheel (``leafview/shaders``,
``leafview/assets``) or, in a source checkout / editable install, at the repository top level."""

from __future__ import annotations

from functools import cache
from pathlib import Path

__all__ = ["shader_dir", "asset_dir", "preset_dir", "builtin_presets", "resolve_preset"]

_PKG = Path(__file__).resolve().parent


def _find(name: str) -> Path:
    for candidate in (_PKG / name, _PKG.parent / name):
        if candidate.is_dir():
            return candidate
    raise FileNotFoundError(f"leafview data folder '{name}' not found next to {_PKG} "
                            "(a broken install? reinstall leafview)")


@cache
def shader_dir() -> Path:
    return _find("shaders")


@cache
def asset_dir() -> Path:
    return _find("assets")


def preset_dir() -> Path:
    return asset_dir() / "presets"


def builtin_presets() -> dict[str, Path]:
    """Built-in preset names (file stems) and their paths, sorted by name."""
    return {p.stem: p for p in sorted(preset_dir().glob("*.toml"))}


def resolve_preset(spec: str) -> Path:
    """A preset given as a path, or as the name of a built-in preset (``ovate``)."""
    path = Path(spec)
    if path.exists() or path.suffix:
        return path
    presets = builtin_presets()
    if spec in presets:
        return presets[spec]
    return path  # let the loader report "no such file" with the name the user typed
