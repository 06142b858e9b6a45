//! Checks every imported scene gets, whatever its format: broken geometry, lights (the environment included)
//! and media are errors naming the node or prim; likely unit mistakes are warnings.
//!
//! **Input → output.** A [`Scene`] fresh from an importer → the same scene with degenerate triangles of
//! ordinary meshes dropped and warnings appended, or a [`SceneError`]. The rules are listed in
//! `docs/design/scene.md` ("Checks after import").

use std::collections::HashMap;

use super::summary::light_area;
use super::{Boundary, Density, LightKind, Scene, SceneError, SceneWarning};

/// Shortest mean free path accepted without a warning \[m\] ("opaque within a micron").
pub const MIN_MEAN_FREE_PATH: f64 = 1e-6;
/// Smallest optical thickness across the scene diagonal accepted without a warning ("invisible across a
/// thousand scene diagonals").
pub const MIN_DIAGONAL_THICKNESS: f64 = 1e-3;
/// Plausible irradiance range at half the scene diagonal \[W/m²\] (about 7 mlux to 70 Mlux).
pub const IRRADIANCE_RANGE: (f64, f64) = (1e-5, 1e5);

/// Runs every check (see the module doc).
pub fn check(scene: &mut Scene) -> Result<(), SceneError> {
    let file = scene.source.clone();
    let err = |loc: &str, msg: String, help: &str| SceneError::at(&file, loc, msg, help);
    let finite3 = |v: &[f64; 3]| v.iter().all(|x| x.is_finite());

    for m in &scene.meshes {
        if let Some(i) = m.positions.iter().position(|p| p.iter().any(|x| !x.is_finite())) {
            return Err(err(
                &m.name,
                format!("vertex {i} is not finite: {:?}", m.positions[i]),
                "fix or remove the vertex",
            ));
        }
        if m.to_world.iter().flatten().any(|x| !x.is_finite()) {
            return Err(err(&m.name, "the world transform is not finite".into(), "fix the node/xform transform"));
        }
        let n = m.positions.len();
        if let Some((i, t)) = m.triangles.iter().enumerate().find(|(_, t)| t.iter().any(|&v| v as usize >= n)) {
            return Err(err(
                &m.name,
                format!("triangle {i} indexes vertex {} but the mesh has {n} vertices", t.iter().max().unwrap_or(&0)),
                "fix the index buffer",
            ));
        }
        for (what, len) in [
            ("normals", Some(m.normals.len())),
            ("uv", m.uv.as_ref().map(Vec::len)),
            ("lightmap_uv", m.lightmap_uv.as_ref().map(Vec::len)),
        ] {
            if let Some(len) = len
                && len != n
            {
                return Err(err(&m.name, format!("{len} {what} for {n} vertices"), "give one value per vertex"));
            }
        }
    }
    for l in &scene.lights {
        if !finite3(&l.radiance) {
            return Err(err(&l.name, format!("light value {:?} is not finite", l.radiance), "fix the intensity"));
        }
        if l.radiance.iter().any(|&v| v < 0.0) {
            return Err(err(
                &l.name,
                format!("negative light intensity {:?}", l.radiance),
                "light intensity, exposure-scaled, and colour must be >= 0",
            ));
        }
        let vectors: Vec<[f64; 3]> = match &l.kind {
            LightKind::Point { position } => vec![*position],
            LightKind::Spot { position, direction, .. } => vec![*position, *direction],
            LightKind::Directional { direction, .. } => vec![*direction],
            LightKind::Rect { center, half_u, half_v, normal } => vec![*center, *half_u, *half_v, *normal],
            LightKind::Disk { center, normal, .. } => vec![*center, *normal],
            LightKind::Sphere { center, .. } => vec![*center],
            LightKind::EmissiveMesh { mesh } => {
                if *mesh >= scene.meshes.len() {
                    return Err(err(&l.name, format!("emissive mesh {mesh} does not exist"), "importer bug"));
                }
                vec![]
            }
        };
        if vectors.iter().any(|v| !finite3(v)) {
            return Err(err(&l.name, "light position or direction is not finite".into(), "fix its transform"));
        }
    }
    if let Some(env) = &scene.environment {
        let m = env.multiplier();
        if !(env.scale.is_finite() && env.scale >= 0.0 && finite3(&m) && env.color.iter().all(|&c| c >= 0.0)) {
            return Err(err(
                &env.name,
                format!("environment scale {} × colour {:?} must be finite and >= 0", env.scale, env.color),
                "light intensity, exposure-scaled, and colour must be finite and >= 0",
            ));
        }
        if !env.rotation.iter().all(finite3) {
            return Err(err(&env.name, "environment rotation is not finite".into(), "fix its transform"));
        }
    }
    for c in &scene.cameras {
        if !(finite3(&c.position) && finite3(&c.forward) && finite3(&c.up)) {
            return Err(err(&c.name, "camera transform is not finite".into(), "fix its transform"));
        }
    }
    let mut globals = scene.media.iter().filter(|m| m.boundary == Boundary::Global);
    if let (Some(a), Some(b)) = (globals.next(), globals.next()) {
        return Err(err(
            &b.name,
            format!("a second global medium (the first is {})", a.name),
            "keep one global medium; put local fog inside closed meshes",
        ));
    }
    for md in &scene.media {
        for (what, v) in [("sigma_s", md.sigma_s), ("sigma_a", md.sigma_a)] {
            if !finite3(&v) || v.iter().any(|&x| x < 0.0) {
                return Err(err(&md.name, format!("{what} = {v:?} must be finite and >= 0"), "fix the coefficient"));
            }
        }
        if md.g.iter().any(|g| g.is_nan() || g.abs() >= 1.0) {
            return Err(err(
                &md.name,
                format!("anisotropy g = {:?} must satisfy |g| < 1", md.g),
                "HG g = ±1 is a delta phase function; use |g| <= 0.999",
            ));
        }
        if let Density::ExponentialHeight { rho, falloff, direction, offset } = &md.density {
            let len = direction.iter().map(|x| x * x).sum::<f64>().sqrt();
            if !(rho.is_finite()
                && *rho >= 0.0
                && falloff.is_finite()
                && finite3(offset)
                && len.is_finite()
                && len > 0.0)
            {
                return Err(err(
                    &md.name,
                    format!(
                        "exponential density rho {rho}, falloff {falloff}, direction {direction:?}, offset {offset:?}"
                    ),
                    "rho must be >= 0, falloff and offset finite, direction non-zero",
                ));
            }
        }
        if let Boundary::Mesh(i) = md.boundary {
            let Some(mesh) = scene.meshes.get(i) else {
                return Err(err(&md.name, format!("boundary mesh {i} does not exist"), "importer bug"));
            };
            closed_manifold(mesh).map_err(|msg| {
                err(
                    &mesh.name,
                    format!("boundary of medium {} {msg}", md.name),
                    "a medium needs a closed, consistently wound manifold mesh: close holes, weld seams, remove \
                     degenerate and duplicate faces",
                )
            })?;
        }
    }
    drop_degenerate(scene);
    unit_sanity(scene);
    Ok(())
}

