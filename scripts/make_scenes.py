#!/usr/bin/env python3
"""Authors voltab's bundled scenes, each once, in both glTF 2.0 and USD.

Every scene is ONE Python description (meshes as numpy arrays in metres, materials, lights, media,
cameras; `docs/design/scene.md` gives the conventions) written out twice:

- `NAME.usda` with the pxr API: `UsdGeom.Mesh` (points, faceVertexCounts/Indices with quads where
  natural, vertex normals, primvars `st` and `st1` = lightmap UVs), UsdLux lights, UsdShade materials
  (`UsdPreviewSurface`; media through `outputs:volume` → a MaterialX `ND_anisotropic_vdf` shader), the
  global medium as a prim with `voltab:` attributes, `metersPerUnit = 1`, `upAxis = "Y"`;
- `NAME.gltf` + `NAME.bin` with the standard json module: KHR_lights_punctual,
  KHR_materials_emissive_strength, KHR_materials_transmission, KHR_materials_ior,
  KHR_materials_volume and voltab's vendor extension `VOLTAB_participating_media`.

Photometric inputs are authored so that both files import to the same radiometric numbers (K = 683
lm/W): a point light of `candela` is glTF `intensity = candela` and a USD `SphereLight` with
`treatAsPoint` whose `L·πr²` equals it; a directional light of `lux` is glTF `intensity = lux` and a
USD `DistantLight` with `normalize = true` and `intensity = lux`; an emissive surface is glTF
`emissiveFactor × emissiveStrength` and USD `emissiveColor` = their product (nits).

Output is deterministic: no timestamps, float32 geometry, transcendental-derived numbers rounded to
12 significant digits, JSON floats written by `repr`. Every file is validated after writing (USD opens in
`Usd.Stage.Open` and its meshes are consistent; glTF accessors, buffer views and indices are in range).

Usage: .venv/bin/python scripts/make_scenes.py [OUT_DIR]   (default: scenes/ next to scripts/)
"""
from __future__ import annotations

import argparse
import json
import math
import pathlib
import sys
from dataclasses import dataclass, field

import numpy as np

LUMENS_PER_WATT = 683.0
SENSOR_MM = (36.0, 24.0)  # full-frame sensor: USD apertures (tenths of a unit, like focal length)

# ---------------------------------------------------------------------------------------------------
# Scene description
# ---------------------------------------------------------------------------------------------------


def r12(x: float) -> float:
    """Rounds a transcendental-derived number to 12 significant digits (last-ulp libm differences
    between machines must not change the written bytes)."""
    return float(f"{x:.12g}") + 0.0  # + 0.0: no negative zero


@dataclass
class ExponentialHeight:
    """iser2018 height fog: rho(x) = rho * exp(-falloff * <x - offset, direction>), falloff in 1/m."""

    rho: float
    falloff: float
    direction: tuple
    offset: tuple


@dataclass
class Medium:
    """Participating medium in 1/m (density 1), HG g."""

    sigma_s: tuple
    sigma_a: tuple
    g: float
    density: ExponentialHeight | None = None

    @property
    def sigma_t(self):
        return tuple(s + a for s, a in zip(self.sigma_s, self.sigma_a))


@dataclass
class Material:
    name: str
    base_color: tuple = (0.8, 0.8, 0.8)
    roughness: float = 0.5
    emissive_color: tuple | None = None  # glTF emissiveFactor, each channel <= 1
    emissive_strength: float = 1.0  # nits per unit of emissive_color
    ior: float | None = None  # transmissive dielectric (glTF transmission 1, USD opacity 0)
    medium: Medium | None = None  # medium inside a closed mesh with this material
    # glTF KHR_materials_volume authoring of `medium`: sigma_t = -ln(attenuationColor)/attenuationDistance
    attenuation_distance: float = 1.0
    thickness: float = 0.0

    @property
    def nits(self):
        """Emitted luminance per channel [cd/m²] (0 when not emissive)."""
        if self.emissive_color is None:
            return (0.0, 0.0, 0.0)
        return tuple(c * self.emissive_strength for c in self.emissive_color)


@dataclass
class Xform:
    """Node transform T·R·S; rotation as a unit quaternion (x, y, z, w)."""

    translate: tuple = (0.0, 0.0, 0.0)
    rotate: tuple = (0.0, 0.0, 0.0, 1.0)
    scale: tuple = (1.0, 1.0, 1.0)

    def matrix(self) -> np.ndarray:
        """4×4 column-vector matrix (p_world = M @ [p, 1])."""
        m = np.eye(4)
        m[:3, :3] = quat_to_matrix(self.rotate) @ np.diag(self.scale)
        m[:3, 3] = self.translate
        return m


@dataclass
class Group:
    """A transform-only node (glTF node without mesh, USD Xform)."""

    name: str
    xform: Xform


@dataclass
class Mesh:
    name: str
    points: np.ndarray  # (N, 3) float32, local space [m]
    normals: np.ndarray  # (N, 3) float32, per vertex
    counts: np.ndarray  # (F,) int32 face vertex counts (3 or 4)
    indices: np.ndarray  # (sum counts,) int32
    material: str
    st: np.ndarray | None = None  # (N, 2) float32 material UVs
    st1: np.ndarray | None = None  # (N, 2) float32 lightmap UVs
    xform: Xform | None = None
    parent: str | None = None  # Group name

    def triangles(self) -> np.ndarray:
        """Fan triangulation (v0, vi, vi+1) of every polygon, as both importers do."""
        tris = []
        start = 0
        for c in self.counts.tolist():
            f = self.indices[start:start + c].tolist()
            for i in range(1, c - 1):
                tris.append((f[0], f[i], f[i + 1]))
            start += c
        return np.asarray(tris, dtype=np.uint32).reshape(-1, 3)


@dataclass
class PointLight:
    name: str
    position: tuple
    color: tuple
    candela: float
    radius: float = 0.05  # USD SphereLight radius (treatAsPoint)


@dataclass
class DirectionalLight:
    name: str
    direction: tuple  # direction the light travels
    color: tuple
    lux: float
    angle_deg: float = 0.53  # USD angular diameter


@dataclass
class Camera:
    name: str
    position: tuple
    target: tuple
    focal_mm: float
    znear: float = 0.05
    zfar: float = 1000.0
    up: tuple = (0.0, 1.0, 0.0)

    @property
    def yfov(self) -> float:
        return 2.0 * math.atan(SENSOR_MM[1] / (2.0 * self.focal_mm))

    @property
    def aspect(self) -> float:
        return SENSOR_MM[0] / SENSOR_MM[1]


@dataclass
class Scene:
    name: str
    description: str
    meshes: list
    materials: list
    lights: list
    cameras: list
    global_medium: Medium | None = None
    global_medium_name: str = "GlobalMedium"
    groups: list = field(default_factory=list)

    def material(self, name: str) -> Material:
        return next(m for m in self.materials if m.name == name)


