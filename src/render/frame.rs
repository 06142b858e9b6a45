//! The methods' orthonormal frame: a unit vector → two unit vectors completing it to a right-handed
//! orthonormal basis, continuous except where `n.z` changes sign (Duff et al. 2017, "Building an
//! orthonormal basis, revisited", branchless). One home for the techniques (the lightmap bake's
//! hemisphere and light sampling, POP's light-aligned grids); the references keep their own copy
//! (`reference::frame`) so they share no code with what they judge.

use glam::DVec3;

/// `(t, b)` with `t × b = n` for a unit `n`.
pub fn frame(n: DVec3) -> (DVec3, DVec3) {
    let s = 1f64.copysign(n.z);
    let a = -1.0 / (s + n.z);
    let b = n.x * n.y * a;
    (DVec3::new(1.0 + s * n.x * n.x * a, s * b, -s * n.x), DVec3::new(b, s + n.y * n.y * a, -n.y))
}
