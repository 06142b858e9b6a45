"""Lightmaps written by `BakeLightmaps` read back with OpenImageIO.

A small pipeline (a reduced ZH table and a coarse bake of the bundled fog room in the Surface, Shadow and
Full modes) is run with `voltab run`. OpenImageIO (not voltab's own EXR reader) then opens every EXR and
the checks are:

- channel names are exactly R, G, B in float, and the image size is the atlas size summary.json reports;
- the texels summary.json lists (pixel position and value as written) read back bit for bit;
- every value is finite and non-negative, and the area outside the charts is black;
- the modes relate as physics says on every texel: media shadowing only removes light (Shadow <= Surface),
  scattering only adds it (Full >= Shadow);
- dilation: each chart's padding ring next to baked texels is filled (bilinear lookups at chart edges
  read no black);
- the PNG previews have the EXR's size.
"""
import json
import os
import pathlib
import subprocess

import numpy as np
import OpenImageIO as oiio
import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
VOLTAB = os.environ.get("VOLTAB_BIN", str(ROOT / "target" / "debug" / "voltab"))

PIPELINE = """(
    tables: [
        ZhResponse(id: "zh_small", g: [0.0, 0.5], distance_bins: 48, quadrature_nodes: 4, theta_bins: 4, bounces: 6),
    ],
    stages: [
        BakeLightmaps(
            id: "bake",
            scene: "%s",
            table: "zh_small",
            modes: [Surface, Shadow, Full],
            texels_per_metre: 4.0,
            samples: 8,
            scatter_samples: 2,
            bounces: 1,
            probe_grid: [2, 2, 2],
        ),
    ],
)
"""


@pytest.fixture(scope="module")
def baked(tmp_path_factory):
    d = tmp_path_factory.mktemp("bake")
    p = d / "p.ron"
    p.write_text(PIPELINE % (ROOT / "scenes" / "fog_room.gltf"))
    out = d / "out"
    r = subprocess.run([VOLTAB, "run", str(p), "--out", str(out)], capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr
    summary = json.loads((out / "bake" / "summary.json").read_text())
    return out / "bake", summary


def read(path):
    inp = oiio.ImageInput.open(str(path))
    assert inp is not None, oiio.geterror()
    spec = inp.spec()
    names = list(spec.channelnames)
    pixels = inp.read_image(0, 0, 0, spec.nchannels, oiio.FLOAT)
    fmt = str(spec.format)
    inp.close()
    return spec.width, spec.height, names, fmt, np.asarray(pixels, dtype=np.float32)


def test_channels_size_and_values_read_back_exactly(baked):
    folder, summary = baked
    w, h = summary["atlas_size"]
    assert [m["mode"] for m in summary["modes"]] == ["Surface", "Shadow", "Full"]
    for m in summary["modes"]:
        width, height, names, fmt, px = read(m["exr"])
        assert (width, height) == (w, h)
        assert names == ["R", "G", "B"]
        assert fmt == "float"
        assert np.all(np.isfinite(px)) and np.all(px >= 0.0)
        assert len(m["texel_samples"]) >= 16
        for x, y, rgb in m["texel_samples"]:
            # Written as f32; JSON carries the shortest decimal that round-trips f32.
            assert px[y, x].tolist() == [float(np.float32(v)) for v in rgb], (m["mode"], x, y)
        # The preview has the lightmap's size.
        png = oiio.ImageInput.open(str(pathlib.Path(m["exr"]).with_suffix(".png")))
        assert (png.spec().width, png.spec().height) == (w, h)
        png.close()


def test_modes_are_ordered_on_every_texel(baked):
    _, summary = baked
    imgs = {m["mode"]: read(m["exr"])[4] for m in summary["modes"]}
    lum = {k: v @ np.array([0.2126, 0.7152, 0.0722], dtype=np.float32) for k, v in imgs.items()}
    baked_px = lum["Surface"] > 0
    assert baked_px.sum() > 100
    # Same random numbers in every mode: attenuation removes light, scattering adds it.
    assert np.all(lum["Shadow"][baked_px] <= lum["Surface"][baked_px] * (1 + 1e-6))
    assert np.all(lum["Full"][baked_px] >= lum["Shadow"][baked_px] * (1 - 1e-6))
    assert lum["Full"][baked_px].mean() > lum["Shadow"][baked_px].mean()


def test_outside_charts_is_black_and_padding_is_dilated(baked):
    _, summary = baked
    _, _, _, _, px = read(summary["modes"][2]["exr"])
    h, w = px.shape[:2]
    inside = np.zeros((h, w), dtype=bool)
    for _name, x, y, cw, ch in summary["charts"]:
        inside[y : y + ch, x : x + cw] = True
    lum = px.sum(axis=2)
    # Padding is 2 texels around each chart: outside charts+padding nothing is written.
    grown = inside.copy()
    for dy in (-2, -1, 0, 1, 2):
        for dx in (-2, -1, 0, 1, 2):
            grown |= np.roll(np.roll(inside, dy, axis=0), dx, axis=1)
    assert np.all(lum[~grown] == 0.0)
    # The ring just outside each chart is filled where the chart's edge row/column is lit.
    for _name, x, y, cw, ch in summary["charts"]:
        if x >= 1 and lum[y : y + ch, x].max() > 0:
            assert lum[y : y + ch, x - 1].max() > 0, _name


def test_probes_file_exists(baked):
    folder, summary = baked
    assert summary["probes"] == 8
    assert (folder / "probes.vtab").stat().st_size > 100
