//! The radial propagation grid of elek2014 Sec. 6 centred on a point light.
//!
//! **Input → output.** A [`VoxelMedium`], the light's position and a resolution `(n, S)` → `n × n`
//! equal-area octahedral directions ([`super::octa`]) × `S` shells, spanning the whole medium, with per
//! cell the medium averaged over the cell (volume-uniform sub-samples: the downsampling of Sec. 4.2), and
//! per cell six links — four angular neighbours across the octahedron's folds, the next shell out and
//! the next shell in — with the two factors of Eqs. 2 and 4 (absorption-only transmittance of the mean
//! `σ_a` over the centre distance, anisotropy decay `g^{σ̄_s t}`). Links whose centre-to-centre segment
//! hits a surface ([`Occluder`]) carry nothing, as in the rectilinear [`super::grid::Grid`].
//!
//! **Shells.** The cell's principal direction is the radial one (the initial principal direction of
//! the point source, Sec. 6). Shell boundaries `0 = r_0 < r_1 < … < r_S = r_far` (`r_far`: the medium
//! box's farthest corner from the light) grow geometrically, `r_{k+1} = q r_k` for `k ≥ 1`, with
//! `q = e^{Δθ}`, `Δθ = √(4π)/n` the angular cell size: a cell is then as long radially as it is wide
//! ("spacing in proportion to the radial segment length at a given radius"). `r_1` follows from that
//! (`r_far e^{−(S−1)Δθ}`), floored at `10⁻⁴ r_far` (with many shells the innermost ones would be
//! uselessly small) and at the distance from the light to the box (a light outside the medium starts
//! its shells where the medium starts).
//!
//! **The centre.** The innermost cells are cones from the light to `r_1` (no hole at `r = 0`): every
//! direction's cone starts at the light. Light that flows inward from an innermost cell ("behind")
//! crosses the light's position into the antipodal innermost cell; that link has the length between the
//! two cell centres, so nothing is lost or created at `r → 0`.

use glam::{DVec2, DVec3};
use rayon::prelude::*;

use super::grid::{Cell, anisotropy_decay};

use crate::render::occluder::Occluder;

use super::octa;
use crate::render::color::Rgb;
use crate::render::voxel::VoxelMedium;

/// No neighbour (the outermost shell's outward link).
pub const NONE: usize = usize::MAX;

/// Link slots of a cell: angular `−u`, `+u`, `−v`, `+v`, then inward, outward.
pub const INWARD: usize = 4;
/// The outward slot.
pub const OUTWARD: usize = 5;

/// A radial grid around a point light.
#[derive(Debug, Clone)]
pub struct RadialGrid {
    /// The light's position \[m\].
    pub centre: DVec3,
    /// Angular cells per side of the octahedral square.
    pub n: usize,
    /// Shell boundaries `r_0 = 0 < … < r_S` \[m\].
    pub radii: Vec<f64>,
    /// Centroid radius of each shell's cells \[m\].
    pub centroid: Vec<f64>,
    /// Centre direction of each angular cell (index `i + n·j`).
    pub dirs: Vec<DVec3>,
    /// The medium per cell, index `a + n²·k` (`a` the angular cell, `k` the shell).
    pub cells: Vec<Cell>,
    /// HG mean cosine per channel.
    pub g: Rgb,
    /// Per cell and slot, the neighbour's index ([`NONE`] when there is none).
    pub neighbours: Vec<[usize; 6]>,
    /// Per cell and slot, the absorption transmittance of the link (0 when blocked).
    pub link_transmittance: Vec<[Rgb; 6]>,
    /// Per cell and slot, Eq. 4's decay `g^{σ̄_s t}` of the link.
    pub link_decay: Vec<[Rgb; 6]>,
}

/// Solid angle of one angular cell of an `n × n` equal-area grid \[sr\].
pub fn cell_solid_angle(n: usize) -> f64 {
    4.0 * std::f64::consts::PI / (n.max(1) * n.max(1)) as f64
}

/// Shell boundaries (module doc): `n` angular cells per side, `shells` shells, the light `r_near` from
/// the medium and `r_far` from its farthest point. Always `shells + 1` strictly increasing finite
/// radii starting at 0 when `r_far` is finite and positive (a non-positive or non-finite `r_far` is
/// taken as 1 m).
pub fn shell_radii(n: usize, shells: usize, r_near: f64, r_far: f64) -> Vec<f64> {
    let s = shells.max(1);
    let r_far = if r_far.is_finite() && r_far > 0.0 { r_far } else { 1.0 };
    if s == 1 {
        return vec![0.0, r_far];
    }
    let dtheta = (4.0 * std::f64::consts::PI).sqrt() / n.max(1) as f64;
    let shrink = (-(s as f64 - 1.0) * dtheta).exp().max(1e-4);
    let near = if r_near.is_finite() { r_near.max(0.0) } else { 0.0 };
    let r1 = (r_far * shrink).max(near).min(r_far * 0.999);
    let ln_q = (r_far / r1).ln() / (s as f64 - 1.0);
    let mut radii = Vec::with_capacity(s + 1);
    radii.push(0.0);
    for k in 1..s {
        radii.push(r1 * ((k - 1) as f64 * ln_q).exp());
    }
    radii.push(r_far);
    radii
}

