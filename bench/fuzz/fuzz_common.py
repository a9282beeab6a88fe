"""The shared part of the coverage-guided fuzz targets in this folder (see README.md).

A target module calls :func:`fuzz` with a name, the file suffixes it reads, its seed files and a
``load(path)`` function. Each input is written to a file with one of those suffixes (the first
byte of the input picks which) and loaded; a :class:`~leafview.errors.LeafviewError` with a
one-line message naming the file is the expected refusal, anything else is a crash.

With atheris installed (``pip install atheris``) the loop is libFuzzer's, guided by coverage of
the leafview modules the target imports inside :func:`instrumented`; libFuzzer's flags pass
through (``-runs=N``, ``-max_total_time=S``, ``-jobs=N``, a corpus folder). Without atheris a
plain random mutation loop runs instead (``--runs N``, ``--seconds S``), with the same check.
Crashing inputs are saved under ``$LEAFVIEW_FUZZ_ARTIFACTS`` (default
``/tmp/leafview-fuzz-artifacts/<name>/``); the seed corpus is copied to
``$LEAFVIEW_FUZZ_CORPUS`` (default ``/tmp/leafview-fuzz-corpus/<name>/``).
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import os
import random
import signal
import sys
import tempfile
import time
import traceback
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

try:
    import atheris
except ImportError:   # the plain random loop below takes over
    atheris = None

ROOT = Path(__file__).resolve().parents[2]
ASSETS = ROOT / "assets"
TIMEOUT_S = 10        # one input; a parse takes milliseconds
MAX_MESSAGE = 1000    # characters of a refusal's message


@contextlib.contextmanager
def instrumented() -> Iterator[None]:
    """Import the code under test inside this block: atheris instruments it for coverage."""
    if atheris is None:
        yield
    else:
        with atheris.instrument_imports(include=["leafview"]):
            yield


class Crash(Exception):
    """An input broke the promise."""


def check(load: Callable[[Path], Any], path: Path, error_type: type[BaseException]) -> None:
    """Load ``path``; raise :class:`Crash` for anything but a value or a clean refusal."""
    try:
        load(path)
    except error_type as exc:
        message = str(exc)
        if "\n" in message.strip() or len(message) > MAX_MESSAGE or path.name not in message:
            raise Crash(f"a refusal that is not one short line naming {path.name}: {message[:400]!r}") from None


def files(*patterns: str) -> list[bytes]:
    """The bytes of the repository files matching ``patterns`` (seeds)."""
    return [p.read_bytes() for pattern in patterns for p in sorted(ROOT.glob(pattern)) if p.is_file()]


def _mutate(data: bytes, rng: random.Random, seeds: list[bytes]) -> bytes:
    """One to four random edits: flip, insert, delete, duplicate a chunk, splice with a seed,
    truncate, or insert a token that parsers mishandle."""
    tokens = [b"[" * 2000, b"{", b"9" * 5000, b"1e400", b"nan", b"\xff", b"\x00", b'"', b"=", b"]]", b"\\u0000",
              b"-0", b"0x10", b"[[species]]", b'"leafview": 1', b"\n[", b"1_0"]
    out = bytearray(data)
    for _ in range(rng.randint(1, 4)):
        at = rng.randint(0, len(out))
        op = rng.randrange(7)
        if op == 0 and out:
            out[min(at, len(out) - 1)] ^= rng.randint(1, 255)
        elif op == 1:
            out[at:at] = rng.choice(tokens)
        elif op == 2:
            del out[at:at + rng.randint(1, 16)]
        elif op == 3:
            out[at:at] = out[at:at + rng.randint(1, 64)] * rng.randint(1, 8)
        elif op == 4:
            other = rng.choice(seeds)
            cut = rng.randint(0, len(other))
            out = out[:at] + other[cut:]
        elif op == 5:
            del out[at:]
        else:
            out[at:at] = bytes(rng.randint(0, 255) for _ in range(rng.randint(1, 8)))
    return bytes(out)


def _save(folder: Path, data: bytes, text: str) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"crash-{hashlib.sha1(data).hexdigest()[:16]}"
    path.write_bytes(data)
    path.with_suffix(".txt").write_text(text, encoding="utf-8")
    return path


def _alarm(signum: int, frame: Any) -> None:
    raise TimeoutError(f"no answer in {TIMEOUT_S} s")


def fuzz(name: str, suffixes: Sequence[str], seeds: Sequence[bytes], load: Callable[[Path], Any],
         error_type: type[BaseException], prepare: Callable[[Path], None] | None = None) -> None:
    """Run the target ``name`` (the command line decides how long; see the module docstring).
    ``prepare(folder)`` puts what inputs may refer to beside them."""
    work = Path(tempfile.mkdtemp(prefix=f"leafview-fuzz-{name}-"))
    if prepare:
        prepare(work)
    artifacts = Path(os.environ.get("LEAFVIEW_FUZZ_ARTIFACTS", f"/tmp/leafview-fuzz-artifacts/{name}"))
    corpus = Path(os.environ.get("LEAFVIEW_FUZZ_CORPUS", f"/tmp/leafview-fuzz-corpus/{name}"))
    seed_data = list(seeds)
    corpus.mkdir(parents=True, exist_ok=True)
    for data in seed_data:
        (corpus / hashlib.sha1(data).hexdigest()[:16]).write_bytes(bytes([0]) + data)

    def one(data: bytes) -> None:
        suffix = suffixes[data[0] % len(suffixes)] if data else suffixes[0]
        path = work / f"input{suffix}"
        path.write_bytes(data[1:])
        signal.signal(signal.SIGALRM, _alarm)
        signal.alarm(TIMEOUT_S)
        try:
            check(load, path, error_type)
        finally:
            signal.alarm(0)

    if atheris is not None:
        args = list(sys.argv)
        if not any(a.startswith("-artifact_prefix=") for a in args):
            artifacts.mkdir(parents=True, exist_ok=True)
            args.append(f"-artifact_prefix={artifacts}/")
        if not any(a.startswith("-timeout=") for a in args):
            args.append(f"-timeout={TIMEOUT_S}")
        if not any(not a.startswith("-") for a in args[1:]):
            args.append(str(corpus))
        atheris.Setup(args, one)
        atheris.Fuzz()
        return
    _plain_loop(name, one, seed_data, artifacts)


def _plain_loop(name: str, one: Callable[[bytes], None], seeds: list[bytes], artifacts: Path) -> None:
    parser = argparse.ArgumentParser(description=f"random mutation fuzzing of the {name} loader (no atheris)")
    parser.add_argument("--runs", type=int, default=0, help="inputs to try (0: until --seconds or Ctrl-C)")
    parser.add_argument("--seconds", type=float, default=0.0, help="stop after this long")
    parser.add_argument("--seed", type=int, default=None, help="random seed (default: from the clock)")
    args, _ = parser.parse_known_args()
    seed = args.seed if args.seed is not None else time.time_ns() % 2**32
    rng = random.Random(seed)
    started, runs = time.monotonic(), 0
    print(f"{name}: plain random loop (atheris not installed), seed {seed}", flush=True)
    while True:
        if args.runs and runs >= args.runs or args.seconds and time.monotonic() - started > args.seconds:
            break
        base = rng.choice(seeds) if seeds and rng.random() < 0.9 else bytes(rng.randint(0, 255) for _ in range(64))
        data = bytes([rng.randrange(256)]) + _mutate(base, rng, seeds or [b""])
        try:
            one(data)
        except Exception:   # the finding: save it, say where, stop
            saved = _save(artifacts, data, traceback.format_exc())
            print(f"{name}: CRASH after {runs} inputs; input saved to {saved}\n{traceback.format_exc()}", flush=True)
            sys.exit(1)
        runs += 1
        if runs % 10_000 == 0:
            print(f"{name}: {runs:,} inputs, {runs / (time.monotonic() - started):,.0f}/s", flush=True)
    print(f"{name}: {runs:,} inputs in {time.monotonic() - started:.0f} s, no crash", flush=True)
