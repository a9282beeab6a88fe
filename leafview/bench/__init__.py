"""``leafview bench``: one module per benchmark table, each with ``run(quick, ctx) -> dict`` and
``format_table(res) -> str`` (:mod:`.core`, :mod:`.scene`, :mod:`.export`, :mod:`.shapes`,
:mod:`.dataset`); the measurements two tables share (:mod:`.instancing`: parameters against baked meshes;
:mod:`.latency`: the viewer's edit latency); and one timing helper for all (:mod:`.timing`). The
command that runs them is :mod:`leafview.cli.bench`.

The constants below are shared by the tables so that their figures stay comparable.
"""

__all__ = ["PAPER_LEAVES_PER_S", "THUMB_SIZE", "THUMB_GRID"]

PAPER_LEAVES_PER_S = 550.0  # Garg & Leow 2011: ~550 leaf instances/s on a quad-core laptop
THUMB_SIZE = (128, 128)     # thumbnails: pixels ...
THUMB_GRID = (32, 64)       # ... and (u, v) samples