/// Centroid radius of the spherical shell segment `[a, b]` (`3/4 · (b⁴ − a⁴)/(b³ − a³)`, factored so
/// nothing cancels or overflows before the radii themselves would).
pub fn centroid_radius(a: f64, b: f64) -> f64 {
    let den = b * b + a * b + a * a;
    if den > 0.0 { 0.75 * (a + b) * (a * a + b * b) / den } else { 0.0 }
}

/// `Δr / V` of a cell of solid angle `omega` between radii `a < b`: the factor turning the power a cell
/// holds into the fluence it adds while crossing the cell radially (`3/(Ω (b² + ab + a²))`).
pub fn fluence_per_power(omega: f64, a: f64, b: f64) -> f64 {
    let den = omega * (b * b + a * b + a * a);
    if den > 0.0 && den.is_finite() { 3.0 / den } else { 0.0 }
}

impl RadialGrid {
    /// Builds the grid around `centre` with `n × n` directions and `shells` shells.
    ///
    /// # Errors
    /// A message when the centre is not finite or a resolution is 0.
    pub fn new(
        medium: &VoxelMedium,
        centre: DVec3,
        n: usize,
        shells: usize,
        occluder: &dyn Occluder,
    ) -> Result<Self, String> {
        if !centre.is_finite() {
            return Err(format!("point light at {centre} is not finite"));
        }
        if n == 0 || shells == 0 {
            return Err(format!(
                "radial grid {n}×{n} directions × {shells} shells has a zero size; give at least 1 of each"
            ));
        }
        let near = (centre.clamp(medium.min, medium.max) - centre).length();
        let mut far = 0.0f64;
        for c in 0..8 {
            let p = DVec3::new(
                if c & 1 == 0 { medium.min.x } else { medium.max.x },
                if c & 2 == 0 { medium.min.y } else { medium.max.y },
                if c & 4 == 0 { medium.min.z } else { medium.max.z },
            );
            far = far.max((p - centre).length());
        }
        let radii = shell_radii(n, shells, near, far);
        let centroid = radii.windows(2).map(|w| centroid_radius(w[0], w[1])).collect();
        let dirs = (0..n * n).map(|a| octa::cell_centre(a % n, a / n, n)).collect();
        let mut grid = RadialGrid {
            centre,
            n,
            radii,
            centroid,
            dirs,
            cells: Vec::new(),
            g: medium.coefficients.g,
            neighbours: Vec::new(),
            link_transmittance: Vec::new(),
            link_decay: Vec::new(),
        };
        grid.cells = grid.sample_medium(medium);
        grid.build_links(occluder);
        Ok(grid)
    }

    /// Shells.
    pub fn shells(&self) -> usize {
        self.radii.len() - 1
    }

    /// Angular cells (`n²`).
    pub fn angular(&self) -> usize {
        self.n * self.n
    }

    /// Number of cells.
    pub fn len(&self) -> usize {
        self.cells.len()
    }

    /// True when the grid has no cells (never, after [`RadialGrid::new`]).
    pub fn is_empty(&self) -> bool {
        self.cells.is_empty()
    }

    /// (angular cell, shell) of flat index `c`.
    #[inline]
    pub fn split(&self, c: usize) -> (usize, usize) {
        (c % self.angular(), c / self.angular())
    }

    /// Centre of cell `c` (on its angular centre direction at the shell's centroid radius).
    pub fn center(&self, c: usize) -> DVec3 {
        let (a, k) = self.split(c);
        self.centre + self.dirs[a] * self.centroid[k]
    }

    /// `Δr/V` of shell `k`'s cells ([`fluence_per_power`]).
    pub fn fluence_per_power(&self, k: usize) -> f64 {
        fluence_per_power(cell_solid_angle(self.n), self.radii[k], self.radii[k + 1])
    }

    /// Continuous coordinates of world point `p`: octahedral square position in cells and the shell
    /// coordinate in centroids (`k` at shell `k`'s centroid radius, linear in between, clamped to the
    /// first and last centroid). `None` at the light itself.
    pub fn local(&self, p: DVec3) -> Option<(DVec2, f64)> {
        let d = p - self.centre;
        let r = d.length();
        if !(r > 0.0 && r.is_finite()) {
            return None;
        }
        let uv = octa::encode(d / r) * self.n as f64;
        let c = &self.centroid;
        let k = c.partition_point(|&x| x <= r);
        let s = if k == 0 {
            0.0
        } else if k >= c.len() {
            (c.len() - 1) as f64
        } else {
            (k - 1) as f64 + (r - c[k - 1]) / (c[k] - c[k - 1])
        };
        Some((uv, s))
    }

