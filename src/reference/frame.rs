//! The references' orthonormal frame: a unit vector → two unit vectors completing it to a right-handed
//! orthonormal basis (Duff et al. 2017, branchless). One home for the path tracers of `volpath`,
//! `grid_mc` and `translucent`; the methods keep their own copy (`render::frame`), so no reference
//! shares code with what it judges.

use glam::DVec3;

/// `(t, b)` with `t × b = n` for a unit `n`; continuous except where `n.z` changes sign.
pub fn frame(n: DVec3) -> (DVec3, DVec3) {
    let sign = 1.0f64.copysign(n.z);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    (DVec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x), DVec3::new(b, sign + n.y * n.y * a, -n.y))
}
