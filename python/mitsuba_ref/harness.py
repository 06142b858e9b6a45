"""The reference computations behind `python -m mitsuba_ref`.

Request (JSON; paths relative to the request file):
    {"export": "DIR", "out": "result.json", "variant": "auto", "runs": 4, "seed": 0, "rr_depth": null,
     "queries": [
        {"kind": "image", "name": "view", "spp": 16, "width": 64, "height": 48, "max_depth": [-1]},
        {"kind": "irradiance", "name": "texels", "points": [[x, y, z], ...], "normals": [[...], ...],
         "spp": 256, "max_depth": [2, -1]},
        {"kind": "radiance", "name": "rays", "origins": [...], "directions": [...], "spp": 64,
         "max_depth": [-1]}]}
A query may also carry `"minus_depth": k` (the estimate at max_depth k, from other seeds, is subtracted:
light of exactly the orders between, e.g. max_depth [2] minus 1 = single scattering and single surface
reflection without directly visible emitters), or `"minus_export": "DIR"` (the same query on another
export, e.g. the scene with its media's scattering turned into absorption, is subtracted) and `"methods": [{"name": ..., "values": [[r, g, b], ...]}]`
(one RGB value per item, pixels row-major for images; a method that is itself a Monte-Carlo estimate adds
`"variance": [[r, g, b], ...]`, the variance of each value, and its noise is subtracted as well): each is
compared with the reference by
`compare.noise_corrected` into the result's `comparisons` (images with `"block": b` as means over b × b
pixel blocks, so that a noisy reference still resolves the error at that scale).
Result (`out`): per query and max_depth, `mean` (per item, RGB) and `var_of_mean` (the variance of the
mean over the runs, i.e. sample variance / runs), the run count, the seconds spent; images also as EXR
files beside `out` (`<stem>_<name>_d<max_depth>_mean.exr` and `..._var.exr`). Every file is written to a
temporary name and renamed.

**max_depth** is Mitsuba volpath's: a path's depth counts every real scattering event in a medium and
every non-null surface event. For images and radiance rays, light that underwent k events (the visible
surface included) is counted iff k <= max_depth - 1. For irradiance the probe (below) is one extra event:
light that scattered k times before reaching the point is counted iff k <= max_depth - 2 (max_depth 2:
unscattered light only). -1: all orders.

**Irradiance** E = ∫ L cos dω at (p, n) is measured as π × the radiance leaving a white Lambertian probe:
a small square of reflectance 1 facing n at p + δn (δ = 1e-4 × the scene's diagonal, at least 0.1 mm),
seen by a ray from p + 2δn along -n. Its reflected radiance is exactly E/π (Lambertian: f = 1/π), and
volpath estimates it with its own next-event estimation to every light, delta lights included (an
`irradiancemeter` cannot see point, spot or directional lights, which have no next-event partner at the
sensor), its own media transport and MIS: nothing of the estimator is ours except the probe geometry.
The probe occludes a square of side 2δ around itself (negligible unless two points are within δ) and
its first ray segment (length δ) is in vacuum.
"""
import json
import math
import os
import pathlib
import tempfile
import time

import numpy as np

from . import compare as _compare
from . import variant as _variant


class RequestError(Exception):
    """A request names something that does not exist or is malformed."""


def _atomic_write_text(path, text):
    path = pathlib.Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".tmp-", suffix=path.suffix)
    with os.fdopen(fd, "w", encoding="utf-8") as f:
        f.write(text)
    os.replace(tmp, path)


