"""The documented long run of the fuzz harness: the parse-level properties of tests/fuzz under the
``long`` Hypothesis profile, in rounds, until a number of examples (default 10⁶) or a deadline.

Each round runs ``pytest tests/fuzz/test_fuzz_parse.py`` with ``LEAFVIEW_FUZZ_PROFILE=long`` (random
seeds, the long budgets scaled by ``--scale``) in ``--jobs`` processes, each on its share of the
properties, and adds up the examples they report (``LEAFVIEW_FUZZ_STATS``). A property that fails
stops at its first failure in that round (Hypothesis reports the shrunk example) and runs again,
with new seeds, in the next round. The log gets one line per round (examples per property, the
rate, the failures with their first error line) and a summary at the end::

    python tools/fuzz_long.py --log /tmp/fuzz_long.log                     # 10⁶ examples
    python tools/fuzz_long.py --log /tmp/fuzz_long.log --until 21:45 --target 1000000
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
# the parse-level properties in two shares of about equal time (random bytes alone are most of
# the examples: a few milliseconds each; the structured properties take 10-40 ms an example)
SHARES = [["test_random_bytes"],
          ["test_compact_loads", "test_seed_mutants", "test_schema_instances", "test_preset_files", "test_compact_files",
           "test_leaf_set_files", "test_scene_files", "test_lobed_files", "test_landmark_files", "test_dict_parsers"]]


def _now() -> str:
    return dt.datetime.now(dt.UTC).strftime("%Y-%m-%dT%H:%M:%SZ")


def _deadline(text: str | None) -> float:
    if not text:
        return float("inf")
    hour, minute = (int(x) for x in text.split(":"))
    now = dt.datetime.now(dt.UTC)
    when = now.replace(hour=hour, minute=minute, second=0, microsecond=0)
    if when < now:
        when += dt.timedelta(days=1)
    return when.timestamp()


def _round(jobs: int, scale: float, folder: Path, index: int) -> tuple[Counter[str], list[str], float]:
    shares = SHARES if jobs > 1 else [[t for s in SHARES for t in s]]
    procs = []
    for i, share in enumerate(shares):
        stats = folder / f"round{index}-{i}.json"
        env = {**os.environ, "LEAFVIEW_FUZZ_PROFILE": "long", "LEAFVIEW_FUZZ_LONG_SCALE": str(scale),
               "LEAFVIEW_FUZZ_STATS": str(stats)}
        cmd = [sys.executable, "-m", "pytest", "tests/fuzz/test_fuzz_parse.py", "-q", "-p", "no:cacheprovider",
               "--no-header", "-W", "ignore::RuntimeWarning", "-k", " or ".join(share)]
        out = open(folder / f"round{index}-{i}.log", "w", encoding="utf-8")   # closed after the wait below
        procs.append((subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=out, stderr=subprocess.STDOUT), stats, out))
    started = time.time()
    counts: Counter[str] = Counter()
    failures: list[str] = []
    for proc, stats, out in procs:
        proc.wait()
        out.close()
        if stats.exists():
            counts.update(json.loads(stats.read_text(encoding="utf-8"))["examples"])
        text = Path(out.name).read_text(encoding="utf-8", errors="replace")
        for m in re.finditer(r"^FAILED (\S+) - (.*)$", text, re.MULTILINE):
            failures.append(f"{m.group(1).split('::')[-1]}: {m.group(2)[:300]}")
        seen = set()   # the properties' own problem lines (the first of each kind)
        for m in re.finditer(r"^E\s{3,}((?:a |an |the |hang|accepted|exit |[A-Za-z]+Error: ).{0,240})", text, re.MULTILINE):
            key = m.group(1)[:40]
            if key not in seen and len(seen) < 8:
                seen.add(key)
                failures.append(f"  problem: {m.group(1)}")
        if proc.returncode not in (0, 1):
            failures.append(f"pytest exited {proc.returncode}: {text[-500:]}")
    return counts, failures, time.time() - started


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--log", default="/tmp/fuzz_long.log", help="append the log here")
    parser.add_argument("--target", type=int, default=1_000_000, help="stop after this many examples")
    parser.add_argument("--until", metavar="HH:MM", help="UTC time after which no new round starts")
    parser.add_argument("--jobs", type=int, default=2, help="processes a round (1 or 2)")
    parser.add_argument("--scale", type=float, default=1.0, help="multiply the long budgets (one round)")
    args = parser.parse_args(argv)
    deadline = _deadline(args.until)
    folder = Path(tempfile.mkdtemp(prefix="leafview-fuzz-long-"))
    total: Counter[str] = Counter()
    failing: Counter[str] = Counter()
    started = time.time()

    def log(line: str) -> None:
        with open(args.log, "a", encoding="utf-8") as fh:
            fh.write(line + "\n")

    log(f"{_now()} start: LEAFVIEW_FUZZ_PROFILE=long, parse-level properties, target {args.target:,} examples, "
        f"{args.jobs} processes, scale {args.scale}, until {args.until or 'done'}; rounds in {folder}")
    index = 0
    while sum(total.values()) < args.target and time.time() < deadline:
        counts, failures, seconds = _round(args.jobs, args.scale, folder, index)
        total.update(counts)
        for f in failures:
            if not f.startswith("  problem"):
                failing[f.split(":")[0]] += 1
        n = sum(counts.values())
        log(f"{_now()} round {index}: {n:,} examples in {seconds:.0f} s ({n / max(seconds, 1):,.0f}/s); "
            f"total {sum(total.values()):,}; " + ", ".join(f"{k} {v:,}" for k, v in sorted(counts.items())))
        for f in failures:
            log(f"    FAILED {f}")
        index += 1
        if n == 0:
            log("    no examples ran: stopping")
            break
    seconds = time.time() - started
    log(f"{_now()} end: {sum(total.values()):,} examples in {seconds / 60:.1f} min over {index} rounds "
        f"({sum(total.values()) / max(seconds, 1):,.0f}/s); per property: "
        + ", ".join(f"{k} {v:,}" for k, v in sorted(total.items())))
    log(f"{_now()} failing properties (rounds with a failure): "
        + (", ".join(f"{k} {v}" for k, v in sorted(failing.items())) or "none"))
    return 0 if not failing else 1


if __name__ == "__main__":
    sys.exit(main())
