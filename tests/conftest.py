"""Shared fixtures.

GL tests use the ``gl`` fixture: without an EGL/OpenGL 4.5 context they skip only when
``LEAFVIEW_REQUIRE_GL`` is unset; with it set (as ``.ci/run`` does) they fail. After every GL
test the context must report GL_NO_ERROR.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from support.validate import ValidatorMissing, ensure_gltf_validator

import leafview
from leafview.core.params import LeafParams
from leafview.resources import builtin_presets

ROOT = Path(__file__).resolve().parent.parent
IMAGES = Path(__file__).parent / "images"
FAILURES = Path(__file__).parent / "_failures"
PIXEL_TOL = 3               # llvmpipe varies by up to 3/255 between CPU vendors
MAX_BAD_FRACTION = 0.005    # of the pixels may exceed PIXEL_TOL


def run_prepare(gl, records: np.ndarray) -> np.ndarray:
    """``records`` after the GPU prepare pass (leaf_prepare.comp) filled their derived members."""
    from leafview.gpu.layout import LEAF_BLOCK

    buf = gl.ctx.buffer(records.tobytes())
    try:
        gl.prepare.run(buf, len(records))
        return np.frombuffer(buf.read(), dtype=LEAF_BLOCK.dtype)
    finally:
        buf.release()


def draw_each(target, batches, camera, after=None) -> list[np.ndarray]:
    """Each of ``batches`` (InstancedLeaves, BakedLeaves, ...) drawn alone into ``target`` through
    ``camera`` and read back; ``after(batch)`` runs after each draw (an error check)."""
    images = []
    for batch in batches:
        target.use()
        target.clear()
        batch.set_camera(camera)
        batch.draw()
        if after is not None:
            after(batch)
        images.append(target.read())
    return images


def compare(actual: np.ndarray, reference: np.ndarray) -> tuple[float, int]:
    """(fraction of pixels off by more than PIXEL_TOL, largest difference)."""
    diff = np.abs(actual.astype(np.int16) - reference.astype(np.int16)).max(axis=-1)
    return float(np.mean(diff > PIXEL_TOL)), int(diff.max())


def assert_matches_reference(actual: np.ndarray, stem: str, request: pytest.FixtureRequest) -> None:
    """Compare ``actual`` with ``tests/images/<stem>.png`` (regenerated with ``--regen-images``);
    on failure the actual image and a ×8 diff go to ``tests/_failures``."""
    from leafview.export.images import read_image, write_image

    ref_path = IMAGES / f"{stem}.png"
    if request.config.getoption("--regen-images"):
        write_image(ref_path, actual)
    assert ref_path.exists(), f"missing reference {ref_path}: run pytest --regen-images and look at it"
    reference, _ = read_image(ref_path)
    assert reference.shape == actual.shape
    bad, worst = compare(actual, reference)
    if bad > MAX_BAD_FRACTION:
        FAILURES.mkdir(exist_ok=True)
        write_image(FAILURES / f"{stem}_actual.png", actual)
        diff = np.abs(actual.astype(np.int16) - reference.astype(np.int16))
        diff_img = np.clip(diff * 8, 0, 255).astype(np.uint8)
        diff_img[..., 3] = 255
        write_image(FAILURES / f"{stem}_diff.png", diff_img)
    assert bad <= MAX_BAD_FRACTION, (f"{stem}: {bad:.2%} of pixels off by more than {PIXEL_TOL}/255 "
                                     f"(largest {worst}); see {FAILURES}")


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption("--regen-images", action="store_true",
                     help="rewrite the reference images in tests/images from the current renderer")


def gl_required() -> bool:
    return bool(os.environ.get("LEAFVIEW_REQUIRE_GL"))


def require_or_skip(message: str) -> None:
    """A missing GL/display capability: a failure when LEAFVIEW_REQUIRE_GL is set, else a skip
    that says so."""
    if gl_required():
        pytest.fail(f"{message} (LEAFVIEW_REQUIRE_GL is set, so this is a failure)", pytrace=False)
    pytest.skip(f"{message} (set LEAFVIEW_REQUIRE_GL=1 to make this a failure)")


def _gl_unavailable(reason: str) -> None:
    require_or_skip(f"OpenGL 4.5 through EGL is unavailable: {reason}")


@pytest.fixture(scope="session")
def _session_renderer():
    from leafview.gpu import GLUnavailable

    try:
        renderer = leafview.gpu.default_renderer()
    except GLUnavailable as exc:
        renderer = None
        reason = str(exc)
    yield renderer if renderer is not None else reason


@pytest.fixture
def gl(_session_renderer):
    """The shared headless :class:`LeafRenderer`; asserts GL_NO_ERROR after the test."""
    if isinstance(_session_renderer, str):
        _gl_unavailable(_session_renderer)
    renderer = _session_renderer
    assert renderer.ctx.error == "GL_NO_ERROR", "a GL error was pending before this test"
    yield renderer
    assert renderer.ctx.error == "GL_NO_ERROR"


@pytest.fixture(scope="session")
def gltf_validator() -> tuple[str, Path]:
    """(node, validate.mjs) of the pinned Khronos glTF validator, for the tests that run it.

    Installed on first use with ``npm ci`` into ``tools/gltf_validator/node_modules`` (git ignores
    it; a file lock keeps concurrent test runs from installing twice), so the README's test command
    needs no separate step. Without node or npm, or when npm cannot reach the registry, the tests
    that use it skip with the reason (what is missing and how to get it), or fail under
    LEAFVIEW_REQUIRE_GL; pytest re-raises that outcome for every such test without trying again."""
    try:
        return ensure_gltf_validator()
    except ValidatorMissing as exc:
        reason = str(exc)
    # outside the except block: the message once, not chained to the exception
    require_or_skip(f"the Khronos glTF validator is unavailable: {reason}")
    raise ValidatorMissing(reason)   # not reached: require_or_skip skips or fails


@pytest.fixture(scope="session")
def presets() -> dict[str, LeafParams]:
    return {name: LeafParams.load(path) for name, path in builtin_presets().items()}


def random_params(rng: np.random.Generator, *, jitter: bool = False) -> LeafParams:
    """A random but plausible Ω: bent, skewed, curled axis; silhouette rows with increasing v̄."""
    a1 = [rng.uniform(-0.2, 0.2), rng.uniform(0.15, 0.5), rng.uniform(-0.2, 0.2)]
    a2 = [rng.uniform(-0.2, 0.2), rng.uniform(0.5, 0.85), rng.uniform(-0.2, 0.2)]
    v = np.sort(rng.uniform(0.05, 0.95, 3))
    v[1] = max(v[1], v[0] + 0.02)
    v[2] = min(max(v[2], v[1] + 0.02), 0.99)
    rows = [[v[i], rng.uniform(0.02, 0.7), rng.uniform(-0.15, 0.15)] for i in range(3)]
    omega = np.r_[a1, a2, np.ravel(rows), rng.uniform(-0.15, 0.15, 6)]
    params = LeafParams.from_vector(omega)
    if jitter:
        from leafview.core.params import Jitter

        params = params.replace(jitter=Jitter(enabled=True, amplitude=rng.uniform(0.005, 0.08),
                                              density=rng.uniform(3, 90), seed=int(rng.integers(0, 1000))))
    return params