# ---------------------------------------------------------------------------------------------------
# Geometry helpers (float64 maths, float32 storage)
# ---------------------------------------------------------------------------------------------------


def normalize(v):
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


def quat_to_matrix(q) -> np.ndarray:
    x, y, z, w = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def matrix_to_quat(m) -> tuple:
    """Unit quaternion (x, y, z, w) of a rotation matrix (Shepperd's method), 12 significant digits."""
    t = m[0, 0] + m[1, 1] + m[2, 2]
    if t > 0:
        s = math.sqrt(t + 1.0) * 2
        q = ((m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, 0.25 * s)
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2]) * 2
        q = (0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s, (m[2, 1] - m[1, 2]) / s)
    elif m[1, 1] > m[2, 2]:
        s = math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2]) * 2
        q = ((m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s, (m[0, 2] - m[2, 0]) / s)
    else:
        s = math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1]) * 2
        q = ((m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s, (m[1, 0] - m[0, 1]) / s)
    if q[3] < 0:
        q = tuple(-c for c in q)
    return tuple(r12(c) for c in q)


def quat_y(deg: float) -> tuple:
    """Rotation about +Y by `deg` degrees."""
    h = math.radians(deg) / 2
    return (0.0, r12(math.sin(h)), 0.0, r12(math.cos(h)))


def look_rotation(forward, up=(0.0, 1.0, 0.0)) -> tuple:
    """Quaternion turning local −Z to `forward` with local +Y as close to `up` as possible."""
    f = normalize(forward)
    r = np.cross(f, up)
    if np.linalg.norm(r) < 1e-9:  # looking straight up or down
        r = np.cross(f, (0.0, 0.0, -1.0))
    r = normalize(r)
    u = np.cross(r, f)
    return matrix_to_quat(np.column_stack([r, u, -f]))


def f32(a) -> np.ndarray:
    return np.ascontiguousarray((np.asarray(a, dtype=np.float64) + 0.0).astype(np.float32))  # no -0


def grid(name, origin, u, v, nu, nv, material, lightmap=True, **kw) -> Mesh:
    """A planar nu×nv grid of quads spanning origin + [0,1]·u + [0,1]·v, facing u × v."""
    origin, u, v = (np.asarray(a, dtype=np.float64) for a in (origin, u, v))
    n = normalize(np.cross(u, v))
    pts, st = [], []
    for j in range(nv + 1):
        for i in range(nu + 1):
            pts.append(origin + u * (i / nu) + v * (j / nv))
            st.append((i / nu, j / nv))
    idx = []
    for j in range(nv):
        for i in range(nu):
            a = j * (nu + 1) + i
            idx += [a, a + 1, a + nu + 2, a + nu + 1]
    st = np.asarray(st)
    return Mesh(
        name=name,
        points=f32(pts),
        normals=f32(np.tile(n, (len(pts), 1))),
        counts=np.full(nu * nv, 4, dtype=np.int32),
        indices=np.asarray(idx, dtype=np.int32),
        material=material,
        st=f32(st),
        st1=f32(0.01 + 0.98 * st) if lightmap else None,
        **kw,
    )


def box(name, size, material, **kw) -> Mesh:
    """An axis-aligned box, x and z centred on 0, y from 0 to size[1]; 6 quads, 24 vertices (flat
    normals); lightmap UVs pack the faces in a 3×2 atlas with padding."""
    sx, sy, sz = (s / 2 for s in (size[0], 0, size[2]))
    h = size[1]
    # each face: origin, u, v (u × v = outward normal)
    faces = [
        ((sx, 0, sz), (0, 0, -2 * sz), (0, h, 0)),  # +X
        ((-sx, 0, -sz), (0, 0, 2 * sz), (0, h, 0)),  # -X
        ((-sx, h, sz), (2 * sx, 0, 0), (0, 0, -2 * sz)),  # +Y
        ((-sx, 0, -sz), (2 * sx, 0, 0), (0, 0, 2 * sz)),  # -Y
        ((-sx, 0, sz), (2 * sx, 0, 0), (0, h, 0)),  # +Z
        ((sx, 0, -sz), (-2 * sx, 0, 0), (0, h, 0)),  # -Z
    ]
    pts, nrm, st, st1, idx = [], [], [], [], []
    for k, (o, u, v) in enumerate(faces):
        o, u, v = (np.asarray(a, dtype=np.float64) for a in (o, u, v))
        n = normalize(np.cross(u, v))
        cell = np.array([(k % 3) / 3.0, (k // 3) / 2.0])
        base = len(pts)
        for (a, b) in ((0, 0), (1, 0), (1, 1), (0, 1)):
            pts.append(o + a * u + b * v)
            nrm.append(n)
            st.append((a, b))
            st1.append(cell + np.array([0.01 + 0.313333 * a, 0.01 + 0.48 * b]))
        idx += [base, base + 1, base + 2, base + 3]
    return Mesh(name=name, points=f32(pts), normals=f32(nrm), counts=np.full(6, 4, dtype=np.int32),
                indices=np.asarray(idx, dtype=np.int32), material=material, st=f32(st), st1=f32(st1), **kw)


def icosphere(name, radius, subdivisions, material, **kw) -> Mesh:
    """A welded, closed, manifold icosphere (20·4^n triangles, outward CCW winding, smooth normals)."""
    t = (1.0 + math.sqrt(5.0)) / 2.0
    verts = [normalize(v) for v in [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t),
                                    (0, -1, -t), (0, 1, -t), (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]]
    faces = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2),
             (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5),
             (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    for _ in range(subdivisions):
        cache = {}

        def mid(a, b):
            key = (min(a, b), max(a, b))
            if key not in cache:
                cache[key] = len(verts)
                verts.append(normalize(verts[a] + verts[b]))
            return cache[key]

        new = []
        for a, b, c in faces:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            new += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        faces = new
    unit = np.asarray(verts)
    return Mesh(name=name, points=f32(unit * radius), normals=f32(unit), counts=np.full(len(faces), 3, dtype=np.int32),
                indices=np.asarray(faces, dtype=np.int32).reshape(-1), material=material, **kw)


def holed_wall(name, x, z_breaks, y_breaks, holes_z, holes_y, material, **kw) -> Mesh:
    """A planar wall at `x` facing −X, made of the quads of the rectilinear grid `z_breaks × y_breaks`
    except the cells whose z interval is in `holes_z` and y interval in `holes_y` (square holes between
    bars). Lightmap UVs are the planar (z, y) projection."""
    nz, ny = len(z_breaks), len(y_breaks)
    z0, z1, y0, y1 = z_breaks[0], z_breaks[-1], y_breaks[0], y_breaks[-1]
    pts, st = [], []
    for y in y_breaks:
        for z in z_breaks:
            pts.append((x, y, z))
            st.append(((z1 - z) / (z1 - z0), (y - y0) / (y1 - y0)))
    idx = []
    for j in range(ny - 1):
        for i in range(nz - 1):
            if i in holes_z and j in holes_y:
                continue
            a = j * nz + i
            idx += [a, a + 1, a + nz + 1, a + nz]  # counter-clockwise seen from -X
    used = sorted(set(idx))
    assert used == list(range(len(pts))), "every grid vertex is a corner of some wall cell"
    st = np.asarray(st)
    return Mesh(name=name, points=f32(pts), normals=f32(np.tile((-1.0, 0.0, 0.0), (len(pts), 1))),
                counts=np.full(len(idx) // 4, 4, dtype=np.int32), indices=np.asarray(idx, dtype=np.int32),
                material=material, st=f32(st), st1=f32(0.01 + 0.98 * st), **kw)


# ---------------------------------------------------------------------------------------------------
# The bundled scenes
# ---------------------------------------------------------------------------------------------------


def room_walls(x0, x1, y1, z0, z1, cell, materials, front=False):
    """Floor, ceiling, back (z0), left (x0), right (x1) — and the front (z1) when asked — facing into
    the box [x0,x1]×[0,y1]×[z0,z1], as grids of `cell`-sized quads."""
    w, d = x1 - x0, z1 - z0
    nw, nh, nd = (max(1, round(s / cell)) for s in (w, y1, d))
    walls = [
        grid("floor", (x0, 0, z1), (w, 0, 0), (0, 0, -d), nw, nd, materials["floor"]),
        grid("ceiling", (x0, y1, z0), (w, 0, 0), (0, 0, d), nw, nd, materials["ceiling"]),
        grid("back_wall", (x0, 0, z0), (w, 0, 0), (0, y1, 0), nw, nh, materials["back_wall"]),
        grid("left_wall", (x0, 0, z1), (0, 0, -d), (0, y1, 0), nd, nh, materials["left_wall"]),
        grid("right_wall", (x1, 0, z0), (0, 0, d), (0, y1, 0), nd, nh, materials["right_wall"]),
    ]
    if front:
        walls.append(grid("front_wall", (x1, 0, z1), (-w, 0, 0), (0, y1, 0), nw, nh, materials["front_wall"]))
    return walls


def fog_room() -> Scene:
    mats = [
        Material("white", base_color=(0.73, 0.73, 0.73), roughness=0.9),
        Material("red", base_color=(0.63, 0.065, 0.05), roughness=0.9),
        Material("green", base_color=(0.14, 0.45, 0.091), roughness=0.9),
        Material("box", base_color=(0.7, 0.7, 0.68), roughness=0.7),
        Material("panel", base_color=(0.78, 0.78, 0.78), roughness=0.5, emissive_color=(1.0, 0.85, 0.6),
                 emissive_strength=3000.0),
    ]
    walls = room_walls(-2.0, 2.0, 3.0, -2.0, 2.0, 0.5,
                       {"floor": "white", "ceiling": "white", "back_wall": "white", "left_wall": "red",
                        "right_wall": "green"})
    meshes = walls + [
        box("tall_box", (1.0, 2.0, 1.0), "box", xform=Xform(translate=(-0.8, 0.0, -0.7), rotate=quat_y(20.0))),
        box("short_box", (1.0, 1.0, 1.0), "box", xform=Xform(translate=(0.8, 0.0, 0.5), rotate=quat_y(-18.0))),
        # 1 m × 1 m panel 2 cm under the ceiling, facing down
        grid("ceiling_panel", (-0.5, 2.98, -0.5), (1.0, 0, 0), (0, 0, 1.0), 1, 1, "panel"),
    ]
    return Scene(
        name="fog_room",
        description="Cornell-style room 4 x 3 x 4 m (open at +Z) with red left and green right walls, two boxes, "
                    "room fog as the global medium, a ceiling panel (emissive quad) and a point light.",
        meshes=meshes,
        materials=mats,
        lights=[PointLight("bulb", (0.9, 2.2, -1.0), (1.0, 0.9, 0.75), 150.0, radius=0.05)],
        cameras=[Camera("camera", (0.0, 1.5, 7.5), (0.0, 1.4, 0.0), 35.0, znear=0.05, zfar=100.0)],
        global_medium=Medium(sigma_s=(0.07, 0.08, 0.09), sigma_a=(0.004, 0.004, 0.004), g=0.3),
        global_medium_name="RoomFog",
    )


# Wax: sigma_t per channel for a sphere of radius 0.1 m (12–22 mean free paths across), albedo exactly
# representable in binary (1 − 2^-8, 1 − 2^-7, 1 − 2^-6) so sigma_a = (1 − albedo)·sigma_t survives
# float32 authoring in both formats.
WAX_SIGMA_T = (60.0, 80.0, 110.0)
WAX_ALBEDO = (0.99609375, 0.9921875, 0.984375)
WAX_G = 0.7


def translucent() -> Scene:
    wax = Medium(sigma_s=tuple(a * t for a, t in zip(WAX_ALBEDO, WAX_SIGMA_T)),
                 sigma_a=tuple((1.0 - a) * t for a, t in zip(WAX_ALBEDO, WAX_SIGMA_T)), g=WAX_G)
    mats = [
        Material("ground", base_color=(0.5, 0.5, 0.5), roughness=0.8),
        Material("wax", base_color=(0.95, 0.9, 0.8), roughness=0.25, ior=1.5, medium=wax,
                 attenuation_distance=0.02, thickness=0.2),
    ]
    meshes = [
        grid("ground", (-1.0, 0.0, 1.0), (2.0, 0, 0), (0, 0, -2.0), 4, 4, "ground"),
        icosphere("wax_sphere", 0.1, 3, "wax", xform=Xform(translate=(0.0, 0.1, 0.0))),
    ]
    return Scene(
        name="translucent",
        description="A wax sphere (radius 0.1 m icosphere, refractive ior 1.5 boundary, scattering medium "
                    "inside with albedo ~0.99 and g = 0.7) on a ground plane, lit by a point light.",
        meshes=meshes,
        materials=mats,
        lights=[PointLight("lamp", (0.4, 0.6, 0.3), (1.0, 0.95, 0.9), 40.0, radius=0.02)],
        cameras=[Camera("camera", (0.0, 0.3, 0.8), (0.0, 0.09, 0.0), 50.0, znear=0.01, zfar=20.0)],
    )


def window_grid_breaks():
    """Breakpoints of the window wall: a 4×3 grid of 0.5 m square holes separated by 0.1 m bars."""
    hole, bar = 0.5, 0.1
    zs = [-2.5, -1.25]
    z = -1.25
    for _ in range(4):
        zs += [z + bar, z + bar + hole]
        z += bar + hole
    zs += [z + bar, 2.5]
    ys = [0.0, 0.8]
    y = 0.8
    for _ in range(3):
        ys += [y + bar, y + bar + hole]
        y += bar + hole
    ys += [y + bar, 3.0]
    zs = [round(v, 6) for v in zs]
    ys = [round(v, 6) for v in ys]
    holes_z = {2, 4, 6, 8}  # cell i spans zs[i]..zs[i+1]
    holes_y = {2, 4, 6}
    return zs, ys, holes_z, holes_y


def window_room() -> Scene:
    mats = [
        Material("plaster", base_color=(0.8, 0.78, 0.75), roughness=0.9),
        Material("wood_floor", base_color=(0.45, 0.3, 0.18), roughness=0.6),
        Material("window_wall", base_color=(0.75, 0.75, 0.78), roughness=0.8),
    ]
    walls = room_walls(-2.5, 2.5, 3.0, -2.5, 2.5, 0.5,
                       {"floor": "wood_floor", "ceiling": "plaster", "back_wall": "plaster", "left_wall": "plaster",
                        "right_wall": "plaster", "front_wall": "plaster"}, front=True)
    walls = [w for w in walls if w.name != "right_wall"]
    zs, ys, hz, hy = window_grid_breaks()
    walls.append(holed_wall("window_wall", 2.5, zs, ys, hz, hy, "window_wall"))
    return Scene(
        name="window_room",
        description="A closed 5 x 3 x 5 m room whose +X wall is a window grid (4 x 3 square 0.5 m holes between "
                    "0.1 m bars); low sun (directional light) shines through it into forward-scattering "
                    "room fog.",
        meshes=walls,
        materials=mats,
        lights=[DirectionalLight("sun", (-1.0, -0.7, 0.25), (1.0, 0.96, 0.9), 60000.0)],
        cameras=[Camera("camera", (-2.2, 1.6, 2.2), (1.0, 0.6, -0.5), 24.0, znear=0.05, zfar=50.0)],
        global_medium=Medium(sigma_s=(0.04, 0.04, 0.04), sigma_a=(0.002, 0.002, 0.002), g=0.5),
        global_medium_name="RoomFog",
    )


def outdoor() -> Scene:
    mats = [
        Material("asphalt", base_color=(0.12, 0.12, 0.12), roughness=0.9),
        Material("concrete", base_color=(0.55, 0.53, 0.5), roughness=0.85),
        Material("brick", base_color=(0.45, 0.2, 0.15), roughness=0.9),
        Material("sign_magenta", base_color=(0.1, 0.1, 0.1), emissive_color=(1.0, 0.1, 0.6), emissive_strength=5000.0),
        Material("sign_cyan", base_color=(0.1, 0.1, 0.1), emissive_color=(0.1, 0.8, 1.0), emissive_strength=5000.0),
        Material("shopfront", base_color=(0.2, 0.2, 0.2), emissive_color=(1.0, 0.75, 0.4), emissive_strength=2000.0),
    ]
    city = Group("city", Xform(translate=(0.0, 0.0, -10.0)))
    buildings = [  # name, size (w, h, d), position (in the city group), rotation about Y, material
        ("tower", (12.0, 30.0, 12.0), (-18.0, 0.0, -5.0), 0.0, "concrete"),
        ("block_a", (10.0, 14.0, 16.0), (17.0, 0.0, -2.0), 0.0, "brick"),
        ("block_b", (8.0, 10.0, 8.0), (-20.0, 0.0, 25.0), 15.0, "brick"),
        ("block_c", (14.0, 20.0, 10.0), (20.0, 0.0, 28.0), -25.0, "concrete"),
        ("kiosk", (3.0, 3.0, 3.0), (6.0, 0.0, 18.0), 40.0, "concrete"),
    ]
    meshes = [grid("ground", (-100.0, 0.0, 100.0), (200.0, 0, 0), (0, 0, -200.0), 20, 20, "asphalt")]
    for name, size, pos, rot, mat in buildings:
        # unit box scaled by the node: exercises T·R·S and normal transformation in both importers
        meshes.append(box(name, (1.0, 1.0, 1.0), mat, parent="city",
                          xform=Xform(translate=pos, rotate=quat_y(rot), scale=size)))
    # Emissive surfaces in world space, 5 cm in front of the axis-aligned buildings (city offset z −10).
    meshes += [
        # on the tower's +Z face (z = −10 − 5 + 6 = −9), 6 × 2 m, facing +Z
        grid("sign_magenta", (-21.0, 12.0, -8.95), (6.0, 0, 0), (0, 2.0, 0), 3, 1, "sign_magenta"),
        # on block_a's −X face (x = 17 − 5 = 12), 2 × 5 m, facing −X
        grid("sign_cyan", (11.95, 6.0, -14.0), (0, 0, 2.0), (0, 5.0, 0), 1, 2, "sign_cyan"),
        # shop window on block_a's −X face at street level, 4 × 2.5 m
        grid("shop_window", (11.95, 0.5, -9.0), (0, 0, 4.0), (0, 2.5, 0), 2, 1, "shopfront"),
    ]
    lamps = [
        PointLight("lamp_sodium_1", (-7.0, 6.0, 20.0), (1.0, 0.55, 0.2), 4000.0, radius=0.15),
        PointLight("lamp_sodium_2", (7.0, 6.0, 5.0), (1.0, 0.55, 0.2), 4000.0, radius=0.15),
        PointLight("lamp_led_1", (-7.0, 6.0, -10.0), (0.92, 0.96, 1.0), 3000.0, radius=0.15),
        PointLight("lamp_led_2", (7.0, 6.0, -25.0), (0.92, 0.96, 1.0), 3000.0, radius=0.15),
    ]
    fog = Medium(sigma_s=(0.02, 0.022, 0.025), sigma_a=(0.001, 0.001, 0.001), g=0.5,
                 density=ExponentialHeight(rho=0.8, falloff=0.05, direction=(0.0, 1.0, 0.0), offset=(0.0, 0.0, 0.0)))
    return Scene(
        name="outdoor",
        description="A 200 m ground plane with five buildings (scaled, rotated unit boxes under a translated "
                    "group), exponential height fog as the global medium, four coloured street lamps "
                    "(point lights) and three emissive surfaces (two signs and a shop window).",
        meshes=meshes,
        materials=mats,
        lights=lamps,
        cameras=[Camera("camera", (0.0, 1.7, 45.0), (0.0, 6.0, -10.0), 28.0, znear=0.1, zfar=1000.0)],
        global_medium=fog,
        global_medium_name="Atmosphere",
        groups=[city],
    )


SCENES = {"fog_room": fog_room, "translucent": translucent, "window_room": window_room, "outdoor": outdoor}


def scenes() -> list:
    """Every bundled scene description, fresh."""
    return [make() for make in SCENES.values()]


# ---------------------------------------------------------------------------------------------------
# Conversions both writers share
# ---------------------------------------------------------------------------------------------------


def usd_point_intensity(light: PointLight) -> float:
    """USD SphereLight (treatAsPoint) intensity [nits] so that L·πr² equals `candela` (r as float32)."""
    r = float(np.float32(light.radius))
    return light.candela / (math.pi * r * r)


def gltf_attenuation(mat: Material) -> list:
    """KHR_materials_volume attenuationColor so that −ln(c)/d = sigma_t."""
    d = mat.attenuation_distance
    return [r12(math.exp(-t * d)) for t in mat.medium.sigma_t]


def gltf_albedo(mat: Material) -> list:
    return [s / t for s, t in zip(mat.medium.sigma_s, mat.medium.sigma_t)]


def world_matrix(scene: Scene, mesh: Mesh) -> np.ndarray:
    m = mesh.xform.matrix() if mesh.xform else np.eye(4)
    if mesh.parent:
        g = next(g for g in scene.groups if g.name == mesh.parent)
        m = g.xform.matrix() @ m
    return m


# ---------------------------------------------------------------------------------------------------
# USD
# ---------------------------------------------------------------------------------------------------


def _usd_xform_ops(prim, xf: Xform):
    from pxr import Gf, UsdGeom

    xa = UsdGeom.Xformable(prim)
    if any(xf.translate):
        xa.AddTranslateOp(UsdGeom.XformOp.PrecisionDouble).Set(Gf.Vec3d(*xf.translate))
    if tuple(xf.rotate) != (0.0, 0.0, 0.0, 1.0):
        x, y, z, w = xf.rotate
        xa.AddOrientOp(UsdGeom.XformOp.PrecisionDouble).Set(Gf.Quatd(w, Gf.Vec3d(x, y, z)))
    if tuple(xf.scale) != (1.0, 1.0, 1.0):
        xa.AddScaleOp(UsdGeom.XformOp.PrecisionDouble).Set(Gf.Vec3d(*xf.scale))


def _usd_medium_attrs(prim, medium: Medium):
    from pxr import Gf, Sdf

    def attr(name, tname, value, uniform=False):
        var = Sdf.VariabilityUniform if uniform else Sdf.VariabilityVarying
        prim.CreateAttribute(name, tname, False, var).Set(value)

    attr("voltab:medium", Sdf.ValueTypeNames.Token, "global", uniform=True)
    attr("voltab:sigmaS", Sdf.ValueTypeNames.Color3f, Gf.Vec3f(*medium.sigma_s))
    attr("voltab:sigmaA", Sdf.ValueTypeNames.Color3f, Gf.Vec3f(*medium.sigma_a))
    attr("voltab:anisotropy", Sdf.ValueTypeNames.Float, medium.g)
    _usd_density_attrs(prim, medium.density)


def _usd_density_attrs(prim, density: ExponentialHeight | None):
    from pxr import Gf, Sdf

    if density is None:
        return
    prim.CreateAttribute("voltab:density", Sdf.ValueTypeNames.Token, False, Sdf.VariabilityUniform).Set(
        "exponentialHeight")
    prim.CreateAttribute("voltab:density:rho", Sdf.ValueTypeNames.Float, False).Set(density.rho)
    prim.CreateAttribute("voltab:density:falloff", Sdf.ValueTypeNames.Float, False).Set(density.falloff)
    prim.CreateAttribute("voltab:density:direction", Sdf.ValueTypeNames.Vector3f, False).Set(
        Gf.Vec3f(*density.direction))
    prim.CreateAttribute("voltab:density:offset", Sdf.ValueTypeNames.Point3f, False).Set(Gf.Vec3f(*density.offset))


def build_usd_stage(scene: Scene):
    """The scene as an in-memory USD stage (Y up, metres)."""
    from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux, UsdShade, Vt

    stage = Usd.Stage.CreateInMemory()
    layer = stage.GetRootLayer()
    layer.documentation = f"voltab bundled scene {scene.name}: {scene.description} Written by scripts/make_scenes.py."
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    world = UsdGeom.Xform.Define(stage, "/World")
    stage.SetDefaultPrim(world.GetPrim())

    # materials
    UsdGeom.Scope.Define(stage, "/World/Looks")
    usd_mats = {}
    for mat in scene.materials:
        path = f"/World/Looks/{mat.name}"
        m = UsdShade.Material.Define(stage, path)
        sh = UsdShade.Shader.Define(stage, f"{path}/PreviewSurface")
        sh.CreateIdAttr("UsdPreviewSurface")
        sh.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(*mat.base_color))
        sh.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(mat.roughness)
        sh.CreateInput("metallic", Sdf.ValueTypeNames.Float).Set(0.0)
        if mat.emissive_color is not None:
            sh.CreateInput("emissiveColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(*mat.nits))
        if mat.ior is not None:
            sh.CreateInput("opacity", Sdf.ValueTypeNames.Float).Set(0.0)
            sh.CreateInput("ior", Sdf.ValueTypeNames.Float).Set(mat.ior)
        m.CreateSurfaceOutput().ConnectToSource(sh.ConnectableAPI(), "surface")
        if mat.medium is not None:
            vdf = UsdShade.Shader.Define(stage, f"{path}/Volume")
            vdf.CreateIdAttr("ND_anisotropic_vdf")
            vdf.CreateInput("absorption", Sdf.ValueTypeNames.Vector3f).Set(Gf.Vec3f(*mat.medium.sigma_a))
            vdf.CreateInput("scattering", Sdf.ValueTypeNames.Vector3f).Set(Gf.Vec3f(*mat.medium.sigma_s))
            vdf.CreateInput("anisotropy", Sdf.ValueTypeNames.Float).Set(mat.medium.g)
            vdf.CreateOutput("out", Sdf.ValueTypeNames.Token)
            m.CreateVolumeOutput().ConnectToSource(vdf.ConnectableAPI(), "out")
            _usd_density_attrs(m.GetPrim(), mat.medium.density)
        usd_mats[mat.name] = m

    for g in scene.groups:
        x = UsdGeom.Xform.Define(stage, f"/World/{g.name}")
        _usd_xform_ops(x.GetPrim(), g.xform)

    for mesh in scene.meshes:
        path = f"/World/{mesh.parent}/{mesh.name}" if mesh.parent else f"/World/{mesh.name}"
        um = UsdGeom.Mesh.Define(stage, path)
        um.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
        um.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(mesh.points))
        um.CreateExtentAttr(UsdGeom.Mesh.ComputeExtent(Vt.Vec3fArray.FromNumpy(mesh.points)))
        um.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(mesh.counts))
        um.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(mesh.indices))
        um.CreateNormalsAttr(Vt.Vec3fArray.FromNumpy(mesh.normals))
        um.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
        pv = UsdGeom.PrimvarsAPI(um)
        # The description's UVs follow glTF (origin at the image's top left, v down); USD's st has its
        # origin at the bottom left, so v is flipped (docs/design/scene.md).
        for name, uv in (("st", mesh.st), ("st1", mesh.st1)):
            if uv is not None:
                flipped = np.ascontiguousarray(np.column_stack([uv[:, 0], 1.0 - uv[:, 1]]), dtype=np.float32)
                pv.CreatePrimvar(name, Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex).Set(
                    Vt.Vec2fArray.FromNumpy(flipped))
        if mesh.xform:
            _usd_xform_ops(um.GetPrim(), mesh.xform)
        UsdShade.MaterialBindingAPI.Apply(um.GetPrim()).Bind(usd_mats[mesh.material])

    for light in scene.lights:
        path = f"/World/{light.name}"
        if isinstance(light, PointLight):
            ul = UsdLux.SphereLight.Define(stage, path)
            ul.CreateTreatAsPointAttr(True)
            ul.CreateRadiusAttr(light.radius)
            ul.CreateIntensityAttr(usd_point_intensity(light))
            ul.CreateColorAttr(Gf.Vec3f(*light.color))
            _usd_xform_ops(ul.GetPrim(), Xform(translate=light.position))
        elif isinstance(light, DirectionalLight):
            ul = UsdLux.DistantLight.Define(stage, path)
            ul.CreateAngleAttr(light.angle_deg)
            ul.CreateNormalizeAttr(True)
            ul.CreateIntensityAttr(light.lux)
            ul.CreateColorAttr(Gf.Vec3f(*light.color))
            _usd_xform_ops(ul.GetPrim(), Xform(rotate=look_rotation(light.direction)))
        else:
            raise TypeError(light)

    for cam in scene.cameras:
        uc = UsdGeom.Camera.Define(stage, f"/World/{cam.name}")
        uc.CreateProjectionAttr(UsdGeom.Tokens.perspective)
        uc.CreateFocalLengthAttr(cam.focal_mm)
        uc.CreateHorizontalApertureAttr(SENSOR_MM[0])
        uc.CreateVerticalApertureAttr(SENSOR_MM[1])
        uc.CreateClippingRangeAttr(Gf.Vec2f(cam.znear, cam.zfar))
        fwd = np.subtract(cam.target, cam.position)
        _usd_xform_ops(uc.GetPrim(), Xform(translate=cam.position, rotate=look_rotation(fwd, cam.up)))

    if scene.global_medium is not None:
        scope = UsdGeom.Scope.Define(stage, f"/World/{scene.global_medium_name}")
        _usd_medium_attrs(scope.GetPrim(), scene.global_medium)
    return stage


def write_usd(scene: Scene, path) -> pathlib.Path:
    path = pathlib.Path(path)
    stage = build_usd_stage(scene)
    path.write_text(stage.GetRootLayer().ExportToString())
    return path


# ---------------------------------------------------------------------------------------------------
# glTF
# ---------------------------------------------------------------------------------------------------

FLOAT, UNSIGNED_SHORT, UNSIGNED_INT = 5126, 5123, 5125
ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER = 34962, 34963
COMPONENT_SIZE = {5120: 1, 5121: 1, 5122: 2, 5123: 2, 5125: 4, 5126: 4}
TYPE_SIZE = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}


class _Bin:
    def __init__(self):
        self.data = bytearray()
        self.views = []
        self.accessors = []

    def add(self, array, component_type, type_, target, minmax=False) -> int:
        while len(self.data) % 4:
            self.data.append(0)
        raw = np.ascontiguousarray(array).tobytes()
        self.views.append({"buffer": 0, "byteOffset": len(self.data), "byteLength": len(raw), "target": target})
        self.data += raw
        acc = {"bufferView": len(self.views) - 1, "componentType": component_type,
               "count": int(array.shape[0]), "type": type_}
        if minmax:
            a = array.reshape(array.shape[0], -1)
            acc["min"] = [float(v) for v in a.min(axis=0)]
            acc["max"] = [float(v) for v in a.max(axis=0)]
        self.accessors.append(acc)
        return len(self.accessors) - 1


def _gltf_trs(xf: Xform | None) -> dict:
    out = {}
    if xf is None:
        return out
    if any(xf.translate):
        out["translation"] = [float(v) for v in xf.translate]
    if tuple(xf.rotate) != (0.0, 0.0, 0.0, 1.0):
        out["rotation"] = [float(v) for v in xf.rotate]
    if tuple(xf.scale) != (1.0, 1.0, 1.0):
        out["scale"] = [float(v) for v in xf.scale]
    return out


def _gltf_medium(medium: Medium) -> dict:
    out = {"sigmaS": list(medium.sigma_s), "sigmaA": list(medium.sigma_a), "anisotropy": medium.g}
    if medium.density is not None:
        d = medium.density
        out["density"] = {"type": "exponentialHeight", "rho": d.rho, "falloff": d.falloff,
                          "direction": list(d.direction), "offset": list(d.offset)}
    return out


def build_gltf(scene: Scene, bin_name: str):
    """(glTF JSON document, binary buffer bytes)."""
    b = _Bin()
    used = set()
    materials = []
    for mat in scene.materials:
        m = {"name": mat.name,
             "pbrMetallicRoughness": {"baseColorFactor": [*mat.base_color, 1.0], "metallicFactor": 0.0,
                                      "roughnessFactor": mat.roughness}}
        ext = {}
        if mat.emissive_color is not None:
            m["emissiveFactor"] = list(mat.emissive_color)
            if mat.emissive_strength != 1.0:
                ext["KHR_materials_emissive_strength"] = {"emissiveStrength": mat.emissive_strength}
        if mat.ior is not None:
            ext["KHR_materials_transmission"] = {"transmissionFactor": 1.0}
            ext["KHR_materials_ior"] = {"ior": mat.ior}
        if mat.medium is not None:
            ext["KHR_materials_volume"] = {"thicknessFactor": mat.thickness,
                                           "attenuationDistance": mat.attenuation_distance,
                                           "attenuationColor": gltf_attenuation(mat)}
            vendor = {"scatteringAlbedo": gltf_albedo(mat), "anisotropy": mat.medium.g}
            if mat.medium.density is not None:
                vendor["density"] = _gltf_medium(mat.medium)["density"]
            ext["VOLTAB_participating_media"] = vendor
        if ext:
            m["extensions"] = ext
            used |= set(ext)
        materials.append(m)
    mat_index = {m.name: i for i, m in enumerate(scene.materials)}

    nodes, meshes, roots = [], [], []
    group_index = {}
    for g in scene.groups:
        group_index[g.name] = len(nodes)
        roots.append(len(nodes))
        nodes.append({"name": g.name, **_gltf_trs(g.xform), "children": []})
    for mesh in scene.meshes:
        attrs = {"POSITION": b.add(mesh.points, FLOAT, "VEC3", ARRAY_BUFFER, minmax=True),
                 "NORMAL": b.add(mesh.normals, FLOAT, "VEC3", ARRAY_BUFFER)}
        if mesh.st is not None:
            attrs["TEXCOORD_0"] = b.add(mesh.st, FLOAT, "VEC2", ARRAY_BUFFER)
        if mesh.st1 is not None:
            attrs["TEXCOORD_1"] = b.add(mesh.st1, FLOAT, "VEC2", ARRAY_BUFFER)
        tris = mesh.triangles().reshape(-1)
        itype = UNSIGNED_SHORT if len(mesh.points) < 65535 else UNSIGNED_INT
        idx = b.add(tris.astype("<u2" if itype == UNSIGNED_SHORT else "<u4"), itype, "SCALAR", ELEMENT_ARRAY_BUFFER)
        meshes.append({"name": mesh.name, "primitives": [
            {"attributes": attrs, "indices": idx, "material": mat_index[mesh.material], "mode": 4}]})
        node = {"name": mesh.name, "mesh": len(meshes) - 1, **_gltf_trs(mesh.xform)}
        if mesh.parent:
            nodes[group_index[mesh.parent]]["children"].append(len(nodes))
        else:
            roots.append(len(nodes))
        nodes.append(node)

    lights = []
    for light in scene.lights:
        if isinstance(light, PointLight):
            lights.append({"name": light.name, "type": "point", "color": list(light.color),
                           "intensity": light.candela})
            trs = _gltf_trs(Xform(translate=light.position))
        else:
            lights.append({"name": light.name, "type": "directional", "color": list(light.color),
                           "intensity": light.lux})
            trs = _gltf_trs(Xform(rotate=look_rotation(light.direction)))
        roots.append(len(nodes))
        nodes.append({"name": light.name, **trs, "extensions": {"KHR_lights_punctual": {"light": len(lights) - 1}}})
    if lights:
        used.add("KHR_lights_punctual")

    cameras = []
    for cam in scene.cameras:
        cameras.append({"name": cam.name, "type": "perspective",
                        "perspective": {"yfov": r12(cam.yfov), "aspectRatio": cam.aspect, "znear": cam.znear,
                                        "zfar": cam.zfar}})
        fwd = np.subtract(cam.target, cam.position)
        roots.append(len(nodes))
        nodes.append({"name": cam.name, "camera": len(cameras) - 1,
                      **_gltf_trs(Xform(translate=cam.position, rotate=look_rotation(fwd, cam.up)))})

    while len(b.data) % 4:
        b.data.append(0)
    doc = {
        "asset": {"version": "2.0", "generator": "voltab scripts/make_scenes.py",
                  "extras": {"description": scene.description}},
        "scene": 0,
        "scenes": [{"name": scene.name, "nodes": roots}],
        "nodes": nodes,
        "meshes": meshes,
        "materials": materials,
        "accessors": b.accessors,
        "bufferViews": b.views,
        "buffers": [{"uri": bin_name, "byteLength": len(b.data)}],
    }
    if cameras:
        doc["cameras"] = cameras
    ext = {}
    if lights:
        ext["KHR_lights_punctual"] = {"lights": lights}
    if scene.global_medium is not None:
        ext["VOLTAB_participating_media"] = {"global": _gltf_medium(scene.global_medium)}
        used.add("VOLTAB_participating_media")
    if ext:
        doc["extensions"] = ext
    doc["extensionsUsed"] = sorted(used)
    return doc, bytes(b.data)


def write_gltf_doc(doc: dict, data: bytes, path) -> pathlib.Path:
    path = pathlib.Path(path)
    (path.parent / doc["buffers"][0]["uri"]).write_bytes(data)
    path.write_text(json.dumps(doc, indent=1, allow_nan=False, ensure_ascii=False) + "\n")
    return path


def write_gltf(scene: Scene, path) -> pathlib.Path:
    path = pathlib.Path(path)
    doc, data = build_gltf(scene, path.with_suffix(".bin").name)
    return write_gltf_doc(doc, data, path)


# ---------------------------------------------------------------------------------------------------
# Validation
# ---------------------------------------------------------------------------------------------------


class InvalidScene(Exception):
    pass


def _check(cond, msg):
    if not cond:
        raise InvalidScene(msg)


def closed_manifold(tris: np.ndarray, points: np.ndarray) -> bool:
    """Every edge (vertices welded by position) shared by exactly two triangles, in opposite directions."""
    _, weld = np.unique(points, axis=0, return_inverse=True)
    weld = weld.reshape(-1)
    t = weld[tris]
    if np.any((t[:, 0] == t[:, 1]) | (t[:, 1] == t[:, 2]) | (t[:, 2] == t[:, 0])):
        return False
    directed = {}
    for a, b, c in t.tolist():
        for e in ((a, b), (b, c), (c, a)):
            directed[e] = directed.get(e, 0) + 1
    return all(n == 1 and directed.get((e[1], e[0])) == 1 for e, n in directed.items())


def validate_gltf(path) -> dict:
    """Parses a .gltf and checks buffers, views, accessors (sizes, POSITION min/max), index ranges,
    node/mesh/material/light/camera references and extensionsUsed. Returns the document."""
    path = pathlib.Path(path)
    doc = json.loads(path.read_text())
    _check(doc["asset"]["version"] == "2.0", "asset.version must be 2.0")
    buffers = []
    for i, buf in enumerate(doc["buffers"]):
        data = (path.parent / buf["uri"]).read_bytes()
        _check(len(data) == buf["byteLength"], f"buffer {i}: byteLength {buf['byteLength']} != file size {len(data)}")
        buffers.append(data)
    for i, v in enumerate(doc["bufferViews"]):
        _check(v["byteOffset"] + v["byteLength"] <= len(buffers[v["buffer"]]), f"bufferView {i} out of its buffer")
        _check(v["byteOffset"] % 4 == 0, f"bufferView {i} not 4-byte aligned")

    def read(ai):
        a = doc["accessors"][ai]
        v = doc["bufferViews"][a["bufferView"]]
        n = TYPE_SIZE[a["type"]]
        size = a["count"] * n * COMPONENT_SIZE[a["componentType"]]
        _check(a.get("byteOffset", 0) + size <= v["byteLength"], f"accessor {ai} overruns bufferView")
        dt = {5126: "<f4", 5123: "<u2", 5125: "<u4", 5121: "u1"}[a["componentType"]]
        start = v["byteOffset"] + a.get("byteOffset", 0)
        arr = np.frombuffer(buffers[v["buffer"]][start:start + size], dtype=dt)
        return a, arr.reshape(a["count"], n) if n > 1 else arr

    used = set()
    for mi, mesh in enumerate(doc["meshes"]):
        for pi, prim in enumerate(mesh["primitives"]):
            _check(prim.get("mode", 4) == 4, f"mesh {mesh['name']}: primitive {pi} is not TRIANGLES")
            acc, pos = read(prim["attributes"]["POSITION"])
            _check(np.all(np.isfinite(pos)), f"mesh {mesh['name']}: non-finite positions")
            _check(acc["min"] == [float(x) for x in pos.min(axis=0)] and acc["max"] == [float(x) for x in pos.max(axis=0)],
                   f"mesh {mesh['name']}: POSITION min/max do not match the data")
            for key, ai in prim["attributes"].items():
                a, arr = read(ai)
                _check(a["count"] == len(pos), f"mesh {mesh['name']}: {key} count != POSITION count")
            _, idx = read(prim["indices"])
            _check(len(idx) % 3 == 0, f"mesh {mesh['name']}: index count not a multiple of 3")
            _check(len(idx) == 0 or int(idx.max()) < len(pos), f"mesh {mesh['name']}: index out of range")
            _check(prim["material"] < len(doc["materials"]), f"mesh {mesh['name']}: material out of range")
    for mat in doc["materials"]:
        used |= set(mat.get("extensions", {}))
        _check(all(0.0 <= c <= 1.0 for c in mat.get("emissiveFactor", [])), f"material {mat['name']}: emissiveFactor > 1")
    lights = doc.get("extensions", {}).get("KHR_lights_punctual", {}).get("lights", [])
    used |= set(doc.get("extensions", {}))
    for ni, node in enumerate(doc["nodes"]):
        _check(node.get("mesh", 0) < len(doc["meshes"]), f"node {node['name']}: mesh out of range")
        _check(node.get("camera", 0) < len(doc.get("cameras", [])) or "camera" not in node, f"node {node['name']}: camera out of range")
        for c in node.get("children", []):
            _check(c < len(doc["nodes"]) and c != ni, f"node {node['name']}: bad child {c}")
        if "rotation" in node:
            _check(abs(sum(q * q for q in node["rotation"]) - 1.0) < 1e-9, f"node {node['name']}: rotation not unit")
        light = node.get("extensions", {}).get("KHR_lights_punctual")
        if light is not None:
            _check(light["light"] < len(lights), f"node {node['name']}: light out of range")
            used.add("KHR_lights_punctual")
    for light in lights:
        _check(light["intensity"] >= 0, f"light {light['name']}: negative intensity")
    _check(sorted(used) == sorted(doc.get("extensionsUsed", [])), f"extensionsUsed {doc.get('extensionsUsed')} != used {sorted(used)}")
    return doc


def validate_usd(path):
    """Opens a USD layer with pxr and checks every mesh (finite points, indices in range, counts
    consistent, primvar and normal lengths) and the stage metadata. Returns the stage."""
    from pxr import Usd, UsdGeom

    stage = Usd.Stage.Open(str(path))
    _check(stage is not None, f"{path}: does not open")
    _check(UsdGeom.StageHasAuthoredMetersPerUnit(stage) and UsdGeom.GetStageMetersPerUnit(stage) == 1.0,
           f"{path}: metersPerUnit must be authored as 1")
    _check(stage.HasAuthoredMetadata("upAxis") and UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.y,
           f"{path}: upAxis must be authored as Y")
    for prim in stage.Traverse():
        if not prim.IsA(UsdGeom.Mesh):
            continue
        m = UsdGeom.Mesh(prim)
        pts = np.asarray(m.GetPointsAttr().Get())
        counts = np.asarray(m.GetFaceVertexCountsAttr().Get())
        idx = np.asarray(m.GetFaceVertexIndicesAttr().Get())
        _check(np.all(np.isfinite(pts)), f"{prim.GetPath()}: non-finite points")
        _check(int(counts.sum()) == len(idx), f"{prim.GetPath()}: faceVertexCounts do not sum to the index count")
        _check(np.all(counts >= 3), f"{prim.GetPath()}: face with fewer than 3 vertices")
        _check(int(idx.max()) < len(pts) and int(idx.min()) >= 0, f"{prim.GetPath()}: index out of range")
        _check(len(m.GetNormalsAttr().Get()) == len(pts), f"{prim.GetPath()}: normals are not per vertex")
        for pv in UsdGeom.PrimvarsAPI(prim).GetAuthoredPrimvars():
            _check(len(pv.Get()) == len(pts), f"{prim.GetPath()}: primvar {pv.GetName()} is not per vertex")
    return stage


def validate_scene(scene: Scene):
    """Checks the description itself: medium boundaries closed and manifold, triangle budget."""
    tris = sum(len(m.triangles()) for m in scene.meshes)
    _check(tris < 20000, f"{scene.name}: {tris} triangles (budget 20k)")
    for mesh in scene.meshes:
        _check(len({mesh.name for mesh in scene.meshes}) == len(scene.meshes), f"{scene.name}: duplicate mesh names")
        if scene.material(mesh.material).medium is not None:
            _check(closed_manifold(mesh.triangles(), mesh.points), f"{mesh.name}: medium boundary is not closed and manifold")
        # outward-facing normals agree with the winding
        t = mesh.triangles()
        p = mesh.points.astype(np.float64)
        fn = np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]])
        _check(np.all(np.einsum("ij,ij->i", fn, mesh.normals[t[:, 0]].astype(np.float64)) > 0),
               f"{mesh.name}: winding disagrees with the normals")


def write_scene(scene: Scene, out_dir, validate=True) -> list:
    """Writes NAME.usda, NAME.gltf and NAME.bin into out_dir; returns the paths."""
    out = pathlib.Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if validate:
        validate_scene(scene)
    usd = write_usd(scene, out / f"{scene.name}.usda")
    gltf = write_gltf(scene, out / f"{scene.name}.gltf")
    if validate:
        validate_usd(usd)
        validate_gltf(gltf)
        for p in (usd, gltf, gltf.with_suffix(".bin")):
            _check(p.stat().st_size < 1 << 20, f"{p}: larger than 1 MB")
    return [usd, gltf, gltf.with_suffix(".bin")]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", nargs="?", default=str(pathlib.Path(__file__).resolve().parents[1] / "scenes"),
                    help="output folder (default: scenes/ of the repository)")
    args = ap.parse_args(argv)
    for scene in scenes():
        paths = write_scene(scene, args.out)
        tris = sum(len(m.triangles()) for m in scene.meshes)
        sizes = ", ".join(f"{p.name} {p.stat().st_size} B" for p in paths)
        print(f"{scene.name}: {len(scene.meshes)} meshes, {tris} triangles; {sizes}")


if __name__ == "__main__":
    sys.exit(main())
