"""One scene, two formats: voltab must read the same numbers from glTF and from USD.

Each bundled scene is authored fresh by `scripts/make_scenes.py` (one Python description written as
`.usda` with pxr and as `.gltf` + `.bin` with the json module) and read back with
`voltab scene FILE --json`. The checks:

- the two formats agree: counts, bounds, every light (kind, position, direction, converted value),
  media (σ_s, σ_a, g, density, boundary kind), cameras, materials, and neither has warnings;
- values derived here independently of both importers and of the generator's own conversions agree
  with what voltab read: triangle counts and world bounds from pxr's composition of the `.usda`, light
  values from the authored candela / lux / nits over 683 lm/W, medium coefficients from the authored
  σ (USD) and from `−ln(attenuationColor)/attenuationDistance` in the glTF JSON, camera yfov from
  focal length and aperture, light and camera directions from pxr's world transforms;
- a `.usda` converted to `.usdc` by pxr (crate version 0.8.0, which openusd reads) reads identically;
- the committed files under `scenes/` are what the generator writes today;
- broken files (index out of range, negative light intensity, NaN points, an open medium boundary) fail
  with a non-zero exit and a message naming the node or prim, never a panic.
"""
import importlib.util
import json
import math
import os
import pathlib
import struct
import subprocess
import sys

import numpy as np
import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
VOLTAB = os.environ.get("VOLTAB_BIN", str(ROOT / "target" / "debug" / "voltab"))
K = 683.0


