"""Unit and orientation conventions of `voltab export mitsuba` + `python/mitsuba_ref`, checked against
closed forms computed here (issue 30: conventions first, so a mismatch is not mistaken for a method
error). Each scene is authored with `scripts/make_scenes.py`'s glTF writer (photometric inputs, like the
bundled scenes), imported and exported by the voltab binary (VOLTAB_BIN), rendered by Mitsuba 3:

- point light: E = I cos θ / r² (I = candela / 683), zero behind the receiver;
- directional light: E = E⊥ cos θ (E⊥ = lux / 683);
- Beer–Lambert: a global absorbing medium between a point light and the receiver (e^{−σ_a r}), and a
  directional light entering the global medium's box at its top face (the box from the documented model:
  scene bounds + 1 % of the diagonal + 1 mm), an index-matched slab mesh (e^{−σ_t H / cos}), and global
  exponential height fog exported as a `.vol` grid (τ = σ_a (r/Δy)(1 − e^{−bΔy})/b);
- single scattering in a homogeneous slab lit by a normal-incidence sun, at a receiver under the slab,
  against a 1-D Gauss–Legendre quadrature of the closed-form single-scattered radiance;
- the camera: an emitter up and to the right of the view axis shows up and to the right at the pixel the
  pinhole model with the scene's yfov predicts.
"""
import importlib.util
import json
import math
import os
import pathlib
import subprocess
import sys

import numpy as np
import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
VOLTAB = os.environ.get("VOLTAB_BIN", str(ROOT / "target" / "debug" / "voltab"))
K = 683.0
sys.path.insert(0, str(ROOT / "python"))

mitsuba = pytest.importorskip("mitsuba")
from mitsuba_ref.harness import Reference  # noqa: E402


