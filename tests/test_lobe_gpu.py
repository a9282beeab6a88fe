"""Lobed leaves on the GPU: the swept surface of ``leaf.vert`` (``lobe_eval`` in
``shaders/leaf_eval.glsl``) read back against its numpy twin ``leafview.deform.sweep.sweep_eval``
(Mündermann et al. 2003, secs 3.3-4), with and without ripples along the margins (Geng, Hu & Zhang
2014, eq. 5), the lobe layer's slot and branch code, the lobed grids and a rendered thumbnail."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from leafview.botany.lobe_sweep import sweep_table
from leafview.core.defaults import DEFAULT_GRID, DETAIL_GRID, LOBED_GRID
from leafview.core.lobes import BranchTurtle, Lobes
from leafview.core.params import LeafParams, Material, Ripple, Transform
from leafview.deform.surface import evaluate, grid_uv
from leafview.deform.sweep import SWEEP_ROWS, SweepTable, catmull_rom_periodic, sweep_eval, table_texels
from leafview.gpu.instanced import InstancedLeaves
from leafview.gpu.layout import (
    BRANCH_LOBE,
    BRANCH_ROWS,
    LOBE_UNIT,
    MAX_SILHOUETTE_ROWS,
    branch_code,
    branch_parts,
    lobe_defines,
    pack_leaf,
    pack_leaves,
    read_slot,
    ripple_keys,
    without_derived,
)
from leafview.gpu.lobe_tables import LobeTables, lobe_keys, lobed_grid
from leafview.gpu.renderer import DRAW_VARYINGS, DRAW_VERTEX_BYTES, LeafRenderer
from leafview.gpu.sheets import render_leaves
from leafview.gpu.targets import OffscreenTarget
from leafview.resources import builtin_presets
from leafview.scene.camera import frame_view
from tests.conftest import assert_matches_reference, run_prepare

POS_TOL = 5e-6     # leaf lengths: float32 splines of values of size ~1 (measured: about 1e-7)
NORMAL_TOL = 2e-4  # away from degenerate ties (see _robust; measured: under 5e-5)


# -- hand-made sweep tables -------------------------------------------------------------------
def _tour_angles(n: int = SWEEP_ROWS) -> np.ndarray:
    """Margin angle of tie j: from the base (straight below the centre) clockwise seen from above."""
    return 2.0 * np.pi * np.arange(n) / n


def _down_clockwise(phi: np.ndarray) -> np.ndarray:
    """Unit directions at angle phi clockwise from -y (seen from +z): -y, -x, +y, +x at 0, 90, 180, 270°."""
    return np.stack([-np.sin(phi), -np.cos(phi)], axis=1)


def _table(feet: np.ndarray, ends: np.ndarray, *, cup: float = 0.0, lift: np.ndarray | None = None,
           tilt: np.ndarray | None = None) -> SweepTable:
    """A SweepTable of flat feet k_j and ends s_j (N, 2), optionally turned like a turtle would: the
    foot lifted by ``lift`` and the tie's frame rotated about the x axis by ``tilt`` (radians)."""
    n = len(feet)
    lift = np.zeros(n) if lift is None else lift
    tilt = np.zeros(n) if tilt is None else tilt
    c, s = np.cos(tilt), np.sin(tilt)
    rot = np.zeros((n, 3, 3))
    rot[:, 0, 0] = 1.0
    rot[:, 1, 1], rot[:, 1, 2], rot[:, 2, 1], rot[:, 2, 2] = c, -s, s, c
    origin = np.c_[feet, lift]
    d = np.c_[ends - feet, np.zeros(n)]
    rim = origin + np.einsum("nij,nj->ni", rot, d)
    up = rot[:, :, 2]
    seg = np.linalg.norm(np.diff(np.r_[ends, ends[:1]], axis=0), axis=1)
    margin = np.r_[0.0, np.cumsum(seg)[:-1]] / seg.sum()
    return SweepTable(origin=origin, rim=rim, up=up, length=np.linalg.norm(ends - feet, axis=1),
                      flat=np.c_[feet, ends], margin=margin, cup=cup)


def disk_table() -> SweepTable:
    """A disc of radius 0.5 around (0, 0.5), every tie from the centre (the skeleton is a point)."""
    phi = _tour_angles()
    centre = np.array([0.0, 0.5])
    return _table(np.broadcast_to(centre, (len(phi), 2)).copy(), centre + 0.5 * _down_clockwise(phi))


