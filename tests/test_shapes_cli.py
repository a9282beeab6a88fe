"""``leafview shapes``: the catalogue table, rendered sheets and single shapes, multilobed leaves,
and bad input (exit 2, the field named, no file written)."""

import json

import numpy as np
import pytest

from leafview.botany.catalogue import catalogue, landmark_leaf, random_instance
from leafview.botany.landmarks import margins
from leafview.cli import main
from leafview.core.defaults import DETAIL_GRID
from leafview.core.params import LeafParams
from leafview.export.images import PARAMS_ATTRIBUTE, read_image
from leafview.shapes import shapes_params


def test_listing_shows_every_shape_with_its_fit_error(capsys):
    assert main(["shapes"]) == 0
    out = capsys.readouterr().out
    lines = out.strip().splitlines()
    names = [e.name for e in catalogue()]
    assert len(lines) == len(names) + 2 and lines[0].split()[:4] == ["name", "waist", "base", "apex"]
    row = next(line for line in lines if line.startswith("cordate "))
    assert "extended" in row and row.rstrip().endswith("%")
    errors = [float(line.split()[-1].rstrip("%")) for line in lines[1:-1]]
    assert max(errors) <= 1.0 and min(errors) > 0.0


@pytest.mark.gl
def test_sheet_of_selected_shapes(gl, tmp_path, capsys):
    out = tmp_path / "sheet.png"
    assert main(["shapes", "--names", "cordate,reniform", "obcordate", "--sheet", "-o", str(out), "--size", "64",
                 "-q"]) == 0
    img, _ = read_image(out)
    assert img.shape[1] == 3 * 64 and (img[..., 3] == 255).all()     # three tiles, opaque sheet
    assert "contact sheet of 3 shapes" in capsys.readouterr().out


@pytest.mark.gl
def test_one_shape_embeds_its_fitted_parameters(gl, tmp_path):
    out = tmp_path / "c.png"
    assert main(["shapes", "--names", "cordate", "-o", str(out), "--size", "48", "-q"]) == 0
    img, meta = read_image(out)
    assert img.shape == (48, 48, 4) and (img[..., 3] == 255).any() and (img[..., 3] == 0).any()
    assert LeafParams.from_dict(json.loads(meta[PARAMS_ATTRIBUTE])) == shapes_params("cordate")


@pytest.mark.gl
def test_directory_of_random_instances(gl, tmp_path):
    out = tmp_path / "dir"
    assert main(["shapes", "--names", "ovate", "lanceolate", "--seed", "3", "-o", str(out), "--size", "32",
                 "-q"]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["lanceolate-3.png", "ovate-3.png"]


@pytest.mark.gl
def test_margin_instance_embeds_its_exact_margin(gl, tmp_path):
    """--margin: the random instance is drawn from its own landmark margin, and the image's
    embedded parameters carry that margin (re-rendering them gives the same leaf)."""
    out = tmp_path / "c.png"
    assert main(["shapes", "--names", "cordate", "--seed", "3", "--margin", "-o", str(out), "--size", "48",
                 "-q"]) == 0
    img, meta = read_image(out)
    leaf = LeafParams.from_dict(json.loads(meta[PARAMS_ATTRIBUTE]))
    assert leaf.name == "cordate#3" and leaf.margin is not None
    assert leaf.margin == margins([random_instance(landmark_leaf("cordate"), 3)])[0]
    again = gl.render_many([leaf], (48, 48), "top", grid=DETAIL_GRID)[0]
    assert np.abs(img.astype(int) - again).max() <= 1


@pytest.mark.gl
def test_lobed_leaf_renders(gl, tmp_path, capsys):
    out = tmp_path / "maple.png"
    assert main(["shapes", "--lobed", "maple", "-o", str(out), "--size", "64"]) == 0
    img, _ = read_image(out)
    assert img.shape == (64, 64, 4) and 0.2 < (img[..., 3] > 0).mean() < 0.8
    assert "maple: 4 lateral lobes, one margin" in capsys.readouterr().out
    assert main(["shapes", "--lobed", "oak"]) == 0             # without -o: describe it
    assert "pinnate, 8 lateral lobes" in capsys.readouterr().out


@pytest.mark.parametrize("argv, message", [
    (["shapes", "--names", "cordat"], "did you mean cordate"),
    (["shapes", "--sheet"], "give -o FILE or -o DIR"),
    (["shapes", "--names", "ovate", "lanceolate", "-o", "two.png"], "need -o DIR"),
    (["shapes", "--sheet", "-o", "sheet.exr"], "use .png or .tif"),
    (["shapes", "--lobed", "mapel", "-o", "x.png"], "built-in"),
    (["shapes", "--lobed", "maple", "-o", "x.txt"], "give an image file name"),
    (["shapes", "--lobed", "maple", "--sheet", "-o", "x.png"], "drop --names, --sheet, --seed and --margin"),
    (["shapes", "--lobed", "maple", "--margin", "-o", "x.png"], "drop --names, --sheet, --seed and --margin"),
    (["shapes", "--margin"], "--margin render images: give -o FILE or -o DIR"),
])
def test_bad_input_exits_2_and_writes_nothing(tmp_path, monkeypatch, capsys, argv, message):
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("leafview shapes: error:") and message in err, err
    assert list(tmp_path.iterdir()) == []


def test_bad_lobed_file_names_file_and_field(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    bad = tmp_path / "bad.toml"
    bad.write_text('lobed = 1\nkind = "palmate"\ntheta = [10.0, "x"]\n')
    assert main(["shapes", "--lobed", str(bad), "-o", "out.png"]) == 2
    err = capsys.readouterr().err
    assert "bad.toml" in err and "theta" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.toml"]