def _load_generator():
    spec = importlib.util.spec_from_file_location("make_scenes", ROOT / "scripts" / "make_scenes.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("make_scenes", mod)
    spec.loader.exec_module(mod)
    return mod


gen = _load_generator()


def export(tmp_path, scene, *extra):
    path = gen.write_gltf(scene, tmp_path / f"{scene.name}.gltf")
    out = tmp_path / "mitsuba"
    r = subprocess.run([VOLTAB, "export", "mitsuba", str(path), "--out", str(out), *extra],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    return Reference(out), json.loads((out / "export.json").read_text())


def black_floor(half=5.0, y=0.0):
    return gen.grid("Floor", (-half, y, half), (2 * half, 0, 0), (0, 0, -2 * half), 1, 1, "Black", lightmap=False)


def scene(name, meshes, materials, lights, medium=None, cameras=()):
    return gen.Scene(name=name, description=name, meshes=meshes, materials=materials, lights=lights,
                     cameras=list(cameras), global_medium=medium)


BLACK = gen.Material("Black", base_color=(0.0, 0.0, 0.0))


def unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


# ------------------------------------------------------------------------------------------------


def test_point_light_irradiance_is_intensity_cos_over_r2(tmp_path):
    light = np.array([0.3, 2.0, -0.4])
    sc = scene("point", [black_floor()], [BLACK], [gen.PointLight("Bulb", tuple(light), (1, 1, 1), 5.0 * K)])
    ref, manifest = export(tmp_path, sc)
    assert manifest["lights"] == [{"name": "Bulb", "kind": "point", "mitsuba": "point"}]
    pts = np.array([[0.0, 0.0, 0.0], [1.5, 0.0, 0.7], [-2.0, 0.0, -1.0], [0.5, 1.0, 0.5], [0.5, 1.0, 0.5]])
    nrm = np.array([[0, 1, 0], [0, 1, 0], [0, 1, 0], unit([1, 1, -1]), [0, -1, 0]], float)
    for depth in (2, -1):
        mean, var = ref.irradiance(pts, nrm, spp=16, max_depth=depth, runs=2)
        for p, n, e in zip(pts, nrm, mean):
            d = light - p
            r = np.linalg.norm(d)
            want = 5.0 * max(0.0, float(np.dot(n, d / r))) / r**2
            assert e == pytest.approx([want] * 3, rel=2e-3, abs=1e-6), (p, n, depth)


def test_directional_irradiance_is_e_cos(tmp_path):
    travel = unit([1.0, -2.0, 0.5])
    sc = scene("sun", [black_floor()], [BLACK], [gen.DirectionalLight("Sun", tuple(travel), (1, 1, 1), 3.0 * K)])
    ref, _ = export(tmp_path, sc)
    nrm = np.array([[0, 1, 0], unit([0.3, 1, 0]), unit([-1, 0.2, 0])], float)
    pts = np.array([[0.0, 0.0, 0.0], [1.0, 0.5, 1.0], [-1.0, 0.5, 0.0]])
    mean, _ = ref.irradiance(pts, nrm, spp=16, max_depth=2, runs=2)
    for n, e in zip(nrm, mean):
        want = 3.0 * max(0.0, float(np.dot(n, -travel)))
        assert e == pytest.approx([want] * 3, rel=2e-3, abs=1e-6), n


def global_box(points):
    """The documented region of a global medium: bounds padded by 1 % of the diagonal + 1 mm."""
    lo, hi = np.min(points, axis=0), np.max(points, axis=0)
    pad = 0.01 * np.linalg.norm(hi - lo) + 1e-3
    return lo - pad, hi + pad


def test_beer_lambert_in_the_global_medium_and_its_box(tmp_path):
    sigma_a = 0.4
    light = np.array([0.0, 2.0, 0.0])
    travel = unit([0.5, -1.0, 0.0])
    fog = gen.Medium(sigma_s=(0.0, 0.0, 0.0), sigma_a=(sigma_a,) * 3, g=0.0)
    sc = scene("absorb", [black_floor()], [BLACK],
               [gen.PointLight("Bulb", tuple(light), (1, 1, 1), 2.0 * K),
                gen.DirectionalLight("Sun", tuple(travel), (1, 1, 1), 1.0 * K)], medium=fog)
    ref, manifest = export(tmp_path, sc)
    lo, hi = global_box(np.array([[-5, 0, -5], [5, 0, 5], light]))
    g = manifest["global_medium"]
    assert g["min"] == pytest.approx(lo.tolist(), abs=1e-9) and g["max"] == pytest.approx(hi.tolist(), abs=1e-9)
    pts = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.5], [-2.0, 0.0, 1.0]])
    nrm = np.tile([0.0, 1.0, 0.0], (3, 1))
    # volpath estimates shadow-ray transmittance by tracking (each path's factor is 0 or 1 in a
    # homogeneous medium): many paths, and a z-test against the runs' own spread.
    mean, var = ref.irradiance(pts, nrm, spp=1 << 15, max_depth=-1, runs=4)
    for p, e, v in zip(pts, mean, var):
        d = light - p
        r = np.linalg.norm(d)
        point = 2.0 * (d[1] / r) / r**2 * math.exp(-sigma_a * r)
        # The sun enters the box at its top face y = hi[1]: path length (hi[1] − y) / cos.
        cos = -travel[1]
        sun = 1.0 * cos * math.exp(-sigma_a * (hi[1] - p[1]) / cos)
        want = point + sun
        print(f"Beer-Lambert at {p}: Mitsuba {e[0]:.5f} ± {math.sqrt(v[0]):.5f}, closed form {want:.5f}")
        assert np.all(np.abs(e - want) < 4 * np.sqrt(v) + 1e-3 * want), (p, e, v, want)


def slab_scene(sigma_s, sigma_a, g, height, lights):
    medium = gen.Medium(sigma_s=(sigma_s,) * 3, sigma_a=(sigma_a,) * 3, g=g)
    slab_mat = gen.Material("Slab", ior=1.0, medium=medium, attenuation_distance=1.0)
    slab = gen.box("Slab", (40.0, height, 40.0), "Slab")
    return scene("slab", [slab], [slab_mat], lights)


