//! Small geometry the export needs: closed-mesh volume and containment (which medium surrounds a point),
//! orthonormal frames, row-major affine matrices.

use crate::scene::{Boundary, Mesh, Scene};

pub(crate) type V3 = [f64; 3];

pub(crate) fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

pub(crate) fn add(a: V3, b: V3) -> V3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

pub(crate) fn scale(a: V3, s: f64) -> V3 {
    a.map(|v| v * s)
}

pub(crate) fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

pub(crate) fn cross(a: V3, b: V3) -> V3 {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

pub(crate) fn norm(a: V3) -> f64 {
    dot(a, a).sqrt()
}

/// `a / |a|`, `None` for a zero or non-finite vector.
pub(crate) fn unit(a: V3) -> Option<V3> {
    let n = norm(a);
    (n > 0.0 && n.is_finite()).then(|| scale(a, 1.0 / n))
}

/// Two unit vectors completing `n` to a right-handed orthonormal frame (`t × b = n`).
pub(crate) fn frame(n: V3) -> (V3, V3) {
    let helper = if n[0].abs() < 0.9 { [1.0, 0.0, 0.0] } else { [0.0, 1.0, 0.0] };
    let t = unit(cross(helper, n)).unwrap_or([1.0, 0.0, 0.0]);
    (t, cross(n, t))
}

/// Row-major affine matrix with the given columns and translation.
pub(crate) fn affine(c0: V3, c1: V3, c2: V3, t: V3) -> [[f64; 4]; 4] {
    [[c0[0], c1[0], c2[0], t[0]], [c0[1], c1[1], c2[1], t[1]], [c0[2], c1[2], c2[2], t[2]], [0.0, 0.0, 0.0, 1.0]]
}

fn vertex(m: &Mesh, i: u32) -> V3 {
    m.positions[i as usize].map(f64::from)
}

/// Signed volume of a mesh \[m³\] (positive for a closed mesh whose triangles wind counter-clockwise seen
/// from outside, i.e. outward normals).
pub(crate) fn signed_volume(m: &Mesh) -> f64 {
    m.triangles.iter().map(|t| dot(vertex(m, t[0]), cross(vertex(m, t[1]), vertex(m, t[2])))).sum::<f64>() / 6.0
}

/// Whether `p` is inside the closed mesh `m` (crossing parity along a fixed, slightly skewed direction
/// so that the ray misses edges and vertices of axis-aligned geometry).
pub(crate) fn contains(m: &Mesh, p: V3) -> bool {
    let d = [0.8017837257372732, 0.2672612419124244, 0.5345224838248488];
    let mut crossings = 0usize;
    for t in &m.triangles {
        let (a, b, c) = (vertex(m, t[0]), vertex(m, t[1]), vertex(m, t[2]));
        // Möller–Trumbore.
        let (e1, e2) = (sub(b, a), sub(c, a));
        let h = cross(d, e2);
        let det = dot(e1, h);
        if det.abs() < 1e-300 {
            continue;
        }
        let s = sub(p, a);
        let u = dot(s, h) / det;
        if !(0.0..=1.0).contains(&u) {
            continue;
        }
        let q = cross(s, e1);
        let v = dot(d, q) / det;
        if v < 0.0 || u + v > 1.0 {
            continue;
        }
        if dot(e2, q) / det > 0.0 {
            crossings += 1;
        }
    }
    crossings % 2 == 1
}

/// The medium surrounding `p`: the innermost closed medium mesh containing it (smallest volume), other
/// than `exclude`; else the global medium when `p` lies in its region `global_box`; else `None` (vacuum).
pub(crate) fn medium_at(scene: &Scene, p: V3, exclude: Option<usize>, global_box: Option<(V3, V3)>) -> Option<usize> {
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
    let inside = global_box.is_some_and(|(lo, hi)| (0..3).all(|k| p[k] >= lo[k] && p[k] <= hi[k]));
    if inside { scene.media.iter().position(|m| m.boundary == Boundary::Global) } else { None }
}

#[cfg(test)]
mod tests;
