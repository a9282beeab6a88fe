"""Run the formats' own validators on exported files (used by the tests; handy by hand).

* glTF: the Khronos glTF-Validator (npm package ``gltf-validator``, pinned in
  ``tools/gltf_validator/package.json``) through ``tools/gltf_validator/validate.mjs``, which
  calls ``validateBytes`` and prints the JSON report. Install it once with
  ``npm ci --prefix tools/gltf_validator`` (``.ci/run`` does).
* USD: every registered ``UsdValidation`` validator on the stage, plus
  ``UsdGeom.Mesh.ValidateTopology`` on every mesh.

``python -m support.validate FILE...`` prints a summary per file and exits 1 if any
file has errors.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

_CHECKOUT = Path(__file__).resolve().parents[2]   # the repository root in a source checkout

__all__ = ["ValidatorMissing", "gltf_report", "gltf_validator_script", "main", "usd_errors"]


class ValidatorMissing(RuntimeError):
    """Node.js or the gltf-validator package is not installed (the message says how to)."""


def gltf_validator_script() -> tuple[str, Path]:
    """(node executable, validate.mjs path); raises :class:`ValidatorMissing`."""
    script = _CHECKOUT / "tools" / "gltf_validator" / "validate.mjs"
    node = shutil.which("node")
    if node is None:
        raise ValidatorMissing("node (Node.js) is not on PATH: apt-get install nodejs npm")
    if not script.is_file():
        raise ValidatorMissing(f"{script} not found (the glTF validator runs from a source checkout)")
    if not (script.parent / "node_modules" / "gltf-validator").is_dir():
        raise ValidatorMissing(f"gltf-validator is not installed: npm ci --prefix {script.parent}")
    return node, script


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
