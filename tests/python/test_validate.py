"""`voltab validate pipelines/default.ron --quality quick` (issue 30's "done when"): every stage of the
default pipeline judged against Mitsuba 3, with errors that cannot flatter.

Pinned here:
- every stage of the pipeline is in validation.json, compared or listed with the reason it is not;
- every compared error is noise-corrected and stated against its floor: a number is never below the
  floor, the 95 % interval contains it, and where a technique target is checked the floor is small
  enough (≤ 5 %) to judge it;
- the stages' internal references (the god-ray marcher, the translucent path tracer) are judged too;
- the technique targets that the quick comparison covers, at the issues' thresholds. Targets the stages
  miss today are strict xfails carrying the measured numbers (an unexpected pass fails, so the mark must
  be removed when a fix lands).

The release binary runs it (the default pipeline's ZH tables take minutes to compile in a debug build):
VOLTAB_RELEASE_BIN, else target/release/voltab (scripts/test-all.sh builds it for the run_report test).
"""
import json
import os
import pathlib
import subprocess

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
VOLTAB = os.environ.get("VOLTAB_RELEASE_BIN", str(ROOT / "target" / "release" / "voltab"))

pytest.importorskip("mitsuba")


@pytest.fixture(scope="module")
def validation(tmp_path_factory):
    assert pathlib.Path(VOLTAB).exists(), f"{VOLTAB} is missing: run `cargo build --release` first"
    out = tmp_path_factory.mktemp("validate")
    env = dict(os.environ, VOLTAB_PYTHONPATH=str(ROOT / "python"))
    r = subprocess.run([VOLTAB, "validate", str(ROOT / "pipelines" / "default.ron"), "--quality", "quick",
                        "--out", str(out / "report"), "--tables", str(out / "tables")],
                       capture_output=True, text=True, timeout=1800, cwd=ROOT, env=env)
    assert r.returncode == 0, r.stderr[-4000:]
    print("\n" + r.stdout)
    v = json.loads((out / "report" / "validation.json").read_text())
    return out / "report", v, {s["stage"]: s for s in v["stages"]}


RESOLVED = {"fog_room_bake", "window_room_god_rays", "window_room_pop"}


def stage_ids():
    r = subprocess.run([VOLTAB, "check", str(ROOT / "pipelines" / "default.ron")], capture_output=True,
                       text=True, timeout=120, check=True)
    return [line.split()[1] for line in r.stdout.splitlines() if line.strip().startswith("stage ")]


def method(stages, stage, name):
    return next(m for m in stages[stage]["methods"] if m["name"] == name)


def test_every_stage_is_judged_or_says_why_not(validation):
    folder, v, stages = validation
    assert sorted({sid.split("/")[0] for sid in stages}) == sorted(stage_ids())
    md = (folder / "validation.md").read_text()
    assert (folder / "error_vs_time.png").stat().st_size > 1000
    for sid, s in stages.items():
        assert sid in md
        if s["not_compared"] is not None:
            assert s["kind"] == "PlotPhase" or "issue" in s["not_compared"], s
            continue
        assert s["methods"] and s["reference_runs"] >= 4 and s["reference_s"] > 0
        for f in s["files"]:
            assert pathlib.Path(f).exists(), f
        for m in s["methods"]:
            # Where this file checks a technique target the comparison must resolve 5 %; elsewhere the
            # floor is stated beside the number (the translucent materials' caustic paths and the lit
            # fog are noisy in Mitsuba at quick settings).
            resolve = 0.05 if sid in RESOLVED else 0.5
            assert m["floor"] is not None and 0 < m["floor"] <= resolve, (sid, m)
            if m["rel_rmse"] is None:
                assert m["text"] == f"< floor {m['floor']:.3g}", m
            else:
                lo, hi = m["ci95"]
                assert m["rel_rmse"] >= m["floor"] and lo <= m["rel_rmse"] <= hi, (sid, m)
                # The reference's noise only ever inflates the raw error.
                assert m["raw_rel_rmse"] >= m["rel_rmse"], (sid, m)
    compared = {s["kind"] for s in stages.values() if s["not_compared"] is None}
    assert compared == {"BakeLightmaps", "EpipolarShadows", "ImageFog", "TranslucentRender", "PopRender"}
    # Every material of the translucent stage is its own row.
    assert {"translucent_materials/Wax", "translucent_materials/Oil", "translucent_materials/Skin"} <= set(stages)


def test_bake_full_mode_meets_issue_31_error_and_mean_targets(validation):
    _, _, stages = validation
    full = method(stages, "fog_room_bake", "full")
    assert full["rel_rmse"] is None or full["rel_rmse"] <= 0.10, full
    assert abs(full["method_mean"] / full["reference_mean"] - 1) <= 0.03, full


@pytest.mark.xfail(strict=True, reason="issue 31: on the fog room's 64 quick texels the Full mode (128 samples "
                   "per texel) measures 9.3 % [8.1, 10.3] against Surface's 7.8 % [5.9, 9.3] (floor 3.3 %)")
