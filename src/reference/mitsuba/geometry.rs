//! Small geometry the export needs: closed-mesh volume and containment (which medium surrounds a point),
//! orthonormal frames, row-major affine matrices.

use glam::DVec3;

use crate::scene::{Boundary, Mesh, Scene};

/// `a / |a|` (as a product with `1/|a|`), `None` for a zero or non-finite vector.
pub(crate) fn unit(a: DVec3) -> Option<DVec3> {
    let n = a.length();
    (n > 0.0 && n.is_finite()).then(|| a * (1.0 / n))
}

/// Two unit vectors completing `n` to a right-handed orthonormal frame (`t × b = n`).
pub(crate) fn frame(n: DVec3) -> (DVec3, DVec3) {
    let helper = if n.x.abs() < 0.9 { DVec3::X } else { DVec3::Y };
    let t = unit(helper.cross(n)).unwrap_or(DVec3::X);
    (t, n.cross(t))
}

/// Row-major affine matrix with the given columns and translation.
pub(crate) fn affine(c0: DVec3, c1: DVec3, c2: DVec3, t: DVec3) -> [[f64; 4]; 4] {
    [[c0.x, c1.x, c2.x, t.x], [c0.y, c1.y, c2.y, t.y], [c0.z, c1.z, c2.z, t.z], [0.0, 0.0, 0.0, 1.0]]
}

fn vertex(m: &Mesh, i: u32) -> DVec3 {
    DVec3::from_array(m.positions[i as usize].map(f64::from))
}

/// Signed volume of a mesh \[m³\] (positive for a closed mesh whose triangles wind counter-clockwise seen
/// from outside, i.e. outward normals).
pub(crate) fn signed_volume(m: &Mesh) -> f64 {
    m.triangles.iter().map(|t| vertex(m, t[0]).dot(vertex(m, t[1]).cross(vertex(m, t[2])))).sum::<f64>() / 6.0
}

/// Whether `p` is inside the closed mesh `m` (crossing parity along a fixed, slightly skewed direction
/// so that the ray misses edges and vertices of axis-aligned geometry).
pub(crate) fn contains(m: &Mesh, p: DVec3) -> bool {
    let d = DVec3::new(0.8017837257372732, 0.2672612419124244, 0.5345224838248488);
    let mut crossings = 0usize;
    for t in &m.triangles {
        let (a, b, c) = (vertex(m, t[0]), vertex(m, t[1]), vertex(m, t[2]));
        // Möller–Trumbore.
        let (e1, e2) = (b - a, c - a);
        let h = d.cross(e2);
        let det = e1.dot(h);
        if det.abs() < 1e-300 {
            continue;
        }
        let s = p - a;
        let u = s.dot(h) / det;
        if !(0.0..=1.0).contains(&u) {
            continue;
        }
        let q = s.cross(e1);
        let v = d.dot(q) / det;
        if v < 0.0 || u + v > 1.0 {
            continue;
        }
        if e2.dot(q) / det > 0.0 {
            crossings += 1;
        }
    }
    crossings % 2 == 1
}

/// The medium surrounding `p`: the innermost closed medium mesh containing it (smallest volume), other
/// than `exclude`; else the global medium when `p` lies in its region `global_box`; else `None` (vacuum).
pub(crate) fn medium_at(
    scene: &Scene,
    p: DVec3,
    exclude: Option<usize>,
    global_box: Option<(DVec3, DVec3)>,
) -> Option<usize> {
    let mut best: Option<(f64, usize)> = None;
    for (i, med) in scene.media.iter().enumerate() {
        let Boundary::Mesh(mesh) = med.boundary else { continue };
        if Some(mesh) == exclude || mesh >= scene.meshes.len() {
            continue;
        }
        let m = &scene.meshes[mesh];
        if contains(m, p) {
            let vol = signed_volume(m).abs();
            if best.is_none_or(|(v, _)| vol < v) {
                best = Some((vol, i));
            }
        }
    }
    if let Some((_, i)) = best {
        return Some(i);
    }
    let inside = global_box.is_some_and(|(lo, hi)| p.cmpge(lo).all() && p.cmple(hi).all());
    if inside { scene.media.iter().position(|m| m.boundary == Boundary::Global) } else { None }
}

#[cfg(test)]
mod tests;