fn weld_key(p: [f32; 3]) -> [u32; 3] {
    // +0.0 and −0.0 are the same point.
    p.map(|x| if x == 0.0 { 0 } else { x.to_bits() })
}

fn is_degenerate(p: [[f32; 3]; 3]) -> bool {
    let d = |a: [f32; 3], b: [f32; 3]| [0, 1, 2].map(|c| f64::from(b[c]) - f64::from(a[c]));
    let (u, v) = (d(p[0], p[1]), d(p[0], p[2]));
    let n = [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]];
    n.iter().all(|&x| x == 0.0)
}

/// Every edge (vertices welded by position) is shared by exactly two triangles, traversed in opposite
/// directions, and no triangle is degenerate.
fn closed_manifold(mesh: &super::Mesh) -> Result<(), String> {
    if mesh.triangles.is_empty() {
        return Err("has no triangles".into());
    }
    let mut ids: HashMap<[u32; 3], u32> = HashMap::new();
    let welded: Vec<u32> = mesh
        .positions
        .iter()
        .map(|&p| {
            let n = ids.len() as u32;
            *ids.entry(weld_key(p)).or_insert(n)
        })
        .collect();
    let mut directed: HashMap<(u32, u32), u32> = HashMap::new();
    for (ti, t) in mesh.triangles.iter().enumerate() {
        let w = t.map(|v| welded[v as usize]);
        if w[0] == w[1] || w[1] == w[2] || w[0] == w[2] || is_degenerate(t.map(|v| mesh.positions[v as usize])) {
            return Err(format!("has a degenerate triangle (triangle {ti})"));
        }
        for k in 0..3 {
            *directed.entry((w[k], w[(k + 1) % 3])).or_default() += 1;
        }
    }
    let mut open = 0usize;
    let mut inconsistent = 0usize;
    let mut example = None;
    for (&(a, b), &n) in &directed {
        let back = directed.get(&(b, a)).copied().unwrap_or(0);
        if back > 0 && a > b {
            continue; // the pair is judged once, from its other direction
        }
        if n > 1 || back > 1 {
            inconsistent += 1;
        } else if back == 0 {
            open += 1;
        } else {
            continue;
        }
        example.get_or_insert((a, b));
    }
    if open + inconsistent == 0 {
        return Ok(());
    }
    let pos: HashMap<u32, [u32; 3]> = ids.iter().map(|(k, v)| (*v, *k)).collect();
    let at = |i: u32| pos[&i].map(f32::from_bits);
    let (a, b) = example.unwrap_or_default();
    Err(format!(
        "is not a closed manifold: {open} open (boundary) edges, {inconsistent} edges shared by more than two faces \
         or wound inconsistently, e.g. the edge {:?} – {:?}",
        at(a),
        at(b)
    ))
}

