"""Mitsuba 3 as voltab's independent reference (issue 30).

`voltab export mitsuba SCENE --out DIR` writes the imported scene as `DIR/scene.xml` (+ meshes, grid
volumes, `export.json`); this package renders what voltab's stages compute from it:

- images from the exported camera (`kind: "image"`);
- irradiance at points with normals (`kind: "irradiance"`), see `harness.irradiance`;
- radiance along rays (`kind: "radiance"`);

each for a list of Mitsuba `max_depth` values (to split scattering orders) and over `runs` independent
seeds, reporting the mean and the variance of that mean (the reference's own noise). Entry points:
`python -m mitsuba_ref REQUEST.json` and `harness.Reference` for tests.
"""
