"""First stage comparison against Mitsuba (issue 30, for issue 31): irradiance at the lightmap bake's own
texels on the bundled fog room. `voltab export mitsuba --texels N` writes the texels with the bake's
table-free modes (Surface, Shadow) and voltab's internal volumetric path tracer; Mitsuba evaluates the
same (position, normal) pairs. Errors are noise-corrected (`mitsuba_ref.compare`), relative to Mitsuba's
converged mean, with the floor stated.

Pinned: the internal reference agrees with Mitsuba (noise-corrected relative RMSE ≤ 5 %, means within
3 %), so a shared simplification or unit slip between the bake's reference and the scene shows up here.
Printed (the measurement for issue 31, not a target of this test): Surface and Shadow against Mitsuba.
"""
import json
import os
import pathlib
import subprocess
import sys

import numpy as np
import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
VOLTAB = os.environ.get("VOLTAB_BIN", str(ROOT / "target" / "debug" / "voltab"))
sys.path.insert(0, str(ROOT / "python"))

pytest.importorskip("mitsuba")
from mitsuba_ref.compare import noise_corrected  # noqa: E402
from mitsuba_ref.harness import Reference  # noqa: E402


def test_fog_room_texels_internal_reference_and_modes_against_mitsuba(tmp_path):
    out = tmp_path / "fog_room"
    r = subprocess.run([VOLTAB, "export", "mitsuba", str(ROOT / "scenes" / "fog_room.gltf"), "--out", str(out),
                        "--texels", "48"], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    tex = json.loads((out / "texels.json").read_text())
    pts, nrm = np.array(tex["positions"]), np.array(tex["normals"])
    assert 24 <= len(pts) <= 48
    ref = Reference(out)
    mean, var = ref.irradiance(pts, nrm, spp=512, max_depth=-1, runs=4, seed=3)
    assert mean.mean() > 0
    internal = np.array(tex["internal_reference"]["mean"])
    var_internal = np.array(tex["internal_reference"]["stderr"]) ** 2
    agree = noise_corrected(internal, mean, var, var_internal)
    ratio = internal.mean() / mean.mean()
    print(f"\nfog room, {len(pts)} texels, Mitsuba {ref.variant}: mean {mean.mean():.4f} W/m²")
    print(f"  internal volpath: rel. RMSE {agree['text']}, mean ×{ratio:.4f}")
    for m in tex["modes"]:
        e = noise_corrected(np.array(m["irradiance"]), mean, var)
        print(f"  bake {m['mode']}: rel. RMSE {e['text']}, mean ×{np.mean(m['irradiance']) / mean.mean():.4f}")
    assert abs(ratio - 1) < 0.03
    assert agree["below_floor"] or agree["rel_rmse"] <= 0.05, agree