fn drop_degenerate(scene: &mut Scene) {
    let mut warnings = Vec::new();
    for m in scene.meshes.iter_mut().filter(|m| m.medium.is_none()) {
        let before = m.triangles.len();
        let positions = &m.positions;
        m.triangles.retain(|t| !is_degenerate(t.map(|v| positions[v as usize])));
        let dropped = before - m.triangles.len();
        if dropped > 0 {
            warnings.push(SceneWarning {
                location: m.name.clone(),
                message: format!("{dropped} of {before} triangles have zero area and were dropped"),
                help: "remove degenerate faces in the authoring tool".into(),
            });
        }
    }
    scene.warnings.extend(warnings);
}

fn unit_sanity(scene: &mut Scene) {
    let diag = scene.diagonal();
    let bounds = scene.bounds();
    let mut warnings = Vec::new();
    for md in &scene.media {
        let t = md.sigma_t();
        let max_t = t.iter().copied().fold(0.0, f64::max) * md.density.max_over(bounds);
        if max_t == 0.0 {
            warnings.push(SceneWarning {
                location: md.name.clone(),
                message: "the medium has zero extinction (it does nothing)".into(),
                help: "remove it, or give it sigma_s / sigma_a".into(),
            });
        } else if 1.0 / max_t < MIN_MEAN_FREE_PATH {
            warnings.push(SceneWarning {
                location: md.name.clone(),
                message: format!(
                    "mean free path {:.3e} m: the medium is opaque within a micron (sigma_t up to {max_t:.3e} 1/m)",
                    1.0 / max_t
                ),
                help: "coefficients are in 1/m (USD: 1/stage unit); values in 1/mm or 1/um, or a wrong \
                       metersPerUnit, give this"
                    .into(),
            });
        } else if diag > 0.0 && max_t * diag < MIN_DIAGONAL_THICKNESS {
            warnings.push(SceneWarning {
                location: md.name.clone(),
                message: format!(
                    "optical thickness {:.3e} across the scene diagonal ({diag:.3} m): invisible across a thousand \
                     diagonals",
                    max_t * diag
                ),
                help: "coefficients are in 1/m; values in 1/km, or a scene authored in the wrong unit, give this"
                    .into(),
            });
        }
    }
    if diag > 0.0 {
        let d = 0.5 * diag;
        let (lo, hi) = IRRADIANCE_RANGE;
        for l in &scene.lights {
            let peak = l.radiance.iter().copied().fold(0.0, f64::max);
            if peak == 0.0 {
                continue;
            }
            let e = match &l.kind {
                LightKind::Point { .. } | LightKind::Spot { .. } => peak / (d * d),
                LightKind::Directional { .. } => peak,
                kind => peak * (light_area(scene, kind).unwrap_or(0.0) / (d * d)).min(std::f64::consts::PI),
            };
            let hint = if e > hi {
                "far too bright: a photometric value entered without the 683 lm/W conversion, watts entered as \
                 candela/nits, or a scene in centimetres read as metres"
            } else if e < lo {
                "far too dark: a radiometric value entered where photometric is expected, an intensity in \
                 kilo-units, or a scene in metres read as centimetres"
            } else {
                continue;
            };
            warnings.push(SceneWarning {
                location: l.name.clone(),
                message: format!(
                    "irradiance {e:.3e} W/m^2 at half the scene diagonal ({d:.3} m) is outside [{lo:e}, {hi:e}]"
                ),
                help: format!("{hint}; voltab's light units are in docs/design/scene.md"),
            });
        }
    }
    scene.warnings.extend(warnings);
}

#[cfg(test)]
mod tests;
