"""The hostile-input rerun of issue 14 (tools/hostile_cases.py) holds the promise: 0 tracebacks,
0 hangs, 0 wrong outcomes (files outside the output folder, temporary or partial files left,
exit 0 with a corrupt, non-finite or blank file, another file's content in a message).

It runs about 250 cases as subprocesses, two at a time, with time-outs: several minutes.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
TOOL = ROOT / "tools" / "hostile_cases.py"


@pytest.mark.slow
def test_hostile_rerun(tmp_path: Path) -> None:
    report_path = tmp_path / "hostile.json"
    done = subprocess.run([sys.executable, str(TOOL), "--json", str(report_path), "--jobs", "2"],
                          capture_output=True, text=True, timeout=1800)
    assert done.returncode == 0, done.stdout[-4000:] + done.stderr[-4000:]
    report = json.loads(report_path.read_text(encoding="utf-8"))
    counts = report["counts"]
    assert counts["clean refusal"] + counts["success"] > 0, done.stdout[-2000:]
    broken = {k: counts[k] for k in ("traceback", "hang", "wrong outcome") if counts[k]}
    assert not broken, f"the promise is broken in {broken} cases:\n" + done.stdout[-12000:]