def star_table(lobes: int = 5) -> SweepTable:
    """A star of ``lobes`` lobes around (0, 0.5), a valley at the base: the skeleton is ``lobes``
    spokes, the feet run out along each spoke to its tip and back (the tour). Each valley's tie (foot
    at the centre) sits at a multiple of 4 ties, as the coarsest lobed grid (every 4th tie) needs:
    the rows of a coarser grid meet at the centre without a gap."""
    n = SWEEP_ROWS
    bounds = 4 * np.round(np.arange(lobes + 1) * n / (4 * lobes)).astype(int)
    j = np.arange(n)
    lobe = np.searchsorted(bounds, j, side="right") - 1
    s = (j - bounds[lobe]) / np.diff(bounds)[lobe]                  # 0 .. 1 across the lobe
    phi = 2.0 * np.pi * (lobe + s) / lobes
    spoke = 2.0 * np.pi * (lobe + 0.5) / lobes                      # the lobe's tip angle
    reach = 1.0 - np.abs(2.0 * s - 1.0)                             # 1 at the tip, 0 at the valleys
    centre = np.array([0.0, 0.5])
    ends = centre + (0.25 + 0.25 * reach)[:, None] * _down_clockwise(phi)
    feet = centre + (0.5 * reach)[:, None] * _down_clockwise(spoke)
    return _table(feet, ends)


def turtle_table() -> SweepTable:
    """The star turned like a turtle would: feet lifted towards the tips, ties tilted by varying
    angles (rotated frames, so U is not z), and cupped."""
    base = star_table()
    feet, ends = base.flat[:, :2], base.flat[:, 2:]
    r = np.linalg.norm(feet - (0.0, 0.5), axis=1)
    j = np.arange(len(feet))
    return _table(feet, ends, cup=0.35, lift=0.3 * r ** 2, tilt=0.4 * np.sin(2 * np.pi * j / len(feet)) + 0.8 * r)


def _lobes(tag: float) -> Lobes:
    """A distinct Lobes value to key a hand-made table (the outline itself is not used by it)."""
    return Lobes(outline=((0.0, 0.0), (0.3 + tag, 0.5), (0.0, 1.0), (-0.3, 0.5)))


HAND = {"disk": (_lobes(0.0), disk_table), "star": (_lobes(0.01), star_table), "turtle": (_lobes(0.02), turtle_table)}
_BY_KEY = {key: make for key, make in HAND.values()}


def hand_table(lobes: Lobes) -> SweepTable:
    return _BY_KEY[lobes]()


def lobed_leaf(name: str, **kw) -> LeafParams:
    return LeafParams(lobes=HAND[name][0], material=Material(front=(0.2, 0.5, 0.15), back=(0.45, 0.6, 0.3)),
                      name=name, **kw)


@pytest.fixture
def renderer(gl):
    """A renderer on the shared context whose lobe tables come from the hand-made tables (and,
    for other keys, from leafview.botany.lobe_sweep)."""
    def table_of(lobes: Lobes) -> SweepTable:
        if lobes in _BY_KEY:
            return hand_table(lobes)
        return sweep_table(lobes)

    with LeafRenderer(gl.ctx, resources=gl.resources) as r:
        r.leaf_lobes.table_of = table_of
        r.batch_lobes.table_of = table_of
        yield r
    assert gl.ctx.error == "GL_NO_ERROR"


def _uv_points(seed: int = 3) -> np.ndarray:
    """The full lobed grid plus random points between the ties and across them."""
    rng = np.random.default_rng(seed)
    extra = np.c_[rng.uniform(-1, 1, 400), rng.uniform(0, 1, 400)]
    return np.r_[grid_uv(*LOBED_GRID).astype(np.float64), extra].astype(np.float32).astype(np.float64)


def _robust(ev, margin: float = 1e-3) -> np.ndarray:
    """Points whose normal is well defined (not at a degenerate tie, where float32 may pick the
    other side of the fallback's threshold)."""
    size = np.linalg.norm(np.cross(ev.Lv, ev.Lu), axis=1)
    scale = np.linalg.norm(ev.Lu, axis=1) * np.linalg.norm(ev.Lv, axis=1)
    return (size > margin * scale) | (size == 0.0)