def test_bake_full_mode_is_never_worse_than_surface_or_shadow(validation):
    _, _, stages = validation
    full = method(stages, "fog_room_bake", "full")["rel_rmse"] or 0.0
    for other in ("surface", "shadow"):
        assert full <= (method(stages, "fog_room_bake", other)["rel_rmse"] or 0.0)


def test_god_rays_meet_issue_32_targets(validation):
    # Measured 13.0 % [12.7, 13.3] (floor 2.3 %), mean ×1.046 while the sun was not attenuated on its way
    # through the fog; 2.4 % [0.0, 3.5], mean ×0.999 with the light entering the fog box at its faces.
    _, _, stages = validation
    epi = method(stages, "window_room_god_rays", "epipolar")
    assert epi["rel_rmse"] is None or epi["rel_rmse"] <= 0.05, epi
    assert abs(epi["method_mean"] / epi["reference_mean"] - 1) <= 0.03, epi


@pytest.mark.xfail(strict=True, reason="issue 33: scattered light (surfaces black on both sides) measures 43.2 % "
                   "[42.9, 43.4] (floor 1.3 %) in the window room and 53.7 % [49.9, 57.3] (floor 9.7 %) in the "
                   "fog room on 4×4 blocks, means ×1.053 and ×1.011, against within 15 %")
def test_pop_meets_issue_33_targets_on_the_bundled_rooms(validation):
    _, _, stages = validation
    for sid in ("window_room_pop", "fog_room_pop"):
        pop = method(stages, sid, "pop")
        assert pop["rel_rmse"] is None or pop["rel_rmse"] <= 0.15, pop


@pytest.mark.xfail(strict=True, reason="issue 34: 4×4-block relative RMSE Wax 17.4 % [13.2, 20.8] (floor 8.7 %), "
                   "Oil 23.0 % [20.5, 25.1] (floor 9.3 %), Skin < floor 44 %; means ×0.971, ×0.970, ×0.963 "
                   "against ≤ 8 % and within 3 %")
def test_translucent_materials_meet_issue_34_targets(validation):
    _, _, stages = validation
    for name in ("Wax", "Oil", "Skin"):
        m = method(stages, f"translucent_materials/{name}", "point-based")
        assert m["rel_rmse"] is None or m["rel_rmse"] <= 0.08, m
        assert abs(m["method_mean"] / m["reference_mean"] - 1) <= 0.03, m


@pytest.mark.xfail(strict=True, reason="issue 36: the outdoor fog's 4×4 blocks measure 50.6 % [49.2, 51.9] "
                   "(floor 8.5 %), mean ×1.161, against ≤ 18 %; attenuation only 70.9 %, no fog 706 %")
def test_image_fog_meets_issue_36_block_target(validation):
    _, _, stages = validation
    fog = method(stages, "outdoor_fog", "fog")
    assert fog["rel_rmse"] is None or fog["rel_rmse"] <= 0.18, fog


def test_image_fog_beats_attenuation_only_and_no_fog(validation):
    # iser2018's claim against its baselines, on the same pixels: multiple scattering brings the image
    # closer to the physics than attenuation alone, which is closer than no fog.
    _, _, stages = validation
    e = {n: method(stages, "outdoor_fog", n)["rel_rmse"] for n in ("fog", "attenuation only", "no fog")}
    assert e["fog"] < e["attenuation only"] < e["no fog"], e


def test_internal_references_are_judged_too(validation):
    # issue 30: each stage's internal reference is checked against Mitsuba, so a simplification it shares
    # with the method shows. The god-ray marcher integrates the stage's own light model: its mean equals
    # the epipolar image's within 1 %; when both left out the light's attenuation before it scatters
    # (stop 41) both were ×1.045 off Mitsuba, now the marcher's mean is within 3 % of it as well.
    _, _, stages = validation
    epi = method(stages, "window_room_god_rays", "epipolar")
    marcher = method(stages, "window_room_god_rays", "internal reference (128-step BVH marcher, mean of 2 runs)")
    assert abs(epi["method_mean"] / marcher["method_mean"] - 1) < 0.01, (epi, marcher)
    # Its own jitter noise (from its two runs) is subtracted too: measured 2.7 % [0.7, 3.8] (floor 2.4 %);
    # 4.4 % while that noise was counted as its error.
    assert marcher["floor"] <= 0.05 and (marcher["rel_rmse"] or 0.0) <= 0.05, marcher
    assert abs(marcher["method_mean"] / marcher["reference_mean"] - 1) <= 0.03, marcher
    # The translucent path tracer's own noise (256 paths) is subtracted: Wax < floor 15.7 %, Oil 21.0 %
    # [9.2, 28.2] (floor 18.3 %), Skin < floor 44 %; its means are within 2 % of Mitsuba's.
    for name in ("Wax", "Oil", "Skin"):
        pt = method(stages, f"translucent_materials/{name}", "internal reference (path tracer, 256 paths)")
        assert pt["floor"] is not None and abs(pt["method_mean"] / pt["reference_mean"] - 1) <= 0.03, pt