    /// Averages the medium over each cell with volume-uniform sub-samples (`s` per axis, chosen so they
    /// are at most about half a voxel apart, 1 to 4).
    fn sample_medium(&self, medium: &VoxelMedium) -> Vec<Cell> {
        let voxel = medium.voxel_size().min_element();
        let n = self.n;
        let dtheta = (4.0 * std::f64::consts::PI).sqrt() / n as f64;
        (0..self.angular() * self.shells())
            .into_par_iter()
            .map(|c| {
                let (a, k) = self.split(c);
                let (r0, r1) = (self.radii[k], self.radii[k + 1]);
                let size = (r1 - r0).max(r1 * dtheta);
                let s = ((2.0 * size / voxel).ceil() as usize).clamp(1, 4);
                let (i, j) = (a % n, a / n);
                let mut density = 0.0;
                for x in 0..s {
                    for y in 0..s {
                        let uv = DVec2::new(
                            (i as f64 + (x as f64 + 0.5) / s as f64) / n as f64,
                            (j as f64 + (y as f64 + 0.5) / s as f64) / n as f64,
                        );
                        let dir = octa::decode(uv);
                        for z in 0..s {
                            // Uniform in volume: r³ uniform between the shell's bounds.
                            let t = (z as f64 + 0.5) / s as f64;
                            let r = (r0 * r0 * r0 + t * (r1 * r1 * r1 - r0 * r0 * r0)).cbrt();
                            density += medium.density_at(self.centre + dir * r);
                        }
                    }
                }
                density /= (s * s * s) as f64;
                Cell::at_density(medium, density)
            })
            .collect()
    }

    /// Neighbours and link factors (module doc).
    fn build_links(&mut self, occluder: &dyn Occluder) {
        let n = self.n;
        let na = self.angular();
        let shells = self.shells();
        let g = self.g;
        let links: Vec<([usize; 6], [Rgb; 6], [Rgb; 6])> = (0..self.len())
            .into_par_iter()
            .map(|c| {
                let (a, k) = self.split(c);
                let (i, j) = ((a % n) as i64, (a / n) as i64);
                let mut nb = [NONE; 6];
                for (slot, (di, dj)) in [(-1i64, 0i64), (1, 0), (0, -1), (0, 1)].into_iter().enumerate() {
                    let (x, y) = octa::wrap(i + di, j + dj, n);
                    nb[slot] = x + n * y + na * k;
                }
                nb[INWARD] = if k == 0 {
                    let (x, y) = octa::antipode(a % n, a / n, n);
                    x + n * y
                } else {
                    c - na
                };
                nb[OUTWARD] = if k + 1 < shells { c + na } else { NONE };
                let mut t = [[0.0; 3]; 6];
                let mut decay = [[0.0; 3]; 6];
                for slot in 0..6 {
                    let o = nb[slot];
                    if o == NONE {
                        continue;
                    }
                    let (p, q) = (self.center(c), self.center(o));
                    if o != c && occluder.segment_blocked(p, q) {
                        continue;
                    }
                    let dist = (q - p).length();
                    let (x, y) = (&self.cells[c], &self.cells[o]);
                    for ch in 0..3 {
                        t[slot][ch] = (-0.5 * (x.sigma_a[ch] + y.sigma_a[ch]) * dist).exp();
                        decay[slot][ch] = anisotropy_decay(g[ch], 0.5 * (x.sigma_s[ch] + y.sigma_s[ch]) * dist);
                    }
                }
                (nb, t, decay)
            })
            .collect();
        self.neighbours = links.iter().map(|l| l.0).collect();
        self.link_transmittance = links.iter().map(|l| l.1).collect();
        self.link_decay = links.iter().map(|l| l.2).collect();
    }

    /// Which part of the source's Eq. 3 partition flows from neighbour `slot` of a cell in shell `k`
    /// into it: `0` front (the inner neighbour's outward flow), `1` side, `2` back (the outer neighbour's
    /// inward flow, and an innermost cell's antipode's inward flow through the centre).
    #[inline]
    pub fn part(slot: usize, k: usize) -> usize {
        match slot {
            INWARD if k > 0 => 0,
            INWARD | OUTWARD => 2,
            _ => 1,
        }
    }

