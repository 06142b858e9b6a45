//! Watertight ray–triangle intersection (Woop, Benthin & Wald 2013, JCGT 2(1)) with a symbolic
//! perturbation deciding rays that pass exactly through an edge or a vertex.
//!
//! **Input → output.** A prepared ray (origin, shear of the ray frame) and a triangle in world space
//! (f32) → the hit parameter, barycentrics and the side the ray arrives from, or a miss.
//!
//! **Why it is watertight.** Each vertex is translated to the ray origin and sheared into the ray frame
//! once, with the same arithmetic for every triangle that shares it. The 2-D edge function of an edge
//! is computed from its two end points only (`Q.x·P.y − Q.y·P.x`), so the two triangles sharing the
//! edge compute exact negations of each other. Rounding is monotone, so a rounded edge function is
//! either of the exact sign or zero; zeros are recomputed in f64, where the products of f32 values are
//! exact, which makes every sign exact for the transformed vertices.
//!
//! **Rule for rays through an edge or a vertex** (an edge function exactly zero). The ray is moved by an
//! infinitesimal `ε·(1, ε')` in the ray frame (simulation of simplicity): an edge `P → Q` with
//! `D = Q − P` then has the sign of `D.y`, or of `−D.x` when `D.y = 0`. The two triangles sharing an
//! edge see `D` and `−D`, so exactly one of them owns a ray through their common edge, and exactly one
//! triangle of a closed fan owns a ray through their common vertex: a ray crossing a closed surface
//! through an edge or a vertex is counted once, and one that only grazes a silhouette edge or vertex is
//! counted zero or two times (entering and leaving at the same `t`). An edge that is a point in the ray
//! frame (the ray runs along it) or a triangle seen edge-on never produces a hit.

/// One triangle as the traversal stores it (in BVH slot order).
#[derive(Debug, Clone, Copy)]
pub(super) struct Tri {
    /// Vertices, world space (metres).
    pub v: [[f32; 3]; 3],
    /// Global triangle index (mesh-major, in scene order): the tie-break between equal `t`.
    pub gid: u32,
}

/// A ray prepared for the watertight test: origin, axis permutation and shear.
#[derive(Debug, Clone, Copy)]
pub(super) struct PreparedRay {
    /// Origin (metres).
    pub o: [f32; 3],
    /// Direction (scaled so its largest component has magnitude in [1, 2); tiny components flushed
    /// to +0).
    pub d: [f32; 3],
    /// `kx, ky, kz`: `kz` is the dominant axis; `kx, ky` swapped when `d[kz] < 0` to keep the winding.
    pub k: [usize; 3],
    /// Shear `(d[kx]/d[kz], d[ky]/d[kz], 1/d[kz])`.
    pub s: [f32; 3],
}

/// A triangle hit in the internal parameter of the prepared ray.
#[derive(Debug, Clone, Copy)]
pub(super) struct TriHit {
    /// Ray parameter (internal units).
    pub t: f32,
    /// Barycentric weights of vertices 1 and 2.
    pub b1: f32,
    /// See `b1`.
    pub b2: f32,
    /// The ray arrives on the side the counter-clockwise winding faces (`⟨d, n_g⟩ < 0`).
    pub front: bool,
}

impl PreparedRay {
    /// Prepares a ray whose direction is finite and non-zero (already scaled and flushed).
    pub fn new(o: [f32; 3], d: [f32; 3]) -> Self {
        let mut kz = 0;
        for a in 1..3 {
            if d[a].abs() > d[kz].abs() {
                kz = a;
            }
        }
        let mut kx = (kz + 1) % 3;
        let mut ky = (kx + 1) % 3;
        if d[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        let s = [d[kx] / d[kz], d[ky] / d[kz], 1.0 / d[kz]];
        PreparedRay { o, d, k: [kx, ky, kz], s }
    }
}

/// Sign of an exactly zero edge function under the perturbation `ε·(1, ε')` (module doc); 0 when the
/// edge is a point in the ray frame.
#[inline]
fn perturbed_sign(dx: f32, dy: f32) -> i32 {
    if dy > 0.0 {
        1
    } else if dy < 0.0 {
        -1
    } else if dx < 0.0 {
        1
    } else if dx > 0.0 {
        -1
    } else {
        0
    }
}

#[inline]
fn sign64(x: f64) -> i32 {
    i32::from(x > 0.0) - i32::from(x < 0.0)
}

/// Intersects the line of `r` with `tri`; returns the hit at any `t` (the caller checks its range).
#[inline(always)]
pub(super) fn intersect(tri: &Tri, r: &PreparedRay) -> Option<TriHit> {
    let [kx, ky, kz] = r.k;
    let [sx, sy, sz] = r.s;
    let rel = |v: &[f32; 3]| [v[0] - r.o[0], v[1] - r.o[1], v[2] - r.o[2]];
    let (a, b, c) = (rel(&tri.v[0]), rel(&tri.v[1]), rel(&tri.v[2]));
    let (ax, ay) = (a[kx] - sx * a[kz], a[ky] - sy * a[kz]);
    let (bx, by) = (b[kx] - sx * b[kz], b[ky] - sy * b[kz]);
    let (cx, cy) = (c[kx] - sx * c[kz], c[ky] - sy * c[kz]);
    let mut u = cx * by - cy * bx;
    let mut v = ax * cy - ay * cx;
    let mut w = bx * ay - by * ax;
    if u == 0.0 || v == 0.0 || w == 0.0 {
        // Exact signs: products of f32 are exact in f64, and the rounded difference keeps the sign.
        let e = |px: f32, py: f32, qx: f32, qy: f32| f64::from(qx) * f64::from(py) - f64::from(qy) * f64::from(px);
        let (u64, v64, w64) = (e(bx, by, cx, cy), e(cx, cy, ax, ay), e(ax, ay, bx, by));
        let pick = |x: f64, dx: f32, dy: f32| if x == 0.0 { perturbed_sign(dx, dy) } else { sign64(x) };
        let su = pick(u64, cx - bx, cy - by);
        let sv = pick(v64, ax - cx, ay - cy);
        let sw = pick(w64, bx - ax, by - ay);
        if su == 0 || su != sv || su != sw {
            return None;
        }
        (u, v, w) = (u64 as f32, v64 as f32, w64 as f32);
    } else if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
        return None;
    }
    let det = u + v + w;
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let (az, bz, cz) = (sz * a[kz], sz * b[kz], sz * c[kz]);
    let inv = 1.0 / det;
    let t = (u * az + v * bz + w * cz) * inv;
    if !t.is_finite() {
        return None;
    }
    Some(TriHit { t, b1: v * inv, b2: w * inv, front: det > 0.0 })
}