def _ply_quads(centres, normals, half):
    """Binary PLY bytes of one square per point (two triangles, counter-clockwise seen from n)."""
    n = len(centres)
    verts = np.zeros((4 * n, 6), np.float32)
    faces = []
    for i, (c, nn) in enumerate(zip(centres, normals)):
        nn = np.asarray(nn, float) / np.linalg.norm(nn)
        helper = np.array([1.0, 0.0, 0.0]) if abs(nn[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        t = np.cross(helper, nn)
        t /= np.linalg.norm(t)
        b = np.cross(nn, t)
        for k, (su, sv) in enumerate([(-1, -1), (1, -1), (1, 1), (-1, 1)]):
            verts[4 * i + k, :3] = np.asarray(c) + half * (su * t + sv * b)
            verts[4 * i + k, 3:] = nn
        faces += [(4 * i, 4 * i + 1, 4 * i + 2), (4 * i, 4 * i + 2, 4 * i + 3)]
    header = (
        "ply\nformat binary_little_endian 1.0\n"
        f"element vertex {4 * n}\nproperty float x\nproperty float y\nproperty float z\n"
        "property float nx\nproperty float ny\nproperty float nz\n"
        f"element face {len(faces)}\nproperty list uchar int vertex_indices\nend_header\n"
    ).encode()
    body = verts.astype("<f4").tobytes()
    face_dtype = np.dtype([("n", "u1"), ("i", "<i4", (3,))])
    fa = np.zeros(len(faces), face_dtype)
    fa["n"] = 3
    fa["i"] = np.asarray(faces, np.int32)
    return header + body + fa.tobytes()


class Reference:
    """One exported scene loaded in Mitsuba, with the queries of the module doc."""

    def __init__(self, export_dir, variant="auto"):
        self.dir = pathlib.Path(export_dir)
        manifest_path = self.dir / "export.json"
        if not manifest_path.is_file():
            raise RequestError(f"{manifest_path}: no export here; run `voltab export mitsuba SCENE --out {self.dir}` first")
        self.manifest = json.loads(manifest_path.read_text(encoding="utf-8"))
        self.xml_path = self.dir / self.manifest["scene_xml"]
        self.mi = _variant.select(variant)
        self.variant = self.mi.variant()
        self.scalar = self.variant.startswith("scalar")
        self._scenes = {}
        lo, hi = self._bounds()
        self.diagonal = float(np.linalg.norm(np.asarray(hi) - np.asarray(lo))) if lo is not None else 1.0

    def _bounds(self):
        g = self.manifest.get("global_medium")
        if g:
            return g["min"], g["max"]
        return None, None

    # -- loading ------------------------------------------------------------------------------------

    def scene(self, max_depth=-1, rr_depth=None, width=None, height=None, extra_xml=""):
        """The scene with these load-time parameters (cached)."""
        cam = self.manifest.get("camera") or {}
        params = {
            "max_depth": int(max_depth),
            "rr_depth": int(rr_depth if rr_depth is not None else (max_depth if max_depth > 0 else 5)),
        }
        if cam:
            params["width"] = int(width or cam["width"])
            params["height"] = int(height or cam["height"])
        key = (tuple(sorted(params.items())), extra_xml)
        if key not in self._scenes:
            self._scenes[key] = self._load(params, extra_xml)
        return self._scenes[key]

    def _load(self, params, extra_xml):
        if not extra_xml:
            return self.mi.load_file(str(self.xml_path), **params)
        text = self.xml_path.read_text(encoding="utf-8")
        end = text.rindex("</scene>")
        fd, tmp = tempfile.mkstemp(dir=self.dir, prefix=".probe-", suffix=".xml")
        try:
            with os.fdopen(fd, "w", encoding="utf-8") as f:
                f.write(text[:end] + extra_xml + text[end:])
            return self.mi.load_file(tmp, **params)
        finally:
            os.unlink(tmp)

    # -- media at points ----------------------------------------------------------------------------

    def media_at(self, points, directions=None):
        """Mitsuba id of the medium containing each point (None: vacuum), found by walking a ray from the
        point to the first surface that changes media (inside if the ray leaves through it)."""
        import drjit as dr

        mi = self.mi
        scene = self.scene()
        trans = {s["id"]: s for s in self.manifest["shapes"] if s.get("interior") or s.get("exterior")}
        shapes = [s for s in scene.shapes() if s.id() in trans]
        out = []
        d0 = np.array([0.5773502691896258, 0.5773502691896257, 0.5773502691896259])
        for i, p in enumerate(points):
            d = np.asarray(directions[i], float) if directions is not None else d0
            d = d / np.linalg.norm(d)
            ray = mi.Ray3f(mi.ScalarPoint3f(*map(float, p)) if self.scalar else mi.Point3f(*map(float, p)),
                           mi.ScalarVector3f(*map(float, d)) if self.scalar else mi.Vector3f(*map(float, d)))
            found = None
            for _ in range(256):
                si = scene.ray_intersect(ray)
                if not bool(np.asarray(si.is_valid()).reshape(-1)[0]):
                    break
                sid = None
                for sh in shapes:
                    if bool(np.asarray(si.shape == (sh if self.scalar else mi.ShapePtr(sh))).reshape(-1)[0]):
                        sid = sh.id()
                        break
                if sid is not None:
                    leaving = float(np.asarray(dr.dot(ray.d, si.n)).reshape(-1)[0]) > 0
                    found = trans[sid]["interior"] if leaving else trans[sid]["exterior"]
                    break
                ray = si.spawn_ray(ray.d)
            out.append(found)
        return out

    # -- estimators ---------------------------------------------------------------------------------

    def _trace(self, scene, origins, directions, spp, seed, medium=None):
        """Mean radiance over `spp` paths per ray (n × 3 array) for one seed."""
        mi = self.mi
        integrator = scene.integrator()
        sampler = mi.load_dict({"type": "independent"})
        n = len(origins)
        if self.scalar:
            out = np.zeros((n, 3))
            for i in range(n):
                acc = np.zeros(3)
                for s in range(spp):
                    sampler.seed(seed * 1_000_003 + i * spp + s)
                    ray = mi.RayDifferential3f(mi.ScalarPoint3f(*origins[i]), mi.ScalarVector3f(*directions[i]))
                    L, _, _ = integrator.sample(scene, sampler, ray, medium)
                    acc += np.array([L[0], L[1], L[2]])
                out[i] = acc / spp
            return out
        total = n * spp
        o = np.repeat(np.asarray(origins, np.float64), spp, axis=0)
        d = np.repeat(np.asarray(directions, np.float64), spp, axis=0)
        sampler.seed(seed, total)
        ray = mi.RayDifferential3f(mi.Point3f(o[:, 0], o[:, 1], o[:, 2]), mi.Vector3f(d[:, 0], d[:, 1], d[:, 2]))
        L, _, _ = integrator.sample(scene, sampler, ray, medium)
        arr = np.stack([np.asarray(L[0]), np.asarray(L[1]), np.asarray(L[2])], axis=1).reshape(n, spp, 3)
        return arr.mean(axis=1)

    def _runs(self, fn, runs, seed):
        vals = np.stack([fn(seed + r) for r in range(runs)])
        mean = vals.mean(axis=0)
        var = vals.var(axis=0, ddof=1) / runs if runs > 1 else np.full_like(mean, np.nan)
        return mean, var

    def irradiance(self, points, normals, spp=256, max_depth=-1, runs=4, seed=0, rr_depth=None):
        """Irradiance [W/m²] at each (point, unit normal), RGB: (mean, variance of the mean)."""
        points = np.asarray(points, float).reshape(-1, 3)
        normals = np.asarray(normals, float).reshape(-1, 3)
        normals = normals / np.linalg.norm(normals, axis=1, keepdims=True)
        delta = max(1e-4 * self.diagonal, 1e-4)
        centres = points + delta * normals
        media = self.media_at(centres + delta * normals, normals)
        groups = {}
        for i, m in enumerate(media):
            groups.setdefault(m, []).append(i)
        extra = []
        for k, (m, idx) in enumerate(sorted(groups.items(), key=lambda kv: str(kv[0]))):
            name = f".probes-{os.getpid()}-{k}.ply"
            (self.dir / name).write_bytes(_ply_quads(centres[idx], normals[idx], delta))
            ext = f'<ref name="exterior" id="{m}"/>' if m else ""
            extra.append(
                f'<shape type="ply" id="voltab_probe_{k}"><string name="filename" value="{name}"/>'
                f'<boolean name="face_normals" value="true"/>'
                f'<bsdf type="diffuse"><rgb name="reflectance" value="1, 1, 1"/></bsdf>{ext}</shape>\n'
            )
        try:
            scene = self.scene(max_depth, rr_depth, extra_xml="".join(extra))
        finally:
            for k in range(len(groups)):
                p = self.dir / f".probes-{os.getpid()}-{k}.ply"
                if p.exists():
                    p.unlink()
        origins = centres + delta * normals
        mean, var = self._runs(lambda s: self._trace(scene, origins, -normals, spp, s), runs, seed)
        return math.pi * mean, math.pi**2 * var

    def radiance(self, origins, directions, spp=64, max_depth=-1, runs=4, seed=0, rr_depth=None):
        """Radiance [W/(m²·sr)] arriving at each origin from along its direction (the ray's integral,
        media included), RGB: (mean, variance of the mean)."""
        origins = np.asarray(origins, float).reshape(-1, 3)
        dirs = np.asarray(directions, float).reshape(-1, 3)
        dirs = dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
        scene = self.scene(max_depth, rr_depth)
        media = self.media_at(origins, dirs)
        objects = self._medium_objects(scene)
        mean = np.zeros((len(origins), 3))
        var = np.zeros((len(origins), 3))
        for m in set(media):
            idx = [i for i, x in enumerate(media) if x == m]
            med = objects.get(m) if m else None
            mu, v = self._runs(lambda s: self._trace(scene, origins[idx], dirs[idx], spp, s, med), runs, seed)
            mean[idx], var[idx] = mu, v
        return mean, var

    def _medium_objects(self, scene):
        out = {}
        for sh in scene.shapes():
            for med in (sh.interior_medium(), sh.exterior_medium()):
                if med is not None and med.id():
                    out[med.id()] = med
        return out

    def image(self, spp=16, max_depth=-1, runs=4, seed=0, width=None, height=None, rr_depth=None):
        """The camera's image (H × W × 3): (mean, variance of the mean)."""
        if not self.manifest.get("camera"):
            raise RequestError(f"{self.dir}: the export has no camera; export with --camera NAME")
        scene = self.scene(max_depth, rr_depth, width, height)
        return self._runs(lambda s: np.asarray(self.mi.render(scene, spp=spp, seed=s)), runs, seed)


def _write_exr(mi, path, array):
    path = pathlib.Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".tmp-", suffix=".exr")
    os.close(fd)
    mi.Bitmap(np.ascontiguousarray(array, dtype=np.float32)).write(tmp)
    os.replace(tmp, path)


def _blocks(values, height, width, b):
    """Means over b × b pixel blocks (the image cropped to whole blocks), as (n, 3)."""
    a = np.asarray(values, float).reshape(height, width, 3)
    h, w = height // b * b, width // b * b
    return a[:h, :w].reshape(h // b, b, w // b, b, 3).mean(axis=(1, 3)).reshape(-1, 3)


def _comparison(method, mean, var, block=1, query=None):
    """One method's values against the reference (mean, variance of the mean), or why not; images with
    `block` > 1 are compared as means over block × block pixels (the variance of a block mean is the
    mean variance / b², the pixels' estimates being independent)."""
    try:
        a, r, vr = method["values"], np.asarray(mean).reshape(-1, 3), np.asarray(var).reshape(-1, 3)
        va = np.asarray(method["variance"], float).reshape(-1, 3) if method.get("variance") is not None else None
        if block and block > 1:
            h, w = int(query["height"]), int(query["width"])
            a, r, vr = _blocks(a, h, w, block), _blocks(r, h, w, block), _blocks(vr, h, w, block) / block**2
            va = None if va is None else _blocks(va, h, w, block) / block**2
        c = _compare.noise_corrected(a, r, vr, va)
    except (KeyError, ValueError) as e:
        return {"method": method.get("name"), "error": str(e)}
    c["method"] = method.get("name")
    return c


def run_request(request, base="."):
    """Runs a request dict (module doc); returns the result dict (also written to `out`)."""
    root = pathlib.Path(base).resolve().parent
    for key in ("export", "out", "queries"):
        if key not in request:
            raise RequestError(f'missing "{key}" (see python/mitsuba_ref/harness.py for the request format)')
    ref = Reference(root / request["export"], request.get("variant", "auto"))
    out = root / request["out"]
    out.parent.mkdir(parents=True, exist_ok=True)
    runs = int(request.get("runs", 4))
    seed = int(request.get("seed", 0))
    rr = request.get("rr_depth")
    results = []
    for q in request["queries"]:
        kind, name = q.get("kind"), q.get("name", q.get("kind"))
        minus = q.get("minus_depth")
        other = Reference(root / q["minus_export"], request.get("variant", "auto")) if q.get("minus_export") else None
        for depth in q.get("max_depth", [-1]):
            t0 = time.perf_counter()
            entry = {"name": name, "kind": kind, "max_depth": depth, "runs": runs}

            def evaluate(d, s, r=ref):
                if kind == "irradiance":
                    return r.irradiance(q["points"], q["normals"], q.get("spp", 256), d, runs, s, rr)
                if kind == "radiance":
                    return r.radiance(q["origins"], q["directions"], q.get("spp", 64), d, runs, s, rr)
                if kind == "image":
                    return r.image(q.get("spp", 16), d, runs, s, q.get("width"), q.get("height"), rr)
                raise RequestError(f'query "{name}": unknown kind "{kind}" (image, irradiance or radiance)')

            m, v = evaluate(depth, seed)
            if minus is not None or other is not None:
                # Light of exactly the orders in (minus_depth, max_depth], or the light the other export
                # lacks: the difference of two independent estimates (other seeds), so their variances add.
                m1, v1 = evaluate(int(minus) if minus is not None else depth, seed + 7919, other or ref)
                m, v = np.asarray(m) - np.asarray(m1), np.asarray(v) + np.asarray(v1)
                if minus is not None:
                    entry["minus_depth"] = int(minus)
                if other is not None:
                    entry["minus_export"] = q["minus_export"]
            if q.get("methods"):
                block = int(q.get("block", 1))
                entry["comparisons"] = [_comparison(meth, m, v, kind == "image" and block, q) for meth in q["methods"]]
            if kind == "image":
                stem = f"{out.stem}_{name}_d{depth}"
                _write_exr(ref.mi, out.parent / f"{stem}_mean.exr", m)
                _write_exr(ref.mi, out.parent / f"{stem}_var.exr", v)
                entry["files"] = [f"{stem}_mean.exr", f"{stem}_var.exr"]
                entry["image_mean"] = m.reshape(-1, 3).mean(axis=0).tolist()
                m, v = None, np.asarray(v).reshape(-1, 3).mean(axis=0)
                entry["pixel_var_of_mean_avg"] = v.tolist()
            if m is not None:
                entry["mean"] = np.asarray(m).tolist()
                entry["var_of_mean"] = np.asarray(v).tolist()
            entry["seconds"] = time.perf_counter() - t0
            results.append(entry)
    result = {"variant": ref.variant, "export": str(ref.dir), "queries": results, "out": str(out)}
    _atomic_write_text(out, json.dumps(result, indent=1) + "\n")
    return result