def test_beer_lambert_through_an_index_matched_slab(tmp_path):
    H, st = 0.5, 1.2
    light = np.array([0.2, 3.0, -0.1])
    sc = slab_scene(0.7, 0.5, 0.3, H, [gen.PointLight("Bulb", tuple(light), (1, 1, 1), 4.0 * K)])
    ref, manifest = export(tmp_path, sc)
    slab = next(s for s in manifest["shapes"] if s["name"].startswith("Slab"))
    assert (slab["bsdf"], slab["interior"]) == ("null", "medium_0")
    pts = np.array([[0.0, -0.05, 0.0], [1.0, -0.05, 1.0], [-2.0, -0.05, 0.5]])
    nrm = np.tile([0.0, 1.0, 0.0], (3, 1))
    mean, var = ref.irradiance(pts, nrm, spp=1 << 15, max_depth=2, runs=4)
    for p, e, v in zip(pts, mean, var):
        d = light - p
        r = np.linalg.norm(d)
        cos = d[1] / r
        want = 4.0 * cos / r**2 * math.exp(-st * H / cos)
        print(f"slab transmittance at {p}: Mitsuba {e[0]:.5f} ± {math.sqrt(v[0]):.5f}, closed form {want:.5f}")
        assert np.all(np.abs(e - want) < 4 * np.sqrt(v) + 1e-3 * want), (p, e, v, want)


def single_scattering_below_slab(sigma_s, sigma_t, g, H, E0, nodes=400):
    """E₁ at a receiver just below a laterally infinite slab of thickness H (facing up), normal-incidence
    sun of irradiance E0: E₁ = 2π ∫₀¹ L₁(μ) μ dμ with
    L₁(μ) = σ_s E0 p(μ) e^{−σ_t H} (1 − e^{−σ_t H (1−μ)/μ}) / (σ_t (1 − μ)) (scattering angle cos = μ)."""
    x, w = np.polynomial.legendre.leggauss(nodes)
    mu, w = 0.5 * (x + 1.0), 0.5 * w
    p = (1 - g * g) / (4 * math.pi * (1 + g * g - 2 * g * mu) ** 1.5)
    a = sigma_t * H * (1 - mu) / mu
    path = np.where(a > 1e-8, -np.expm1(-a) / (sigma_t * (1 - mu)), H / mu)
    L1 = sigma_s * E0 * p * math.exp(-sigma_t * H) * path
    return 2 * math.pi * float(np.sum(w * L1 * mu))


def test_single_scattering_in_a_homogeneous_slab(tmp_path):
    ss, sa, g, H = 0.6, 0.2, 0.5, 1.0
    sc = slab_scene(ss, sa, g, H, [gen.DirectionalLight("Sun", (0.0, -1.0, 0.0), (1, 1, 1), 1.0 * K)])
    ref, _ = export(tmp_path, sc)
    pts = np.array([[0.0, -0.01, 0.0], [0.7, -0.01, -0.4], [-0.5, -0.01, 0.6], [0.2, -0.01, 0.9]])
    nrm = np.tile([0.0, 1.0, 0.0], (len(pts), 1))
    e0, v0 = ref.irradiance(pts, nrm, spp=1 << 14, max_depth=2, runs=4)
    direct = math.exp(-(ss + sa) * H)
    assert abs(float(e0.mean()) - direct) < 4 * math.sqrt(float(v0.mean()) / e0.size) + 1e-3 * direct
    # Same seed and sample count for both depths: the unscattered parts are the same draws.
    e1, v1 = ref.irradiance(pts, nrm, spp=1 << 14, max_depth=3, runs=4)
    single = e1 - e0
    want = single_scattering_below_slab(ss, ss + sa, g, H, 1.0)
    est = float(single.mean())
    se = math.sqrt(float(v1.mean()) / single.size)
    print(f"single scattering: Mitsuba {est:.5f} ± {se:.5f}, quadrature {want:.5f}")
    assert abs(est - want) < 4 * se + 0.01 * want, (est, se, want)