    /// Trilinear resampling of a per-cell field at world point `p` (angular bilinear across the
    /// octahedron's folds, linear in the shell coordinate); the innermost shell's value at the light.
    pub fn sample(&self, field: &[Rgb], p: DVec3) -> Rgb {
        let n = self.n;
        let na = self.angular();
        let Some((uv, s)) = self.local(p) else {
            // At the light: the mean of the innermost cells.
            let mut m = [0.0; 3];
            for v in &field[..na] {
                for c in 0..3 {
                    m[c] += v[c] / na as f64;
                }
            }
            return m;
        };
        let x = uv - DVec2::splat(0.5);
        let (i0, j0) = (x.x.floor(), x.y.floor());
        let (fx, fy) = (x.x - i0, x.y - j0);
        let k0 = (s.floor() as usize).min(self.shells() - 1);
        let k1 = (k0 + 1).min(self.shells() - 1);
        let fk = s - k0 as f64;
        let mut out = [0.0; 3];
        for (di, wi) in [(0i64, 1.0 - fx), (1, fx)] {
            for (dj, wj) in [(0i64, 1.0 - fy), (1, fy)] {
                let (a, b) = octa::wrap(i0 as i64 + di, j0 as i64 + dj, n);
                let ang = a + n * b;
                for (k, wk) in [(k0, 1.0 - fk), (k1, fk)] {
                    let w = wi * wj * wk;
                    if w == 0.0 {
                        continue;
                    }
                    let v = field[ang + na * k];
                    for c in 0..3 {
                        out[c] += w * v[c];
                    }
                }
            }
        }
        out
    }
}

/// `voltab stability` rows of the radial-grid formulas: shell radii, centroid radius, `Δr/V`, the
/// octahedral map at the poles and axes, and the exact `∫ ds/r²` of a step through the light.
pub fn stability_rows() -> Vec<crate::stability::Row> {
    use crate::stability::{Expect, Row};
    let row = |formula, input: String, value, expect| Row { kind: "PopRadial", formula, input, value, expect };
    let mut v = Vec::new();
    for (n, s, near, far) in
        [(16, 16, 0.0, 4.7), (2, 256, 0.0, 1e-9), (256, 256, 0.0, 1e9), (1, 1, 0.0, 1.0), (16, 16, 5.0, 5.0 + 1e-12)]
    {
        let r = shell_radii(n, s, near, far);
        let ok = r.len() == s + 1 && r[0] == 0.0 && r.windows(2).all(|w| w[1] > w[0] && w[1].is_finite());
        v.push(row(
            "shell radii increasing",
            format!("n={n} S={s} r=[{near},{far}]"),
            f64::from(u8::from(ok)),
            Expect::Close { to: 1.0, rel: 0.0 },
        ));
        let k = fluence_per_power(cell_solid_angle(n), r[0], r[1]);
        v.push(row("Δr/V innermost cone", format!("n={n} S={s} r_far={far}"), k, Expect::Positive));
    }
    v.push(row(
        "centroid radius",
        "a=0, b=1".into(),
        centroid_radius(0.0, 1.0),
        Expect::Close { to: 0.75, rel: 1e-15 },
    ));
    v.push(row("centroid radius", "a=b=1e-300".into(), centroid_radius(1e-300, 1e-300), Expect::Finite));
    v.push(row(
        "centroid radius",
        "a=1e100, b=2e100".into(),
        centroid_radius(1e100, 2e100),
        Expect::InRange(1e100, 2e100),
    ));
    v.push(row(
        "Δr/V",
        "a=1e200, b=2e200 (overflow → 0)".into(),
        fluence_per_power(1.0, 1e200, 2e200),
        Expect::InRange(0.0, 0.0),
    ));
    for (name, d) in
        [("+z", DVec3::Z), ("−z", -DVec3::Z), ("+x", DVec3::X), ("1e-300 off −z", DVec3::new(1e-300, 0.0, -1.0))]
    {
        let e = (octa::decode(octa::encode(d)) - d.normalize()).length();
        v.push(row("octahedral round trip error", name.into(), e, Expect::InRange(0.0, 1e-15)));
    }
    let through =
        super::radial_propagate::inverse_square_integral(DVec3::new(-1.0, 0.0, 0.0), DVec3::X, 2.0, DVec3::ZERO, 1e-4);
    v.push(row(
        "∫ds/r² through the light",
        "b=0 (floor 1e-4)".into(),
        through,
        Expect::Close { to: std::f64::consts::PI / 1e-4, rel: 1e-3 },
    ));
    let far =
        super::radial_propagate::inverse_square_integral(DVec3::new(-1e9, 1.0, 0.0), DVec3::X, 2e9, DVec3::ZERO, 1e-4);
    v.push(row("∫ds/r² infinite line", "b=1".into(), far, Expect::Close { to: std::f64::consts::PI, rel: 1e-8 }));
    v
}
