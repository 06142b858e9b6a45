//! The equal-area octahedral parametrisation of the sphere that elek2014 Sec. 6 uses for the angular
//! coordinates of a point light's radial grid.
//!
//! **Input → output.** A unit direction ↔ a point of the unit square `[0, 1]²`; an `n × n` cell grid on
//! the square with each cell's four neighbours across the octahedron's folded edges, its centre
//! direction and its antipodal cell.
//!
//! elek2014 cites the octahedron parametrisation because it "discretizes the domain into a 2D square
//! where every cell has four natural neighbours". voltab uses its equal-area variant (Clarberg 2008): the
//! same octahedron and the same folding of the square's edges, with the radius inside each octant
//! remapped so that equal areas of the square cover equal solid angles. Every cell of an `n × n` grid
//! then subtends exactly `4π/n²`, which keeps the radial grid's cell volumes and initial powers exact.
//!
//! **Map** (square coordinates `p = 2·uv − 1 ∈ [−1, 1]²`): `s = 1 − (|p_x| + |p_y|)` is positive on the
//! upper hemisphere (the inner diamond) and negative in the four folded corners; `r = 1 − |s|`,
//! `φ = ((|p_y| − |p_x|)/r + 1)·π/4`, `z = sign(s)(1 − r²)`, `(x, y) = (sign p_x cos φ, sign p_y sin φ)·r√(2 − r²)`.
//! The inverse takes `r² = (x² + y²)/(1 + |z|)` (no cancellation at the poles).
//!
//! **Folds.** The square's edge `p_x = ±1` is glued to itself mirrored in `y` (the points `(±1, y)` and
//! `(±1, −y)` are the same direction), likewise `p_y = ±1` mirrored in `x`; the four corners are the south
//! pole. So the neighbour of cell `(n − 1, j)` across the right edge is `(n − 1, n − 1 − j)`
//! ([`wrap`]); with odd `n` the middle edge cell is its own neighbour there.

use glam::{DVec2, DVec3};

/// `+1` for `+0.0` and positive values, `−1` otherwise.
#[inline]
fn sign(v: f64) -> f64 {
    1.0_f64.copysign(v)
}

/// The unit direction of square point `uv ∈ [0, 1]²` (clamped into the square).
pub fn decode(uv: DVec2) -> DVec3 {
    let p = (uv.clamp(DVec2::ZERO, DVec2::ONE)) * 2.0 - DVec2::ONE;
    let (au, av) = (p.x.abs(), p.y.abs());
    let s = 1.0 - (au + av);
    let r = 1.0 - s.abs();
    let phi = if r > 0.0 { ((av - au) / r + 1.0) * std::f64::consts::FRAC_PI_4 } else { 0.0 };
    let z = sign(s) * (1.0 - r * r);
    let k = r * (2.0 - r * r).max(0.0).sqrt();
    DVec3::new(sign(p.x) * phi.cos().abs() * k, sign(p.y) * phi.sin().abs() * k, z)
}

/// The square point of unit direction `d` (normalised here; a zero or non-finite `d` gives the north
/// pole's point, the square's centre).
pub fn encode(d: DVec3) -> DVec2 {
    let Some(d) = d.try_normalize() else { return DVec2::splat(0.5) };
    let (ax, ay, az) = (d.x.abs(), d.y.abs(), d.z.abs().min(1.0));
    let r = ((ax * ax + ay * ay) / (1.0 + az)).sqrt().min(1.0);
    let t = if ax > 0.0 || ay > 0.0 { ay.atan2(ax) * (4.0 / std::f64::consts::PI) } else { 0.0 };
    let (au, av) =
        if d.z >= 0.0 { (r * (1.0 - 0.5 * t), 0.5 * r * t) } else { (1.0 - 0.5 * r * t, 1.0 - r + 0.5 * r * t) };
    let p = DVec2::new(sign(d.x) * au.clamp(0.0, 1.0), sign(d.y) * av.clamp(0.0, 1.0));
    (p + DVec2::ONE) * 0.5
}

/// Cell `(i, j)` of an `n × n` grid containing direction `d`.
pub fn cell_of(d: DVec3, n: usize) -> (usize, usize) {
    let uv = encode(d) * n as f64;
    let f = |v: f64| (v.max(0.0) as usize).min(n.max(1) - 1);
    (f(uv.x), f(uv.y))
}

/// The centre direction of cell `(i, j)` of an `n × n` grid.
pub fn cell_centre(i: usize, j: usize, n: usize) -> DVec3 {
    decode(DVec2::new((i as f64 + 0.5) / n as f64, (j as f64 + 0.5) / n as f64))
}

/// The cell an integer cell coordinate one step outside the square lands in after the folds (module
/// doc); coordinates inside are returned unchanged. `n ≥ 1`.
pub fn wrap(i: i64, j: i64, n: usize) -> (usize, usize) {
    let last = n.max(1) as i64 - 1;
    let (mut i, mut j) = (i, j);
    if i < 0 || i > last {
        i = i.clamp(0, last);
        j = last - j;
    }
    if j < 0 || j > last {
        j = j.clamp(0, last);
        i = last - i;
    }
    (i.clamp(0, last) as usize, j.clamp(0, last) as usize)
}

/// The cell containing the direction opposite to cell `(i, j)`'s centre.
pub fn antipode(i: usize, j: usize, n: usize) -> (usize, usize) {
    cell_of(-cell_centre(i, j, n), n)
}

#[cfg(test)]
mod tests;
