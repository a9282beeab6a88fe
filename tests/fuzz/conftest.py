"""The fuzz tests' Hypothesis profile and their example count.

``LEAFVIEW_FUZZ_PROFILE`` selects the profile (``ci``, the default: derandomized, a fixed budget
per property; ``long``: random seeds and the long budgets; ``dev``: a twentieth of ci). The
number of examples each property ran is printed at the end of the session, and written as JSON
to ``$LEAFVIEW_FUZZ_STATS`` when that is set (the long run's log uses it).
"""

from __future__ import annotations

import json
import os
import time

import pytest
from hypothesis import settings
from support.fuzzing import BUDGETS, COUNTS, PROFILE

settings.load_profile(PROFILE)
_STARTED = time.time()


def pytest_terminal_summary(terminalreporter: pytest.TerminalReporter) -> None:
    if not COUNTS:
        return
    total = sum(COUNTS.values())
    seconds = time.time() - _STARTED
    terminalreporter.write_sep("-", f"leafview fuzz ({PROFILE} profile): {total:,} examples in {seconds:.0f} s")
    for name, n in sorted(COUNTS.items()):
        terminalreporter.write_line(f"  {name:28s} {n:>10,}")
    path = os.environ.get("LEAFVIEW_FUZZ_STATS")
    if path:
        with open(path, "w", encoding="utf-8") as fh:
            json.dump({"profile": PROFILE, "total": total, "seconds": round(seconds, 1), "examples": dict(COUNTS),
                       "budgets": {k: {"ci": v[0], "long": v[1]} for k, v in BUDGETS.items()}}, fh, indent=1)