def _compare(renderer, params: LeafParams, table: SweepTable, ripple: Ripple | None = None
             ) -> tuple[float, float]:
    uv = _uv_points()
    pos, nrm = renderer.capture(params, uv[:, 0], uv[:, 1])
    ev = sweep_eval(table, uv, ripple)
    ok = _robust(ev)
    pos_err = float(np.abs(pos - ev.L).max())
    nrm_err = float(np.abs(nrm[ok] - ev.normal[ok]).max())
    assert ok.mean() > 0.9
    assert pos_err < POS_TOL, (params.name, pos_err)
    assert nrm_err < NORMAL_TOL, (params.name, nrm_err)
    return pos_err, nrm_err


# -- numpy only ---------------------------------------------------------------------------------
def test_lobed_grids_land_on_the_ties():
    assert LOBED_GRID == (9, SWEEP_ROWS + 1) and lobed_grid(LOBED_GRID) == LOBED_GRID
    assert lobed_grid(DEFAULT_GRID) == (8, SWEEP_ROWS + 1)       # the margin gets the vertices
    for nu, nv in [(5, 3), (9, 15), (17, 100), (9, 1000), DETAIL_GRID, (3, 5)]:
        gu, gv = lobed_grid((nu, nv))
        assert 2 <= gu <= max(nu, 2) and SWEEP_ROWS % (gv - 1) == 0 and SWEEP_ROWS // (gv - 1) in (1, 2, 4)
        # about the vertex count asked for, or the coarsest or finest lobed grid
        near = abs(gu * gv - nu * nv) <= 0.5 * nu * nv
        assert near or (gu, gv) in ((2, SWEEP_ROWS // 4 + 1), (min(nu, 9), SWEEP_ROWS + 1)), (nu, nv, gu, gv)
        x = grid_uv(gu, gv)[:, 1].astype(np.float64) * SWEEP_ROWS
        np.testing.assert_array_equal(x, np.round(x))   # every grid row is a tie


def test_hand_tables_are_sweeps():
    for name, (_, make) in HAND.items():
        table = make()
        ev = sweep_eval(table, grid_uv(*LOBED_GRID))
        assert np.isfinite(ev.L).all() and np.allclose(np.linalg.norm(ev.normal, axis=1), 1.0), name
        # upper side: the normals of the flat ones point up
        if table.cup == 0.0 and not table.origin[:, 2].any():
            assert (ev.normal[:, 2] > 0.99).all(), name
        # the first and last grid rows are the same tie
        rows = ev.L.reshape(LOBED_GRID[1], LOBED_GRID[0], 3)
        np.testing.assert_allclose(rows[0], rows[-1], atol=1e-12)


def test_ripple_twin_keeps_the_plain_sweep_and_its_derivatives():
    table = turtle_table()
    uv = _uv_points()
    plain = sweep_eval(table, uv)
    off = sweep_eval(table, uv, Ripple(enabled=False, amplitude=(0.05, 0.05)))
    np.testing.assert_array_equal(plain.L, off.L)
    rip = Ripple(enabled=True, amplitude=(0.04, 0.01), fluctuation=(0.3, 0.9), veins=40.0, seed=7)
    on = sweep_eval(table, uv, rip)
    d = on.L - plain.L
    assert np.abs(d).max() > 0.01
    # D is along U and vanishes on the skeleton (t = 0)
    assert np.abs(d[uv[:, 0] == -1.0]).max() == 0.0
    # finite differences of the rippled surface match Lu, Lv (interior points)
    x = uv[:, 1] * SWEEP_ROWS   # off the ties (the splines' second derivatives jump there)
    inner = uv[(np.abs(uv[:, 0]) < 0.99) & (np.abs(x - np.round(x)) > 0.01)]
    h = 1e-6
    ev = sweep_eval(table, inner, rip)
    du = (sweep_eval(table, inner + (h, 0), rip).L - sweep_eval(table, inner - (h, 0), rip).L) / (2 * h)
    dv = (sweep_eval(table, inner + (0, h), rip).L - sweep_eval(table, inner - (0, h), rip).L) / (2 * h)
    np.testing.assert_allclose(ev.Lu, du, atol=1e-5 * max(1.0, np.abs(du).max()))
    np.testing.assert_allclose(ev.Lv, dv, atol=1e-4 * max(1.0, np.abs(dv).max()))


def test_lobe_slot_and_branch_code_round_trip():
    leaves = [LeafParams(), lobed_leaf("disk"), lobed_leaf("star", ripple=Ripple(enabled=True))]
    layers = np.array([-1, 0, 3], np.int32)
    recs, _ = pack_leaves(leaves, lobe_layers=layers)
    np.testing.assert_array_equal(read_slot(recs, "leaf_lobe_layer"), layers)
    code = branch_code(recs)
    parts = branch_parts(code)
    np.testing.assert_array_equal(parts["lobe"], layers)
    np.testing.assert_array_equal(parts["ripple"], [0, 0, 1])
    assert BRANCH_LOBE > BRANCH_ROWS * MAX_SILHOUETTE_ROWS + 3
    # every combination decodes to its parts
    rows = np.arange(MAX_SILHOUETTE_ROWS + 1)
    for lobe in (-1, 0, 5, 1000):
        for ripple in (0, 1):
            for bend in (0, 1):
                c = ripple + 2 * bend + BRANCH_ROWS * rows + BRANCH_LOBE * (lobe + 1)
                p = branch_parts(c)
                assert (p["lobe"] == lobe).all() and (p["rows"] == rows).all()
                assert (p["ripple"] == ripple).all() and (p["bend"] == bend).all()
    # unlobed records keep their old code; the slot is a packer field, not a derived one
    np.testing.assert_array_equal(branch_code(pack_leaves(leaves)[0]), [0, 0, 1])
    np.testing.assert_array_equal(read_slot(without_derived(recs), "leaf_lobe_layer"), layers)
    assert lobe_defines(recs) == {} and lobe_defines(recs[:1]) == {"LEAF_NO_LOBES": 1}
    assert read_slot(pack_leaf(leaves[1], lobe_layer=2), "leaf_lobe_layer") == 2


def test_lobe_texels_hold_the_cup_and_the_texture_window():
    table = turtle_table()
    tex = table_texels(table)
    assert tex.shape == (4, SWEEP_ROWS, 4) and tex.dtype == np.float32
    assert tex[2, 0, 3] == np.float32(table.cup)
    np.testing.assert_array_equal(tex[2, 1:5, 3], np.asarray(table.window, np.float32))
    xc, hw, y0, h = table.window     # the window is the flat margin's bounding box
    rim = table.flat[:, 2:]
    assert np.isclose(rim[:, 0].min(), xc - hw) and np.isclose(rim[:, 0].max(), xc + hw)
    assert np.isclose(rim[:, 1].min(), y0) and np.isclose(rim[:, 1].max(), y0 + h)
    np.testing.assert_array_equal(tex[0, :, 3], table.margin.astype(np.float32))


# -- GL -----------------------------------------------------------------------------------------
@pytest.mark.gl
def test_prepare_pass_folds_the_lobe_layer_into_the_branch_code(gl):
    leaves = [LeafParams(), lobed_leaf("disk"), lobed_leaf("star", ripple=Ripple(enabled=True)), lobed_leaf("turtle")]
    recs, _ = pack_leaves(leaves, lobe_layers=[-1, 0, 1, 40])
    out = run_prepare(gl, recs)
    np.testing.assert_array_equal(read_slot(out, "leaf_branches"), branch_code(recs))
    np.testing.assert_array_equal(branch_parts(read_slot(out, "leaf_branches"))["lobe"], [-1, 0, 1, 40])


@pytest.mark.gl
@pytest.mark.parametrize("name", list(HAND))
def test_readback_matches_sweep_eval(renderer, name):
    params = lobed_leaf(name)
    pos_err, nrm_err = _compare(renderer, params, HAND[name][1]())
    print(f"{name}: positions {pos_err:.2e}, normals {nrm_err:.2e}")


@pytest.mark.gl
@pytest.mark.parametrize("name", ["star", "turtle"])
def test_readback_with_ripples_matches_sweep_eval(renderer, name):
    rip = Ripple(enabled=True, amplitude=(0.03, 0.001), fluctuation=(0.3, 0.9), veins=40.0, seed=5, beta=1.5)
    params = lobed_leaf(name, ripple=rip)
    pos_err, nrm_err = _compare(renderer, params, HAND[name][1](), rip)
    plain = sweep_eval(HAND[name][1](), _uv_points())
    assert np.abs(sweep_eval(HAND[name][1](), _uv_points(), rip).L - plain.L).max() > 0.01   # ripples drawn
    print(f"{name} rippled: positions {pos_err:.2e}, normals {nrm_err:.2e}")


@pytest.mark.gl
def test_the_lobes_variant_and_the_full_program_agree(renderer):
    """LEAF_NO_LOBES compiles the branch out for unlobed draws without changing them, and a lobed
    leaf is drawn the same by the full program and its own variant."""
    uv = grid_uv(9, 15)
    plain = LeafParams(ripple=Ripple(enabled=True))
    for leaf, defines in ((plain, {"LEAF_NO_LOBES": 1}), (lobed_leaf("turtle"), {"LEAF_NO_JITTER": 1})):
        outs = [np.concatenate(renderer.capture(leaf, uv[:, 0], uv[:, 1], defines=d), axis=1) for d in (None, defines)]
        np.testing.assert_array_equal(outs[0], outs[1])


@pytest.mark.gl
def test_lobe_tables_hold_one_layer_per_key(gl):
    tables = LobeTables(gl.ctx, hand_table)
    try:
        leaves = [lobed_leaf("star"), LeafParams(), lobed_leaf("disk"), lobed_leaf("star")]
        layers = tables.update(leaves)
        assert layers.tolist() == [0, -1, 1, 0] and tables.keys == lobe_keys(leaves)
        assert tables.texture is not None and tables.texture.size == (SWEEP_ROWS, 4, 2)
        got = np.frombuffer(tables.texture.read(), np.float32).reshape(2, 4, SWEEP_ROWS, 4)
        np.testing.assert_array_equal(got[1], table_texels(disk_table()))
        before = tables.uploads
        assert tables.update(leaves).tolist() == [0, -1, 1, 0] and tables.uploads == before   # nothing rewritten
        tables.use()
        assert tables.update([LeafParams()]).tolist() == [-1] and not tables.active
    finally:
        tables.release()
    assert LOBE_UNIT == 7


@pytest.mark.gl
def test_instanced_and_batched_lobed_leaves_match_the_single_leaf(renderer, gl):
    """render_many (the thumbnails' captured draw) and the single-leaf capture draw a lobed leaf
    among unlobed ones from the same vertices."""
    leaves = [LeafParams(), lobed_leaf("turtle"), lobed_leaf("star")]
    images = renderer.render_many(leaves, (48, 48), flat=True)
    alone = [renderer.render(p, (48, 48), flat=True) for p in leaves]
    for a, b in zip(images, alone):
        np.testing.assert_array_equal(a, b)
    assert (images[2][..., 3] > 0).mean() > 0.2


def built_lobes() -> Lobes:
    """A five-lobed outline for the real table builder, cupped, two branches turned like a turtle."""
    phi = np.linspace(0.0, 2.0 * np.pi, 15, endpoint=False)
    r = 0.35 + 0.15 * np.cos(5.0 * phi)
    outline = tuple((float(-np.sin(p) * q), float(0.5 - np.cos(p) * q)) for p, q in zip(phi, r))
    edits = (BranchTurtle(branch=0, bend=(20.0, 40.0, 40.0, 60.0), twist=(0.0, 15.0, 30.0, 30.0)),
             BranchTurtle(branch=2, bend=(-30.0, -30.0, 0.0, 0.0), turn=(10.0, 10.0, 10.0, 10.0)))
    return Lobes(outline=outline, cup=0.2, branches=edits)


@pytest.mark.gl
@pytest.mark.parametrize("rippled", [False, True])
def test_readback_of_a_built_table_matches_sweep_eval(renderer, rippled):
    lobes = built_lobes()
    table = sweep_table(lobes)
    assert not np.allclose(table.up, (0.0, 0.0, 1.0))   # the turtle turned some ties
    rip = Ripple(enabled=True, amplitude=(0.02, 0.02), seed=11) if rippled else Ripple()
    params = LeafParams(lobes=lobes, ripple=rip, name="built")
    pos_err, nrm_err = _compare(renderer, params, table, rip)
    print(f"built{' rippled' if rippled else ''}: positions {pos_err:.2e}, normals {nrm_err:.2e}")


def _maple() -> LeafParams:
    """The built-in maple preset (assets/presets/maple.toml)."""
    return LeafParams.load(builtin_presets()["maple"])


@pytest.mark.gl
def test_lobed_thumbnail(renderer, request):
    """A 128 px top view of the hand-made star: five lobes, the midrib band along x = 0 and no hole
    where the valleys' ties fan out from the centre."""
    img = renderer.render(lobed_leaf("star"), (128, 128), "top")
    alpha = img[..., 3] > 0
    assert 0.2 < alpha.mean() < 0.8
    rows = np.nonzero(alpha.any(axis=1))[0]
    cols = np.nonzero(alpha.any(axis=0))[0]
    cy, cx = (rows[0] + rows[-1]) // 2, (cols[0] + cols[-1]) // 2
    assert alpha[cy - 6:cy + 7, cx - 6:cx + 7].all()       # the centre is covered
    assert_matches_reference(img, "lobed_star", request)


@pytest.mark.gl
def test_maple_thumbnail(renderer):
    """A 128 px top view of the maple preset: a leaf without holes (the paired ties weld); the
    star's image above is the reference image of the lobed branch."""
    maple = _maple()
    img = renderer.render(maple, (128, 128), "top")
    alpha = img[..., 3] > 0
    assert 0.2 < alpha.mean() < 0.8
    assert not (ndimage.binary_fill_holes(alpha) & ~alpha).any()


@pytest.mark.gl
def test_maple_readback_matches_sweep_eval(renderer):
    maple = _maple()
    assert maple.lobes.enabled
    table = sweep_table(maple.lobes)
    rip = maple.ripple if maple.ripple.enabled else None
    pos_err, nrm_err = _compare(renderer, maple, table, rip)
    print(f"maple: positions {pos_err:.2e}, normals {nrm_err:.2e}")
    rippled = maple.replace(ripple=Ripple(enabled=True, amplitude=(0.02, 0.02)))
    pos_err, nrm_err = _compare(renderer, rippled, table, rippled.ripple)
    print(f"maple rippled: positions {pos_err:.2e}, normals {nrm_err:.2e}")


@pytest.mark.gl
def test_instanced_lobed_leaves_match_sweep_eval(gl):
    """The instanced path (record attributes, the ripple's members from the row texture) draws
    lobed leaves among unlobed ones from the same tables."""
    rip = Ripple(enabled=True, amplitude=(0.03, 0.01), veins=30.0, seed=2)
    leaves = [LeafParams(), lobed_leaf("turtle", ripple=rip), lobed_leaf("star"), LeafParams(ripple=Ripple(enabled=True))]
    grid = lobed_grid((9, 65))
    tables = LobeTables(gl.ctx, hand_table)
    try:
        layers = tables.update(leaves)
        records, jitter = pack_leaves(leaves, lobe_layers=layers)
        with OffscreenTarget(gl.ctx, (1, 1)) as target, \
                InstancedLeaves(gl.ctx, records, grid, jitter_tables=jitter, ripple_signals=ripple_keys(leaves),
                                resources=gl.resources, lobes=tables) as inst:
            target.use()
            pos, nrm = inst.capture()
        uv = grid_uv(*grid)
        for i, (leaf, table_rip) in enumerate([(leaves[1], rip), (leaves[2], None)]):
            ev = sweep_eval(hand_table(leaf.lobes), uv, table_rip)
            assert np.abs(pos[i + 1] - ev.L).max() < POS_TOL   # identity transforms: world = leaf space
            ok = _robust(ev)
            assert np.abs(nrm[i + 1][ok] - ev.normal[ok]).max() < NORMAL_TOL
        # the unlobed leaves are still Ω (the lobed grid's rows are just more v samples)
        single = [gl.capture(leaves[k], uv[:, 0], uv[:, 1]) for k in (0, 3)]
        for k, (p, n) in zip((0, 3), single):
            assert np.abs(pos[k] - p).max() < 1e-5 and np.abs(nrm[k] - n).max() < 1e-4
    finally:
        tables.release()


@pytest.mark.gl
def test_interactive_draw_of_a_lobed_leaf_matches_its_thumbnail(renderer):
    """set_leaf + draw() (the viewer's path) draws a lobed leaf on its lobed grid, the same picture
    as the captured thumbnail; an unlobed leaf after it is drawn unlobed again."""
    leaf = lobed_leaf("turtle")
    asked = (9, 15)                 # drawn as (9, 65): rows on every 4th tie
    grid = lobed_grid(asked)
    thumb = renderer.render(leaf, (64, 64), "top", grid=asked, flat=True)
    uv = grid_uv(*grid)
    fbo = renderer.ctx.simple_framebuffer((64, 64))
    try:
        renderer.set_leaf(leaf)
        assert renderer.lobed
        world, _ = renderer.capture(leaf, uv[:, 0], uv[:, 1])
        renderer.set_camera(frame_view("top", world.astype(np.float64), (64, 64)), srgb=True, flat=True)
        fbo.use()
        fbo.clear(0, 0, 0, 0, depth=1.0)
        renderer.draw(asked)
        img = np.frombuffer(fbo.read(components=4), np.uint8).reshape(64, 64, 4)[::-1]
        diff = np.abs(img.astype(int) - thumb.astype(int)).max(axis=-1)
        assert np.mean(diff > 2) < 0.01, np.mean(diff > 2)
        renderer.set_leaf(LeafParams())
        assert not renderer.lobed and not renderer.leaf_lobes.active
    finally:
        renderer.ctx.detect_framebuffer(0).use()
        fbo.release()


@pytest.mark.gl
def test_sheets_draw_lobed_leaves(gl):
    """render_leaves binds the sweep tables: the lobed leaf's drawn width is its swept outline's,
    not the default Ω's beside it."""
    lobed = LeafParams(lobes=built_lobes())
    img = render_leaves([lobed, LeafParams(transform=Transform(translation=(1.2, 0.0, 0.0)))], (192, 128), "top")
    cols = np.nonzero((img[..., 3] > 0).any(axis=0))[0]
    runs = np.split(cols, np.nonzero(np.diff(cols) > 1)[0] + 1)
    assert len(runs) == 2                                     # two leaves side by side
    flat = sweep_eval(sweep_table(lobed.lobes), grid_uv(*LOBED_GRID)).L
    ratio = len(runs[0]) / len(runs[1])
    omega = 2 * np.abs(leafview_evaluate(LeafParams())[:, 0]).max()
    assert ratio == pytest.approx(np.ptp(flat[:, 0]) / omega, rel=0.1)


def leafview_evaluate(params: LeafParams) -> np.ndarray:
    uv = grid_uv(33, 65).astype(np.float64)
    return np.asarray(evaluate(params, uv[:, 0], uv[:, 1]))


@pytest.mark.gl
def test_texture_uv_and_vein_band_read_back_equal_their_twins(renderer):
    """leaf.vert's v_uv of a lobed leaf is its flat position in the table's texture window and
    v_rib.x the distance from the skeleton along the tie over LOBE_RIB_HALFWIDTH (0.3), read back
    through the thumbnail's transform feedback against deform.sweep."""
    leaf = lobed_leaf("turtle")
    table = hand_table(leaf.lobes)
    uv = _uv_points()
    renderer.set_leaf(leaf, textures=False)
    renderer._bind()
    program = renderer.resources.leaf_program({}, varyings=DRAW_VARYINGS)
    vbo = renderer.ctx.buffer(uv.astype(np.float32).tobytes())
    vao = renderer.ctx.vertex_array(program, [(vbo, "2f", "in_uv")])
    try:
        with renderer.resources.capture.recording(len(uv), DRAW_VERTEX_BYTES) as rec:
            rec.add(vao, len(uv))
            out = rec.records().reshape(len(uv), -1)
    finally:
        vao.release()
        vbo.release()
    ev = sweep_eval(table, uv)
    np.testing.assert_allclose(out[:, 6:8], ev.uv, atol=2e-5)
    t = 0.5 * (uv[:, 0] + 1.0)
    ln, _ = catmull_rom_periodic(table.length, uv[:, 1] * table.rows)
    np.testing.assert_allclose(out[:, 8], t * ln / 0.3, atol=2e-5)
    np.testing.assert_array_equal(out[:, 9], 0.0)
    inside = (np.abs(ev.uv[:, 0]) <= 1 + 1e-6) & (ev.uv[:, 1] >= -1e-6) & (ev.uv[:, 1] <= 1 + 1e-6)
    assert inside.all()          # the window holds the whole blade
