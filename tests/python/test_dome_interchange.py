"""USD dome lights as usd-core (pxr) authors and reads them, against `voltab scene --json`'s `environment`.

The layers are written through pxr's UsdLux schema API (so the attribute names voltab reads are the
schema's), and the expected values come from pxr's own reading of them:

- the texture: the attribute's `resolvedPath` as pxr resolves it, for a dome authored in a sublayer one
  folder below the root layer with a relative `@sky.exr@` (a decoy of the same name sits next to the root);
- the radiance per texel value: pxr's `intensity`, `exposure`, `color` through UsdLux's
  `intensity · 2^exposure · color` over 683 lm/W;
- the rotation: the map axes through pxr's `ComputeLocalToWorldTransform` (translation and uniform scale
  removed), and for `DomeLight_1` on a Z-up stage the UsdLux text itself (`poleAxis = "scene"`: the top pole
  on the stage's up axis, which is voltab's +Y);
- a `mirroredBall` texture drops the dome with a warning naming the prim.
"""
import json
import math
import os
import pathlib
import shutil
import subprocess

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[2]
VOLTAB = os.environ.get("VOLTAB_BIN", str(ROOT / "target" / "debug" / "voltab"))
K = 683.0


def scene_json(path):
    out = subprocess.run([VOLTAB, "scene", str(path), "--json"], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert "panicked" not in out.stderr, out.stderr
    return json.loads(out.stdout)


def new_stage(path, up):
    from pxr import Usd, UsdGeom

    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    UsdGeom.SetStageUpAxis(stage, up)
    return stage


def test_dome_in_a_sublayer_reads_as_pxr_reads_it(tmp_path):
    from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux

    (tmp_path / "layers").mkdir()
    shutil.copy(ROOT / "scenes" / "sky.exr", tmp_path / "layers" / "sky.exr")
    shutil.copy(ROOT / "scenes" / "sky.exr", tmp_path / "sky.exr")  # decoy next to the root layer
    sub = Usd.Stage.CreateNew(str(tmp_path / "layers" / "dome.usda"))
    rig = UsdGeom.Xform.Define(sub, "/Rig")
    rig.AddTranslateOp().Set(Gf.Vec3d(5, 6, 7))
    rig.AddScaleOp().Set(Gf.Vec3f(2, 2, 2))
    dome = UsdLux.DomeLight.Define(sub, "/Rig/Sky")
    dome.CreateIntensityAttr(1.5)
    dome.CreateExposureAttr(2.0)
    dome.CreateColorAttr(Gf.Vec3f(0.9, 0.6, 0.3))
    dome.CreateTextureFileAttr(Sdf.AssetPath("sky.exr"))
    dome.CreateTextureFormatAttr(UsdLux.Tokens.latlong)
    dome.AddRotateYOp().Set(90.0)
    dome.AddRotateXOp().Set(30.0)
    sub.GetRootLayer().Save()
    root = new_stage(tmp_path / "root.usda", UsdGeom.Tokens.y)
    root.GetRootLayer().subLayerPaths.append("layers/dome.usda")
    root.GetRootLayer().Save()

    stage = Usd.Stage.Open(str(tmp_path / "root.usda"))
    prim = UsdLux.DomeLight(stage.GetPrimAtPath("/Rig/Sky"))
    resolved = prim.GetTextureFileAttr().Get().resolvedPath
    assert resolved and pathlib.Path(resolved).samefile(tmp_path / "layers" / "sky.exr"), resolved
    intensity, exposure = prim.GetIntensityAttr().Get(), prim.GetExposureAttr().Get()
    color = list(prim.GetColorAttr().Get())
    m = UsdGeom.XformCache().GetLocalToWorldTransform(prim.GetPrim())
    axes = [m.TransformDir(Gf.Vec3d(*e)).GetNormalized() for e in np.eye(3)]

    env = scene_json(tmp_path / "root.usda")["environment"]
    assert env is not None
    assert env["name"] == "/Rig/Sky"
    assert pathlib.Path(env["texture"]).samefile(resolved)
    scale = intensity * 2.0**exposure / K
    assert math.isclose(env["scale"], scale, rel_tol=1e-12), (env["scale"], scale)
    assert np.allclose(env["color"], color, rtol=0, atol=1e-7), (env["color"], color)
    # Column j of voltab's rotation is the world direction of the dome's axis j (Y-up, metres: no frame).
    assert np.allclose(env["rotation"], [list(a) for a in axes], atol=1e-6), (env["rotation"], axes)


def test_dome_light_1_pole_follows_the_stage_up_axis(tmp_path):
    from pxr import UsdGeom, UsdLux

    stage = new_stage(tmp_path / "zup.usda", UsdGeom.Tokens.z)
    dome = UsdLux.DomeLight_1.Define(stage, "/Sky")
    assert dome.GetPoleAxisAttr().Get() == UsdLux.Tokens.scene  # the schema's fallback
    stage.GetRootLayer().Save()
    env = scene_json(tmp_path / "zup.usda")["environment"]
    # UsdLux: with poleAxis "scene" the top pole is on the stage's up axis (+Z here), which is voltab's +Y.
    assert np.allclose(env["rotation"][1], [0, 1, 0], atol=1e-12), env["rotation"]
    assert env["texture"] is None
    assert math.isclose(env["scale"], 1.0 / K, rel_tol=1e-12)  # intensity fallback 1


def test_mirrored_ball_dome_is_dropped_with_a_warning(tmp_path):
    from pxr import Sdf, UsdGeom, UsdLux

    stage = new_stage(tmp_path / "ball.usda", UsdGeom.Tokens.y)
    dome = UsdLux.DomeLight.Define(stage, "/Ball")
    dome.CreateTextureFileAttr(Sdf.AssetPath("ball.exr"))
    dome.CreateTextureFormatAttr(UsdLux.Tokens.mirroredBall)
    stage.GetRootLayer().Save()
    doc = scene_json(tmp_path / "ball.usda")
    assert doc["environment"] is None
    assert any(w["location"] == "/Ball" and "mirroredBall" in w["message"] for w in doc["warnings"]), doc["warnings"]
