"""The god rays (issue 32) against Mitsuba 3 on stress variants of the bundled window room that the
default pipeline does not cover (issue 30: scenes that stress what the paper claims):

- `grazing`: the sun 10° off the window wall's plane, so only thin, long shafts enter the room;
- `thick`: fog 12.5× denser (σ_s = 0.5 /m, about two mean free paths across the room).

Each variant is the bundled scene with one value changed, written next to a copy of its buffer; both
run through `voltab validate --quality quick` (single scattering: only the sun, black surfaces, Mitsuba
max_depth 2 − 1). Targets are issue 32's (≤ 5 % per-pixel relative RMSE, mean within 3 %); missed ones
are strict xfails carrying the measured numbers.
"""
import json
import math
import os
import pathlib
import shutil
import subprocess

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
VOLTAB = os.environ.get("VOLTAB_RELEASE_BIN", str(ROOT / "target" / "release" / "voltab"))

pytest.importorskip("mitsuba")


def rotation_from_minus_z(d):
    """Unit quaternion (x, y, z, w) turning glTF's light axis −Z onto the unit vector `d`."""
    a = (0.0, 0.0, -1.0)
    axis = (a[1] * d[2] - a[2] * d[1], a[2] * d[0] - a[0] * d[2], a[0] * d[1] - a[1] * d[0])
    q = (*axis, 1.0 + sum(x * y for x, y in zip(a, d)))
    n = math.sqrt(sum(x * x for x in q))
    return [x / n for x in q]


@pytest.fixture(scope="module")
def stress(tmp_path_factory):
    assert pathlib.Path(VOLTAB).exists(), f"{VOLTAB} is missing: run `cargo build --release` first"
    d = tmp_path_factory.mktemp("god_rays_stress")
    base = json.loads((ROOT / "scenes" / "window_room.gltf").read_text())
    shutil.copy(ROOT / "scenes" / "window_room.bin", d / "window_room.bin")
    sun = [-0.17, -0.45, 0.88]
    n = math.sqrt(sum(x * x for x in sun))
    variants = {
        "grazing": lambda g: next(x for x in g["nodes"] if x.get("name") == "sun").update(
            rotation=rotation_from_minus_z([x / n for x in sun])),
        "thick": lambda g: g["extensions"]["VOLTAB_participating_media"]["global"].update(sigmaS=[0.5] * 3),
    }
    stages = []
    for name, change in variants.items():
        g = json.loads(json.dumps(base))
        change(g)
        (d / f"{name}.gltf").write_text(json.dumps(g))
        stages.append(f'EpipolarShadows(id: "{name}", scene: "{name}.gltf", width: 640, height: 480, '
                      f'colour_samples: 1, reference_steps: 128)')
    (d / "stress.ron").write_text("(\n    stages: [\n        " + ",\n        ".join(stages) + ",\n    ],\n)\n")
    env = dict(os.environ, VOLTAB_PYTHONPATH=str(ROOT / "python"))
    r = subprocess.run([VOLTAB, "validate", str(d / "stress.ron"), "--quality", "quick", "--out", str(d / "report")],
                       capture_output=True, text=True, timeout=900, cwd=ROOT, env=env)
    assert r.returncode == 0, r.stderr[-4000:]
    print("\n" + r.stdout)
    v = json.loads((d / "report" / "validation.json").read_text())
    return {s["stage"]: {m["name"]: m for m in s["methods"]} for s in v["stages"]}


def test_the_variants_are_judged_above_a_small_floor(stress):
    assert set(stress) == {"grazing", "thick"}
    for stage, methods in stress.items():
        epi = methods["epipolar"]
        assert epi["floor"] is not None and epi["floor"] <= 0.08, (stage, epi)
        assert epi["method_mean"] > 0 and math.isfinite(epi["method_mean"]), (stage, epi)


def test_thick_fog_mean_is_within_3_percent(stress):
    epi = stress["thick"]["epipolar"]
    assert abs(epi["method_mean"] / epi["reference_mean"] - 1) <= 0.03, epi


@pytest.mark.xfail(strict=True, reason="issue 32: thick fog measures 5.7 % [4.9, 6.4] (floor 2.6 %), mean ×0.973 "
                   "(the BVH marcher ×0.973: a shared 2.7 % deficit not yet explained), against ≤ 5 %")
def test_thick_fog_meets_the_per_pixel_target(stress):
    epi = stress["thick"]["epipolar"]
    assert epi["rel_rmse"] is None or epi["rel_rmse"] <= 0.05, epi


def test_grazing_sun_mean_is_within_3_percent(stress):
    # Measured ×1.065 while a view-ray sample took the depth of the pixel it falls in: on the ceiling,
    # which the camera sees at a grazing angle, samples ran up to half a pixel's depth change past the
    # surface into the lit fog above it. With the depth blended between pixels of one surface: ×1.025.
    epi = stress["grazing"]["epipolar"]
    assert abs(epi["method_mean"] / epi["reference_mean"] - 1) <= 0.03, epi


@pytest.mark.xfail(strict=True, reason="issue 32: the grazing sun measures 11.4 % [8.1, 13.9] per pixel (floor "
                   "7.3 %; 17.5 % before the depth blend), against ≤ 5 %")
def test_grazing_sun_meets_the_per_pixel_target(stress):
    epi = stress["grazing"]["epipolar"]
    assert epi["rel_rmse"] is None or epi["rel_rmse"] <= 0.05, epi