def test_camera_orientation_and_field_of_view(tmp_path):
    # Camera at the origin looking along −Z (glTF), up +Y: a small emitter up and to the right.
    cam = gen.Camera("Cam", (0.0, 0.0, 0.0), (0.0, 0.0, -1.0), 35.0)
    glow = gen.Material("Glow", base_color=(0, 0, 0), emissive_color=(1.0, 1.0, 1.0), emissive_strength=K)
    c = np.array([0.8, 0.5, -4.0])
    quad = gen.grid("Lamp", tuple(c + [-0.1, -0.1, 0]), (0.2, 0, 0), (0, 0.2, 0), 1, 1, "Glow", lightmap=False)
    sc = scene("camera", [quad], [glow], [], cameras=[cam])
    ref, manifest = export(tmp_path, sc, "--width", "96")
    w, h = manifest["camera"]["width"], manifest["camera"]["height"]
    assert (w, h) == (96, 64)
    img, _ = ref.image(spp=4, max_depth=2, runs=1)
    lum = img.sum(axis=2)
    ys, xs = np.nonzero(lum > 0.5 * lum.max())
    # Pinhole: column from x/−z over tan(yfov/2)·aspect, row from y/−z over tan(yfov/2), row 0 on top.
    t = math.tan(cam.yfov / 2)
    col = (1 + (c[0] / -c[2]) / (t * w / h)) / 2 * w
    row = (1 - (c[1] / -c[2]) / t) / 2 * h
    assert xs.mean() + 0.5 == pytest.approx(col, abs=0.75) and ys.mean() + 0.5 == pytest.approx(row, abs=0.75)
    # The emitter's radiance (1 W/(m²·sr)) seen directly.
    assert img[ys, xs].mean() == pytest.approx(1.0, rel=0.05)


def test_beer_lambert_through_exponential_height_fog_grid(tmp_path):
    # Global fog ρ(y) = 1.0·e^{−1.5 y}, σ_a = 0.8: the grid volume's placement and cell-centre
    # convention decide the optical depth τ = σ_a (r / Δy) ∫₀^{Δy} e^{−b y} dy along each light path.
    sigma_a, b = 0.8, 1.5
    light = np.array([0.1, 2.0, 0.2])
    fog = gen.Medium(sigma_s=(0.0, 0.0, 0.0), sigma_a=(sigma_a,) * 3, g=0.0,
                     density=gen.ExponentialHeight(1.0, b, (0.0, 1.0, 0.0), (0.0, 0.0, 0.0)))
    sc = scene("heightfog", [black_floor()], [BLACK], [gen.PointLight("Bulb", tuple(light), (1, 1, 1), 3.0 * K)],
               medium=fog)
    ref, manifest = export(tmp_path, sc)
    med = manifest["media"][0]
    assert med["mitsuba_type"] == "heterogeneous" and med["grid"]["resolution"][1] >= 60
    pts = np.array([[0.0, 0.0, 0.0], [1.5, 0.0, -1.0], [-2.5, 0.0, 0.5]])
    nrm = np.tile([0.0, 1.0, 0.0], (3, 1))
    mean, var = ref.irradiance(pts, nrm, spp=1 << 15, max_depth=2, runs=4)
    for p, e, v in zip(pts, mean, var):
        d = light - p
        r = np.linalg.norm(d)
        tau = sigma_a * (r / d[1]) * (-math.expm1(-b * d[1])) / b
        want = 3.0 * (d[1] / r) / r**2 * math.exp(-tau)
        print(f"height fog at {p}: Mitsuba {e[0]:.5f} ± {math.sqrt(v[0]):.5f}, closed form {want:.5f}")
        assert np.all(np.abs(e - want) < 4 * np.sqrt(v) + 2e-3 * want), (p, e, v, want)


@pytest.mark.parametrize("name", ["fog_room", "window_room", "translucent", "outdoor"])
def test_bundled_scenes_export_load_and_render(tmp_path, name):
    # Every bundled scene (glTF) exports, loads in Mitsuba and renders a finite, non-empty image; the
    # global medium's box (if any) contains every exported mesh.
    out = tmp_path / "mitsuba"
    r = subprocess.run([VOLTAB, "export", "mitsuba", str(ROOT / "scenes" / f"{name}.gltf"), "--out", str(out),
                        "--width", "32"], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    ref = Reference(out)
    img, var = ref.image(spp=2, runs=2, max_depth=3)
    assert np.all(np.isfinite(img)) and np.all(np.isfinite(var)) and img.mean() > 0, name
    g = ref.manifest["global_medium"]
    if g:
        lo, hi = np.array(g["min"]), np.array(g["max"])
        for s in ref.manifest["shapes"]:
            if s["file"]:
                data = (out / s["file"]).read_bytes()
                head, body = data.split(b"end_header\n", 1)
                nv = int(head.split(b"element vertex ")[1].split(b"\n")[0])
                v = np.frombuffer(body[:nv * 24], "<f4").reshape(nv, 6)[:, :3]
                assert np.all(v >= lo) and np.all(v <= hi), (name, s["name"])
