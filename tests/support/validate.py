"""Run the formats' own validators on exported files (used by the tests; handy by hand).

* glTF: the Khronos glTF-Validator (npm package ``gltf-validator``, pinned in
  ``tools/gltf_validator/package-lock.json``) through ``tools/gltf_validator/validate.mjs``, which
  calls ``validateBytes`` and prints the JSON report. :func:`ensure_gltf_validator` installs the
  pinned package with ``npm ci`` into ``tools/gltf_validator/node_modules`` (ignored by git) when
  it is missing or another version; the tests' ``gltf_validator`` fixture and ``main`` call it.
  It needs Node.js and npm (``apt-get install nodejs npm``) and, once, the npm registry.
* USD: every registered ``UsdValidation`` validator on the stage, plus
  ``UsdGeom.Mesh.ValidateTopology`` on every mesh.

``python -m support.validate FILE...`` prints a summary per file and exits 1 if any
file has errors.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

try:
    import fcntl
except ImportError:  # pragma: no cover - not POSIX: concurrent installs are not serialised
    fcntl = None

_CHECKOUT = Path(__file__).resolve().parents[2]   # the repository root in a source checkout
VALIDATOR_DIR = _CHECKOUT / "tools" / "gltf_validator"
PACKAGE = "gltf-validator"
APT_HINT = "sudo apt-get install nodejs npm"
# npm's error codes when the registry cannot be reached
_NETWORK_CODES = ("ENOTFOUND", "EAI_AGAIN", "ECONNREFUSED", "ECONNRESET", "ETIMEDOUT", "ENETUNREACH",
                  "EHOSTUNREACH", "ERR_SOCKET_TIMEOUT", "ENOTCACHED")

__all__ = ["APT_HINT", "VALIDATOR_DIR", "ValidatorMissing", "ensure_gltf_validator", "gltf_report",
           "gltf_validator_script", "main", "usd_errors"]


class ValidatorMissing(RuntimeError):
    """Node.js, npm or the gltf-validator package is missing and cannot be installed (the message
    says what is missing and how to get it)."""


def _pinned_version(folder: Path) -> str:
    """The gltf-validator version that ``package-lock.json`` pins."""
    lock = json.loads((folder / "package-lock.json").read_text(encoding="utf-8"))
    return str(lock["packages"][f"node_modules/{PACKAGE}"]["version"])


def _installed_version(folder: Path) -> str | None:
    manifest = folder / "node_modules" / PACKAGE / "package.json"
    try:
        return str(json.loads(manifest.read_text(encoding="utf-8"))["version"])
    except (OSError, ValueError, KeyError):
        return None


def gltf_validator_script(folder: Path = VALIDATOR_DIR) -> tuple[str, Path]:
    """(node executable, validate.mjs path) of an installed validator; raises
    :class:`ValidatorMissing` (nothing is installed here: see :func:`ensure_gltf_validator`)."""
    script = folder / "validate.mjs"
    if not script.is_file():
        raise ValidatorMissing(f"{script} not found (the glTF validator runs from a source checkout)")
    node = shutil.which("node")
    if node is None:
        raise ValidatorMissing(f"Node.js is not installed (no `node` on PATH); the glTF validator needs "
                               f"node and npm: {APT_HINT}")
    installed, pinned = _installed_version(folder), _pinned_version(folder)
    if installed != pinned:
        have = "is not installed" if installed is None else f"{installed} is installed"
        raise ValidatorMissing(f"{PACKAGE} {pinned} (pinned in {folder / 'package-lock.json'}) {have} in "
                               f"{folder / 'node_modules'}: run `npm ci --prefix {folder}` (the tests' gltf_validator "
                               f"fixture does)")
    return node, script


def _npm_failure(folder: Path, returncode: int, output: str) -> str:
    """A message for a failed ``npm ci``: whether the registry was unreachable, and npm's last lines."""
    said = [line for line in output.strip().splitlines()     # without stack frames and object dumps
            if not re.match(r"(npm (error|ERR!))?\s*(at\s|\w+: ['\d]|[{}]|$)", line)]
    tail = "\n".join(said[:8])
    codes = sorted({c for c in _NETWORK_CODES if re.search(rf"\b{c}\b", output)})
    if codes:
        return (f"could not install the Khronos glTF validator: `npm ci --prefix {folder}` could not reach "
                f"the npm registry ({', '.join(codes)}: offline?). Run that command once with network "
                f"access (or point npm at a reachable mirror: `npm config set registry URL`); the tests "
                f"need no network after that. npm said:\n{tail}")
    return (f"could not install the Khronos glTF validator: `npm ci --prefix {folder}` exited with "
            f"{returncode}. npm said:\n{tail}")