def _load_generator():
    spec = importlib.util.spec_from_file_location("make_scenes", ROOT / "scripts" / "make_scenes.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules["make_scenes"] = mod
    spec.loader.exec_module(mod)
    return mod


gen = _load_generator()
NAMES = list(gen.SCENES)


# ------------------------------------------------------------------------------------------------
# helpers
# ------------------------------------------------------------------------------------------------


def run_voltab(path):
    return subprocess.run([VOLTAB, "scene", str(path), "--json"], capture_output=True, text=True, timeout=120)


_summaries = {}


def summary(path):
    """`voltab scene PATH --json`, parsed (cached per path)."""
    key = str(path)
    if key not in _summaries:
        out = run_voltab(path)
        assert out.returncode == 0, f"voltab scene {path} failed:\n{out.stderr}"
        assert "panicked" not in out.stderr, out.stderr
        _summaries[key] = json.loads(out.stdout)
    return _summaries[key]


def without_file(doc):
    return {k: v for k, v in doc.items() if k != "file"}


def close(a, b, rel=1e-6, abs_=1e-12):
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return a.shape == b.shape and bool(np.all(np.abs(a - b) <= np.maximum(rel * np.maximum(np.abs(a), np.abs(b)), abs_)))


def assert_close(a, b, what, rel=1e-6, abs_=1e-12):
    assert close(a, b, rel, abs_), f"{what}: {a} != {b} (rel {rel}, abs {abs_})"


def leaf(name):
    return name.rstrip("/").split("/")[-1]


@pytest.fixture(scope="module")
def authored(tmp_path_factory):
    """Every bundled scene, authored fresh: name → (description, usda path, gltf path)."""
    out = tmp_path_factory.mktemp("scenes")
    result = {}
    for scene in gen.scenes():
        usd, gltf, _ = gen.write_scene(scene, out)
        result[scene.name] = (scene, usd, gltf)
    return result


def pxr_world(usd_path):
    """Independent reading of a .usda with pxr: (triangles, world bounds of points and point lights,
    {light name: (world position, world −Z)}, {camera name: (position, forward)})."""
    from pxr import Gf, Usd, UsdGeom, UsdLux

    stage = Usd.Stage.Open(str(usd_path))
    cache = UsdGeom.XformCache()
    tris, pts, lights, cams = 0, [], {}, {}
    for prim in stage.Traverse():
        m = cache.GetLocalToWorldTransform(prim)
        if prim.IsA(UsdGeom.Mesh):
            mesh = UsdGeom.Mesh(prim)
            tris += sum(c - 2 for c in mesh.GetFaceVertexCountsAttr().Get())
            pts += [m.Transform(Gf.Vec3d(p)) for p in mesh.GetPointsAttr().Get()]
        elif prim.IsA(UsdLux.SphereLight) or prim.IsA(UsdLux.DistantLight) or prim.IsA(UsdGeom.Camera):
            pos = m.Transform(Gf.Vec3d(0, 0, 0))
            fwd = m.TransformDir(Gf.Vec3d(0, 0, -1)).GetNormalized()
            up = m.TransformDir(Gf.Vec3d(0, 1, 0)).GetNormalized()
            if prim.IsA(UsdGeom.Camera):
                cams[prim.GetName()] = (list(pos), list(fwd), list(up))
            else:
                lights[prim.GetName()] = (list(pos), list(fwd))
                if prim.IsA(UsdLux.SphereLight):
                    pts.append(pos)
    pts = np.array([list(p) for p in pts])
    return tris, [pts.min(axis=0).tolist(), pts.max(axis=0).tolist()], lights, cams


def match_lights(a, b):
    """Pairs the lights of two summaries by kind and nearest position (or direction)."""
    assert sorted(l["kind"] for l in a) == sorted(l["kind"] for l in b)
    pairs, rest = [], list(b)
    for la in a:
        key = "position" if la["position"] is not None else "direction"
        cands = [lb for lb in rest if lb["kind"] == la["kind"]]
        lb = min(cands, key=lambda l: float(np.linalg.norm(np.subtract(l[key], la[key]))))
        rest.remove(lb)
        pairs.append((la, lb))
    return pairs


# ------------------------------------------------------------------------------------------------
# the generator alone (pxr, json)
# ------------------------------------------------------------------------------------------------


def test_generator_is_deterministic(authored, tmp_path):
    """The command line (a fresh process, so another string-hash seed) writes the same bytes as the
    in-process authoring of the fixture."""
    out = subprocess.run([sys.executable, str(ROOT / "scripts" / "make_scenes.py"), str(tmp_path)],
                         capture_output=True, text=True, env=dict(os.environ, PYTHONHASHSEED="12345"))
    assert out.returncode == 0, out.stderr
    files = sorted(p.name for p in tmp_path.iterdir())
    assert len(files) == 3 * len(NAMES)
    fresh_dir = authored[NAMES[0]][1].parent
    for f in files:
        assert (tmp_path / f).read_bytes() == (fresh_dir / f).read_bytes(), f


@pytest.mark.parametrize("name", NAMES)
def test_generated_files_are_small_and_valid(authored, name):
    scene, usd, gltf = authored[name]
    tris_pxr, _, _, _ = pxr_world(usd)
    doc = gen.validate_gltf(gltf)
    tris_gltf = sum(doc["accessors"][p["indices"]]["count"] // 3 for m in doc["meshes"] for p in m["primitives"])
    # triangle count from the description's polygons: a quad is two triangles
    tris_desc = sum(int(np.sum(m.counts - 2)) for m in scene.meshes)
    assert tris_pxr == tris_gltf == tris_desc < 20000
    assert any(int(c) == 4 for m in scene.meshes for c in m.counts), "quads exercise triangulation"
    for p in (usd, gltf, gltf.with_suffix(".bin")):
        assert p.stat().st_size < 1 << 20, p
    for m in scene.meshes:
        if scene.material(m.material).medium is None:
            assert m.st1 is not None, f"{m.name} lacks lightmap UVs"


def test_validator_rejects_broken_gltf(authored, tmp_path):
    _, _, gltf = authored["translucent"]
    doc = json.loads(gltf.read_text())
    (tmp_path / doc["buffers"][0]["uri"]).write_bytes(gltf.with_suffix(".bin").read_bytes()[:-4])
    (tmp_path / "t.gltf").write_text(json.dumps(doc))
    with pytest.raises(gen.InvalidScene, match="byteLength"):
        gen.validate_gltf(tmp_path / "t.gltf")


def test_wax_sphere_is_a_closed_manifold_of_a_few_to_tens_of_mean_free_paths(authored):
    scene, _, gltf = authored["translucent"]
    sphere = next(m for m in scene.meshes if m.name == "wax_sphere")
    tris = sphere.triangles()
    assert 1000 <= len(tris) <= 5000
    assert gen.closed_manifold(tris, sphere.points)
    assert len(np.unique(sphere.points, axis=0)) == len(sphere.points), "vertices are welded"
    # Euler characteristic of a sphere: V − E + F = 2
    assert len(sphere.points) - len(tris) * 3 // 2 + len(tris) == 2
    wax = json.loads(gltf.read_text())["materials"][1]
    vol = wax["extensions"]["KHR_materials_volume"]
    sigma_t = [-math.log(c) / vol["attenuationDistance"] for c in vol["attenuationColor"]]
    diameter = float(np.ptp(sphere.points[:, 0]))
    assert all(3 <= diameter * t <= 50 for t in sigma_t), (diameter, sigma_t)


def test_vendor_extension_objects_match_the_schema(authored):
    """Every VOLTAB_participating_media object the generator writes validates against the committed
    JSON Schema (docs/design/scene.md names it), and the schema is not vacuous."""
    import jsonschema

    schema = json.loads((ROOT / "schemas" / "VOLTAB_participating_media.schema.json").read_text())
    objects = []
    for _, _, gltf in authored.values():
        doc = json.loads(gltf.read_text())
        for holder in doc["materials"] + [doc]:
            ext = holder.get("extensions", {}).get("VOLTAB_participating_media")
            if ext is not None:
                objects.append(ext)
    assert len(objects) == 4  # the wax material and three global media
    for obj in objects:
        jsonschema.validate(obj, schema)
    for bad in ({"global": {"sigmaS": [0.1, 0.1]}}, {"scatteringAlbedo": [0.5, 0.5, 1.5]}, {"sigmaS": [1, 1, 1]}):
        with pytest.raises(jsonschema.ValidationError):
            jsonschema.validate(bad, schema)


def test_committed_scenes_are_what_the_generator_writes(authored):
    from pxr import Sdf

    committed = ROOT / "scenes"
    for name, (_, usd, gltf) in authored.items():
        for fresh in (gltf, gltf.with_suffix(".bin")):
            assert (committed / fresh.name).read_bytes() == fresh.read_bytes(), (
                f"scenes/{fresh.name} is stale: run .venv/bin/python scripts/make_scenes.py")
        # USD text formatting may change between usd-core releases: compare as pxr reads them
        a = Sdf.Layer.FindOrOpen(str(committed / usd.name)).ExportToString()
        b = Sdf.Layer.FindOrOpen(str(usd)).ExportToString()
        assert a == b, f"scenes/{usd.name} is stale: run .venv/bin/python scripts/make_scenes.py"
    assert (committed / "README.md").is_file()


# ------------------------------------------------------------------------------------------------
# voltab: both formats agree
# ------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", NAMES)
def test_formats_agree(authored, name):
    _, usd, gltf = authored[name]
    u, g = summary(usd), summary(gltf)
    assert (u["format"], g["format"]) == ("Usd", "Gltf")
    assert u["counts"] == g["counts"]
    diag = g["diagonal"]
    assert_close(u["bounds"], g["bounds"], "bounds", rel=1e-5, abs_=1e-5 * diag)
    assert_close(u["diagonal"], diag, "diagonal", rel=1e-5)
    assert u["warnings"] == [] and g["warnings"] == [], (u["warnings"], g["warnings"])
    assert u["meshes_without_lightmap_uv"] == [] and g["meshes_without_lightmap_uv"] == []

    for lu, lg in match_lights(u["lights"], g["lights"]):
        what = f"{name}: light {lu['name']} / {lg['name']}"
        assert lu["kind"] == lg["kind"] and lu["quantity"] == lg["quantity"], what
        for key in ("position", "direction"):
            assert (lu[key] is None) == (lg[key] is None), f"{what}: {key}"
            if lu[key] is not None:
                assert_close(lu[key], lg[key], f"{what}: {key}", rel=1e-6, abs_=1e-6 * max(1.0, diag))
        assert_close(lu["value"], lg["value"], f"{what}: value")
        for key in ("area", "power"):
            assert (lu[key] is None) == (lg[key] is None), f"{what}: {key}"
            if lu[key] is not None:
                assert_close(lu[key], lg[key], f"{what}: {key}", rel=1e-5)

    assert len(u["media"]) == len(g["media"])
    by_kind = lambda media: sorted(media, key=lambda m: m["boundary"] != "global")  # noqa: E731
    for mu, mg in zip(by_kind(u["media"]), by_kind(g["media"])):
        what = f"{name}: medium {mu['name']} / {mg['name']}"
        assert (mu["boundary"] == "global") == (mg["boundary"] == "global"), what
        assert mu["interface"] == mg["interface"], what
        for key in ("sigma_s", "sigma_a", "sigma_t", "albedo", "g"):
            assert_close(mu[key], mg[key], f"{what}: {key}")
        du, dg = mu["density"], mg["density"]
        if du == "Homogeneous" or dg == "Homogeneous":
            assert du == dg, what
        else:
            eu, eg = du["ExponentialHeight"], dg["ExponentialHeight"]
            for key in ("rho", "falloff", "direction", "offset"):
                assert_close(eu[key], eg[key], f"{what}: density {key}")

    assert len(u["cameras"]) == len(g["cameras"])
    for cu, cg in zip(u["cameras"], g["cameras"]):
        what = f"{name}: camera {cu['name']}"
        for key in ("position", "forward", "up"):
            assert_close(cu[key], cg[key], f"{what}: {key}", abs_=1e-6 * max(1.0, diag))
        assert_close(cu["znear"], cg["znear"], f"{what}: znear")
        assert_close(cu["zfar"], cg["zfar"], f"{what}: zfar")
        pu, pg = cu["projection"]["Perspective"], cg["projection"]["Perspective"]
        assert_close(pu["yfov"], pg["yfov"], f"{what}: yfov")
        assert_close(pu["aspect"], pg["aspect"], f"{what}: aspect")

    mats_u = {leaf(m["name"]): m for m in u["materials"]}
    mats_g = {leaf(m["name"]): m for m in g["materials"]}
    assert mats_u.keys() == mats_g.keys()
    for key, mu in mats_u.items():
        mg = mats_g[key]
        for field in ("base_color", "emission", "roughness"):
            assert_close(mu[field], mg[field], f"{name}: material {key}: {field}")
        assert mu["surface"] == mg["surface"], f"{name}: material {key}: surface"


# ------------------------------------------------------------------------------------------------
# voltab: independently derived values
# ------------------------------------------------------------------------------------------------


def _expected_lights(scene):
    """(kind, position or None, direction or None, value, area or None) from the description."""
    out = []
    for light in scene.lights:
        if isinstance(light, gen.PointLight):
            out.append(("point", light.position, None, [c * light.candela / K for c in light.color], None))
        else:
            d = np.asarray(light.direction) / np.linalg.norm(light.direction)
            out.append(("directional", None, d.tolist(), [c * light.lux / K for c in light.color], None))
    for mesh in scene.meshes:
        mat = scene.material(mesh.material)
        if mat.emissive_color is None:
            continue
        # emissive meshes here are planar rectangles authored in world space: centre and area of the corners
        assert mesh.xform is None and mesh.parent is None
        p = mesh.points.astype(float)
        lo, hi = p.min(axis=0), p.max(axis=0)
        ext = sorted(hi - lo)
        out.append(("emissive_mesh", ((lo + hi) / 2).tolist(), None,
                    [c * mat.emissive_strength / K for c in mat.emissive_color], ext[1] * ext[2]))
    return out


@pytest.mark.parametrize("fmt", ["usda", "gltf"])
@pytest.mark.parametrize("name", NAMES)
def test_values_match_the_authored_description(authored, name, fmt):
    scene, usd, gltf = authored[name]
    s = summary(usd if fmt == "usda" else gltf)
    tris, bounds, pxr_lights, pxr_cams = pxr_world(usd)
    assert s["counts"]["triangles"] == tris
    assert s["counts"]["meshes"] == len(scene.meshes)
    assert_close(s["bounds"], bounds, "bounds from pxr", rel=1e-5, abs_=1e-5 * s["diagonal"])

    expected = _expected_lights(scene)
    assert len(s["lights"]) == len(expected)
    rest = list(s["lights"])
    for kind, pos, direction, value, area in expected:
        cands = [l for l in rest if l["kind"] == kind]
        assert cands, f"no {kind} light left"
        got = min(cands, key=lambda l: float(np.linalg.norm(np.subtract(l["position"] or l["direction"], pos or direction))))
        rest.remove(got)
        what = f"{name}.{fmt}: {kind} {got['name']}"
        assert_close(got["value"], value, f"{what}: value")
        if pos is not None:
            assert_close(got["position"], pos, f"{what}: position", abs_=1e-6 * max(1.0, s["diagonal"]))
        if direction is not None:
            assert_close(got["direction"], direction, f"{what}: direction", abs_=2e-6)
        if area is not None:
            assert_close(got["area"], area, f"{what}: area", rel=1e-5)
            assert_close(got["power"], [math.pi * v * area for v in value], f"{what}: power", rel=1e-5)
        if kind == "point":
            assert_close(got["power"], [4 * math.pi * v for v in value], f"{what}: power")

    # the generator's quaternions put light and camera axes where the description says (pxr composes them)
    for light in scene.lights:
        pos, fwd = pxr_lights[light.name]
        if isinstance(light, gen.DirectionalLight):
            assert_close(fwd, np.asarray(light.direction) / np.linalg.norm(light.direction), "pxr sun", abs_=1e-9)
        else:
            assert_close(pos, light.position, "pxr light position", abs_=1e-9)

    media = {("global" if m["boundary"] == "global" else "mesh"): m for m in s["media"]}
    expected_media = {}
    if scene.global_medium is not None:
        expected_media["global"] = scene.global_medium
    for mesh in scene.meshes:
        mat = scene.material(mesh.material)
        if mat.medium is not None:
            expected_media["mesh"] = mat.medium
    assert media.keys() == expected_media.keys()
    for kind, m in expected_media.items():
        what = f"{name}.{fmt}: {kind} medium"
        assert_close(media[kind]["sigma_s"], m.sigma_s, f"{what}: sigma_s")
        assert_close(media[kind]["sigma_a"], m.sigma_a, f"{what}: sigma_a")
        assert_close(media[kind]["g"], [m.g] * 3, f"{what}: g")
        if m.density is None:
            assert media[kind]["density"] == "Homogeneous"
        else:
            d = media[kind]["density"]["ExponentialHeight"]
            assert_close([d["rho"], d["falloff"]], [m.density.rho, m.density.falloff], f"{what}: density")
            assert_close(d["direction"] + d["offset"], list(m.density.direction) + list(m.density.offset), what, abs_=1e-9)
    if "mesh" in media:
        assert media["mesh"]["interface"] == "refractive (ior 1.5)"

    assert len(s["cameras"]) == len(scene.cameras)
    for cam, got in zip(scene.cameras, s["cameras"]):
        what = f"{name}.{fmt}: camera"
        yfov = 2 * math.atan(24.0 / (2 * cam.focal_mm))  # 24 mm vertical aperture
        assert_close(got["projection"]["Perspective"]["yfov"], yfov, f"{what}: yfov")
        assert_close(got["projection"]["Perspective"]["aspect"], 1.5, f"{what}: aspect")
        assert_close(got["position"], cam.position, f"{what}: position", abs_=1e-6 * max(1.0, s["diagonal"]))
        fwd = np.subtract(cam.target, cam.position)
        assert_close(got["forward"], fwd / np.linalg.norm(fwd), f"{what}: forward", abs_=2e-6)
        _, pfwd, pup = pxr_cams[cam.name]
        assert_close(got["up"], pup, f"{what}: up", abs_=2e-6)
        assert abs(float(np.dot(got["up"], got["forward"]))) < 1e-6 and got["up"][1] > 0
        assert_close([got["znear"], got["zfar"]], [cam.znear, cam.zfar], f"{what}: clipping")


def test_wax_coefficients_follow_the_khronos_attenuation_formula(authored):
    """σ_t = −ln(attenuationColor)/attenuationDistance as written in the glTF JSON, split by the vendor
    extension's albedo; the USD file authors σ_s and σ_a directly: voltab must land on the same numbers."""
    _, usd, gltf = authored["translucent"]
    mat = next(m for m in json.loads(gltf.read_text())["materials"] if m["name"] == "wax")
    vol, vendor = mat["extensions"]["KHR_materials_volume"], mat["extensions"]["VOLTAB_participating_media"]
    sigma_t = [-math.log(c) / vol["attenuationDistance"] for c in vol["attenuationColor"]]
    albedo = vendor["scatteringAlbedo"]
    for path in (usd, gltf):
        (m,) = [m for m in summary(path)["media"] if m["boundary"] != "global"]
        assert_close(m["sigma_t"], sigma_t, f"{path.name}: sigma_t")
        assert_close(m["sigma_s"], [a * t for a, t in zip(albedo, sigma_t)], f"{path.name}: sigma_s")
        assert_close(m["sigma_a"], [(1 - a) * t for a, t in zip(albedo, sigma_t)], f"{path.name}: sigma_a", rel=2e-6)
        assert_close(m["g"], [vendor["anisotropy"]] * 3, f"{path.name}: g")


def test_committed_scenes_read_like_fresh_ones(authored):
    for name, (_, usd, gltf) in authored.items():
        for fresh in (usd, gltf):
            assert without_file(summary(ROOT / "scenes" / fresh.name)) == without_file(summary(fresh)), fresh.name


# ------------------------------------------------------------------------------------------------
# voltab: usda → usdc round trip
# ------------------------------------------------------------------------------------------------

USDC_CONVERT = "import sys; from pxr import Sdf; assert Sdf.Layer.FindOrOpen(sys.argv[1]).Export(sys.argv[2])"


@pytest.mark.parametrize("name", NAMES)
def test_usdc_round_trip_reads_identically(authored, name, tmp_path):
    _, usd, _ = authored[name]
    out = tmp_path / f"{name}.usdc"
    usdcat = ROOT / ".venv" / "bin" / "usdcat"
    # openusd reads crate files up to 0.12; newer usd-core may default to 0.13
    env = dict(os.environ, USD_WRITE_NEW_USDC_FILES_AS_VERSION="0.8.0")
    cmd = [str(usdcat), str(usd), "-o", str(out)] if usdcat.exists() else [sys.executable, "-c", USDC_CONVERT, str(usd), str(out)]
    subprocess.run(cmd, check=True, env=env, capture_output=True)
    head = out.read_bytes()[:16]
    assert head[:8] == b"PXR-USDC" and tuple(head[8:11]) <= (0, 12, 0), head
    assert without_file(summary(out)) == without_file(summary(usd))


# ------------------------------------------------------------------------------------------------
# voltab: broken files fail cleanly, naming the culprit
# ------------------------------------------------------------------------------------------------


def _base(name):
    return gen.Scene(
        name=name, description="broken on purpose", materials=[gen.Material("grey")],
        meshes=[gen.grid("ground", (-1, 0, 1), (2, 0, 0), (0, 0, -2), 2, 2, "grey")],
        lights=[gen.PointLight("lamp", (0.0, 1.0, 0.0), (1.0, 1.0, 1.0), 10.0)],
        cameras=[gen.Camera("camera", (0.0, 1.0, 3.0), (0.0, 0.0, 0.0), 35.0)])


def _index_out_of_range(fmt, path):
    scene = _base("bad_index")
    tri = gen.grid("broken_tri", (0, 0.5, 0), (1, 0, 0), (0, 1, 0), 1, 1, "grey")
    tri.indices = np.array([0, 1, 2, 7], dtype=np.int32)  # the mesh has 4 vertices
    scene.meshes.append(tri)
    return scene, "broken_tri", "/World/broken_tri"


def _negative_intensity(fmt, path):
    scene = _base("negative_light")
    scene.lights.append(gen.PointLight("negative_lamp", (0.5, 1.0, 0.0), (1.0, 1.0, 1.0), -25.0))
    return scene, "negative_lamp", "/World/negative_lamp"


def _nan_points(fmt, path):
    scene = _base("nan_points")
    quad = gen.grid("nan_mesh", (0, 0.5, 0), (1, 0, 0), (0, 1, 0), 1, 1, "grey")
    quad.points = quad.points.copy()
    quad.points[2, 1] = np.nan
    scene.meshes.append(quad)
    return scene, "nan_mesh", "/World/nan_mesh"


def _open_medium_box(fmt, path):
    scene = _base("open_box")
    scene.materials.append(gen.Material("fog_in_box", ior=1.0, medium=gen.Medium((1.0, 1.0, 1.0), (0.1, 0.1, 0.1), 0.0)))
    b = gen.box("open_box", (0.5, 0.5, 0.5), "fog_in_box")
    b.counts, b.indices = b.counts[:5], b.indices[:20]  # drop the −Z face
    scene.meshes.append(b)
    return scene, "open_box", "/World/open_box"


def _write_unvalidated(scene, fmt, path):
    if fmt == "usda":
        gen.write_usd(scene, path)
        return
    nan_mesh = next((m for m in scene.meshes if np.isnan(m.points).any()), None)
    if nan_mesh is not None:  # JSON has no NaN: author finite min/max, then poison the binary buffer
        poisoned = nan_mesh.points.copy()
        nan_mesh.points = np.nan_to_num(poisoned)
    doc, data = gen.build_gltf(scene, path.with_suffix(".bin").name)
    if nan_mesh is not None:
        mi = next(i for i, m in enumerate(doc["meshes"]) if m["name"] == nan_mesh.name)
        acc = doc["accessors"][doc["meshes"][mi]["primitives"][0]["attributes"]["POSITION"]]
        view = doc["bufferViews"][acc["bufferView"]]
        data = bytearray(data)
        struct.pack_into("<f", data, view["byteOffset"] + (2 * 3 + 1) * 4, float("nan"))
        data = bytes(data)
    gen.write_gltf_doc(doc, data, path)


@pytest.mark.parametrize("fmt", ["gltf", "usda"])
@pytest.mark.parametrize("case", [_index_out_of_range, _negative_intensity, _nan_points, _open_medium_box],
                         ids=["index_out_of_range", "negative_intensity", "nan_points", "open_medium_boundary"])
def test_broken_scene_fails_naming_the_culprit(case, fmt, tmp_path):
    path = tmp_path / f"broken.{fmt}"
    scene, node, prim = case(fmt, path)
    _write_unvalidated(scene, fmt, path)
    out = run_voltab(path)
    assert out.returncode != 0, f"voltab accepted {case.__name__} ({fmt}):\n{out.stdout[:2000]}"
    assert (prim if fmt == "usda" else node) in out.stderr, out.stderr
    for text in ("panicked", "RUST_BACKTRACE", "stack backtrace"):
        assert text not in out.stderr, out.stderr


def test_the_base_of_the_broken_scenes_is_fine(tmp_path):
    """Without the defect the scene loads in both formats: the failures above are the defect's."""
    scene = _base("fine")
    for fmt in ("gltf", "usda"):
        path = tmp_path / f"fine.{fmt}"
        _write_unvalidated(scene, fmt, path)
        assert run_voltab(path).returncode == 0, run_voltab(path).stderr
