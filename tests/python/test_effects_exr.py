"""Images written by the real-time effect stages read back with OpenImageIO.

`EpipolarShadows` (window room) and `ImageFog` (outdoor street) run on small rasters with `voltab run`;
OpenImageIO (not voltab's own EXR reader) opens the EXRs and the checks are:

- channels are R, G, B plus the documented layers, all float, at the stage's raster size;
- every value is finite and non-negative; transmittance lies in [0, 1];
- the god-ray image is `colour · transmittance + inscatter` per pixel and channel, and the fog image is
  `attenuated + scattered`;
- fog never brightens a surface in the attenuated layer (`attenuated <= colour`);
- the PNG previews have the EXR's size.
"""
import os
import pathlib
import subprocess

import numpy as np
import OpenImageIO as oiio
import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
VOLTAB = os.environ.get("VOLTAB_BIN", str(ROOT / "target" / "debug" / "voltab"))

PIPELINE = """(
    stages: [
        EpipolarShadows(id: "god", scene: "%s", width: 96, height: 72, colour_samples: 1, shadow_map: 512),
        ImageFog(id: "fog", scene: "%s", width: 96, height: 54, colour_samples: 1),
    ],
)
"""


@pytest.fixture(scope="module")
def out(tmp_path_factory):
    d = tmp_path_factory.mktemp("fx")
    p = d / "p.ron"
    p.write_text(PIPELINE % (ROOT / "scenes" / "window_room.gltf", ROOT / "scenes" / "outdoor.gltf"))
    o = d / "out"
    r = subprocess.run([VOLTAB, "run", str(p), "--out", str(o)], capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr
    return o


def layers(path, expected_size):
    buf = oiio.ImageBuf(str(path))
    assert not buf.has_error, buf.geterror()
    spec = buf.spec()
    assert (spec.width, spec.height) == expected_size
    assert spec.format == oiio.FLOAT
    px = buf.get_pixels(oiio.FLOAT)
    names = list(spec.channelnames)
    out = {}
    for layer in {n.rsplit(".", 1)[0] if "." in n else "" for n in names}:
        prefix = layer + "." if layer else ""
        out[layer] = np.stack([px[:, :, names.index(prefix + c)] for c in "RGB"], axis=-1).astype(np.float64)
    return out


def test_god_rays_exr_composes_colour_transmittance_and_inscatter(out):
    img = layers(out / "god" / "godrays.exr", (96, 72))
    assert set(img) == {"", "inscatter", "transmittance", "colour"}
    for name, a in img.items():
        assert np.isfinite(a).all() and (a >= 0).all(), name
    assert (img["transmittance"] <= 1.0).all()
    want = img["colour"] * img["transmittance"] + img["inscatter"]
    np.testing.assert_allclose(img[""], want, rtol=1e-5, atol=1e-7)
    assert img["inscatter"].max() > 0.0


def test_fog_exr_is_attenuated_plus_scattered(out):
    img = layers(out / "fog" / "fog.exr", (96, 54))
    assert set(img) == {"", "attenuated", "scattered", "colour"}
    for name, a in img.items():
        assert np.isfinite(a).all() and (a >= 0).all(), name
    np.testing.assert_allclose(img[""], img["attenuated"] + img["scattered"], rtol=1e-5, atol=1e-7)
    assert (img["attenuated"] <= img["colour"] * (1 + 1e-6) + 1e-9).all()
    assert img["scattered"].sum() > 0.0


@pytest.mark.parametrize(
    "png,size",
    [
        ("god/godrays.png", (96, 72)),
        ("god/inscatter.png", (96, 72)),
        ("fog/fog.png", (96, 54)),
        ("fog/fog_attenuated.png", (96, 54)),
        ("fog/fog_scattered.png", (96, 54)),
    ],
)
def test_previews_have_the_exr_size(out, png, size):
    spec = oiio.ImageInput.open(str(out / png)).spec()
    assert (spec.width, spec.height) == size
