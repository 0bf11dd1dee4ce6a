"""Slice pictures name their plane and use the colours of the 3D view (issue 17 item 5): the
sieve colours are the VRML palette of `anm run` (read here from src/cli/run.f90), shell layers take
the colours stored in the model (/shells/colour, as the VRML shells), and the title says x/y/z =
position for planes normal to an axis."""
import pathlib
import re
import types

import numpy as np

from anm_post.images import SIEVE_COLOURS, label_rgb, layer_colours, plane_name
from anm_post.slicing import Plane

ROOT = pathlib.Path(__file__).resolve().parents[2]


def vrml_palette():
    text = (ROOT / "src" / "cli" / "run.f90").read_text()
    block = re.search(r"palette\(3, *(\d+)\) *= *reshape\(\[(.*?)\]", text, re.S)
    values = [float(x.replace("_wp", "")) for x in re.findall(r"[\d.]+_wp", block.group(2))]
    return [tuple(values[i:i + 3]) for i in range(0, len(values), 3)]


def test_sieve_colours_are_the_vrml_palette():
    palette = vrml_palette()
    assert len(palette) == 6
    assert [tuple(round(c, 6) for c in col) for col in SIEVE_COLOURS] == palette


def test_layer_colours_come_from_the_model():
    model = types.SimpleNamespace(shells={"colour": np.array([[0.1, 0.2, 0.3]])})
    cols = layer_colours(model, 2)
    assert cols[0] == (0.1, 0.2, 0.3)
    assert cols[1] != cols[0]          # a layer the model does not store: the fallback
    assert len(layer_colours(None, 3)) == 3


def test_label_image_colours():
    result = types.SimpleNamespace(particle=np.array([[0, -1, -1]]), sieve=np.array([[1, -1, -1]]),
                                   layer=np.array([[0, 1, 0]]))
    model = types.SimpleNamespace(shells={"colour": np.array([[0.1, 0.2, 0.3]])})
    img = label_rgb(result, 2, model)
    assert np.allclose(img[0, 0], SIEVE_COLOURS[1]) and np.allclose(img[0, 1], (0.1, 0.2, 0.3))
    assert np.allclose(img[0, 2], 1.0)


def test_plane_names():
    eye = np.eye(3)
    cases = [(0, "x = 2.5 mm", "y (mm)", "z (mm)"), (1, "y = 2.5 mm", "x (mm)", "z (mm)"),
             (2, "z = 2.5 mm", "x (mm)", "y (mm)")]
    for k, title, ulab, vlab in cases:
        iu, iv = [d for d in range(3) if d != k]
        origin = np.zeros(3)
        origin[k] = 2.5
        p = Plane(tuple(origin), tuple(eye[iu]), tuple(eye[iv]), (4.0, 4.0), 0.1)
        assert plane_name(p) == (title, ulab, vlab)
    s = np.sqrt(0.5)
    oblique = Plane((0.0, 0.0, 0.0), (s, -s, 0.0), (0.0, 0.0, 1.0), (2.0, 2.0), 0.1)
    title, ulab, _ = plane_name(oblique)
    assert title.startswith("through (") and "normal (" in title and ulab == "u (mm)"
