"""Interchange checks run with the Python ecosystem's own tools (not voltab's code):

- every bundled pipeline, as voltab reads it (`voltab check --dump-json`), validates against the
  committed JSON Schema with the `jsonschema` package, and a pipeline with an unknown field does
  not — so the schema is neither too loose nor too strict for real files;
- PNGs written by voltab stages open in OpenImageIO with the documented size and real content;
- usd-core is importable (the scene-import checks of later issues build on it).
"""
import json
import os
import pathlib
import subprocess

import jsonschema
import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
VOLTAB = os.environ.get("VOLTAB_BIN", str(ROOT / "target" / "debug" / "voltab"))
SCHEMA = json.loads((ROOT / "schemas" / "pipeline.schema.json").read_text())


def dump(path):
    out = subprocess.run([VOLTAB, "check", str(path), "--dump-json"], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout)


@pytest.mark.parametrize("pipeline", sorted((ROOT / "pipelines").glob("*.ron")) + [ROOT / "tables" / "golden" / "golden.ron"], ids=lambda p: p.name)
def test_bundled_pipelines_match_schema(pipeline):
    jsonschema.validate(dump(pipeline), SCHEMA)


def test_schema_rejects_unknown_fields():
    doc = dump(ROOT / "pipelines" / "default.ron")
    doc["tables"][0]["PhaseHg"]["mu_bin"] = 64
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(doc, SCHEMA)


def test_stage_png_reads_in_openimageio(tmp_path):
    import OpenImageIO as oiio

    pipe = tmp_path / "p.ron"
    pipe.write_text('(tables: [PhaseHg(id: "hg", g: [0.0, 0.8], mu_bins: 64, xi_bins: 64)], stages: [PlotPhase(id: "plot", table: "hg")])')
    out = subprocess.run([VOLTAB, "run", str(pipe), "--out", str(tmp_path / "out")], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    buf = oiio.ImageBuf(str(tmp_path / "out" / "plot.png"))
    assert not buf.has_error, buf.geterror()
    spec = buf.spec()
    assert (spec.width, spec.height) == (1024, 720)
    stats = oiio.ImageBufAlgo.computePixelStats(buf)
    # A plot is mostly white background with dark text and coloured curves: not uniform.
    assert min(stats.min[:3]) < 0.5 and max(stats.max[:3]) > 0.9


def test_usd_core_is_available():
    from pxr import Usd, UsdGeom

    stage = Usd.Stage.CreateInMemory()
    UsdGeom.Xform.Define(stage, "/root")
    assert stage.GetPrimAtPath("/root").IsValid()