def ensure_gltf_validator(folder: Path = VALIDATOR_DIR, *, timeout: float = 600.0) -> tuple[str, Path]:
    """(node, validate.mjs) after making sure the pinned gltf-validator is installed in
    ``folder/node_modules``.

    A missing or different version is installed with ``npm ci`` (npm's cache first, then the
    registry) into a temporary folder beside it, which then replaces ``node_modules`` by renaming:
    an interrupted install leaves no half-written ``node_modules``. A file lock
    (``folder/.install.lock``) serialises concurrent test processes; the second one finds the
    first one's install. Raises :class:`ValidatorMissing` naming what is missing (node, npm, the
    registry) and how to get it."""
    try:
        return gltf_validator_script(folder)
    except ValidatorMissing:
        if shutil.which("node") is None or not (folder / "validate.mjs").is_file():
            raise
    npm = shutil.which("npm")
    if npm is None:
        raise ValidatorMissing(f"npm is not installed (no `npm` on PATH), so the pinned {PACKAGE} cannot be "
                               f"installed into {folder / 'node_modules'}: {APT_HINT}")
    try:
        lock = (folder / ".install.lock").open("a+")     # held, and locked, for the whole install
    except OSError as exc:
        raise ValidatorMissing(f"cannot install {PACKAGE} into {folder}: {exc}") from exc
    with lock:
        if fcntl is not None:
            fcntl.flock(lock, fcntl.LOCK_EX)      # released when the file closes
        try:
            return gltf_validator_script(folder)  # another process installed it meanwhile
        except ValidatorMissing:
            pass
        work = Path(tempfile.mkdtemp(prefix=".install-", dir=folder))
        try:
            for name in ("package.json", "package-lock.json"):
                shutil.copy2(folder / name, work / name)
            # npm's cache first; two retries 2 s and 10 s apart (npm's defaults, 10 s and 60 s, make an
            # offline machine wait 70 s for the message)
            cmd = [npm, "ci", "--prefix", str(work), "--prefer-offline", "--no-audit", "--no-fund",
                   "--loglevel=error", "--fetch-retry-mintimeout=2000", "--fetch-retry-maxtimeout=10000"]
            env = {**os.environ, "npm_config_update_notifier": "false"}
            start = time.perf_counter()
            try:
                proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env=env, check=False)
            except subprocess.TimeoutExpired as exc:
                raise ValidatorMissing(f"could not install the Khronos glTF validator: `npm ci --prefix {folder}` "
                                       f"took more than {timeout:.0f} s (a slow or unreachable npm registry?)"
                                       ) from exc
            if proc.returncode != 0:
                raise ValidatorMissing(_npm_failure(folder, proc.returncode, proc.stdout + proc.stderr))
            if _installed_version(work) != _pinned_version(folder):
                raise ValidatorMissing(f"`npm ci` in {work} did not install {PACKAGE} {_pinned_version(folder)}")
            target = folder / "node_modules"
            if target.exists():
                target.rename(work / "node_modules.old")
            (work / "node_modules").rename(target)
            print(f"installed {PACKAGE} {_pinned_version(folder)} into {target} in "
                  f"{time.perf_counter() - start:.1f} s", file=sys.stderr)
        finally:
            shutil.rmtree(work, ignore_errors=True)
        return gltf_validator_script(folder)


def gltf_report(path: str | Path, timeout: float = 300.0) -> dict[str, Any]:
    """The Khronos glTF-Validator's report of ``path`` (a dict; ``issues.numErrors`` etc.)."""
    node, script = gltf_validator_script()
    proc = subprocess.run([node, str(script), str(path)], capture_output=True, text=True, timeout=timeout,
                          check=False)
    if proc.returncode not in (0, 1):
        raise RuntimeError(f"glTF validator failed on {path}: {proc.stderr.strip()}")
    return json.loads(proc.stdout)


def usd_errors(path: str | Path) -> list[str]:
    """Errors of the USD file: UsdValidation (all registered validators, errors only) and
    UsdGeom.Mesh.ValidateTopology per mesh; an empty list means clean."""
    from pxr import Usd, UsdGeom, UsdValidation

    stage = Usd.Stage.Open(str(path))
    if stage is None:
        return [f"{path}: USD could not open the file"]
    registry = UsdValidation.ValidationRegistry()
    context = UsdValidation.ValidationContext(registry.GetOrLoadAllValidators())
    out = [f"{e.GetName()}: {e.GetMessage()}" for e in context.Validate(stage)
           if e.GetType() == UsdValidation.ValidationErrorType.Error]
    for prim in stage.Traverse():
        if prim.IsA(UsdGeom.Mesh):
            mesh = UsdGeom.Mesh(prim)
            ok, why = UsdGeom.Mesh.ValidateTopology(mesh.GetFaceVertexIndicesAttr().Get(),
                                                    mesh.GetFaceVertexCountsAttr().Get(),
                                                    len(mesh.GetPointsAttr().Get()))
            if not ok:
                out.append(f"{prim.GetPath()}: {why}")
    return out


def main(argv: list[str] | None = None) -> int:
    files = sys.argv[1:] if argv is None else argv
    if any(Path(name).suffix.lower() in (".glb", ".gltf") for name in files):
        ensure_gltf_validator()
    bad = 0
    for name in files:
        suffix = Path(name).suffix.lower()
        if suffix in (".glb", ".gltf"):
            report = gltf_report(name)
            issues = report["issues"]
            print(f"{name}: {issues['numErrors']} errors, {issues['numWarnings']} warnings, "
                  f"{issues['numInfos']} infos, {issues['numHints']} hints "
                  f"(glTF-Validator {report.get('validatorVersion', '?')})")
            seen: dict[tuple[int, str], list[str]] = {}
            for m in issues["messages"]:
                seen.setdefault((m["severity"], m["code"]), []).append(m.get("pointer", ""))
            for (severity, code), where in sorted(seen.items()):
                level = ("error", "warning", "info", "hint")[severity]
                more = f" and {len(where) - 1} more" if len(where) > 1 else ""
                print(f"  {level} {code}: {where[0]}{more}")
            bad += issues["numErrors"] > 0
        elif suffix in (".usda", ".usdc", ".usd"):
            errors = usd_errors(name)
            print(f"{name}: {len(errors)} errors")
            for e in errors:
                print(f"  {e}")
            bad += bool(errors)
        else:
            print(f"{name}: not a glTF or USD file", file=sys.stderr)
            bad += 1
    return 1 if bad else 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
