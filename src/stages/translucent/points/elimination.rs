//! The object's triangles → `N` blue-noise surface samples (wang2018 Sec. 3.4.1): area-uniform
//! candidates reduced by weighted sample elimination (Yuksel 2015), as the module doc of
//! [`super`] describes.

use super::*;

/// A world-space triangle of the object.
#[derive(Debug, Clone, Copy)]
pub(super) struct Tri {
    pub(super) v: [DVec3; 3],
    pub(super) normal: DVec3,
    pub(super) area: f64,
    /// Index into the mesh's triangles.
    pub(super) index: u32,
}

/// The mesh's triangles with finite vertices and non-zero area (counter-clockwise = outward).
pub(super) fn world_triangles(mesh: &crate::scene::Mesh) -> Vec<Tri> {
    mesh.triangles
        .iter()
        .enumerate()
        .filter_map(|(i, t)| {
            let v = [0, 1, 2].map(|k| mesh.positions.get(t[k] as usize).map(|p| DVec3::from_array(p.map(f64::from))));
            let v = [v[0]?, v[1]?, v[2]?];
            let c = (v[1] - v[0]).cross(v[2] - v[0]);
            let len = c.length();
            (len > 0.0 && len.is_finite() && i <= u32::MAX as usize).then(|| Tri {
                v,
                normal: c / len,
                area: 0.5 * len,
                index: i as u32,
            })
        })
        .collect()
}

/// `n` blue-noise points (position, index into `tris`): `4n` area-uniform candidates reduced by
/// weighted sample elimination. Deterministic in `seed`.
pub(super) fn surface_samples(tris: &[Tri], total_area: f64, n: usize, seed: u64) -> Vec<(DVec3, usize)> {
    let cands = area_uniform(tris, 4 * n, seed);
    let keep = eliminate(&cands.iter().map(|c| c.0).collect::<Vec<_>>(), n, total_area);
    keep.into_iter().map(|i| cands[i]).collect()
}

/// `m` area-uniform points: triangle by the area CDF, uniform barycentrics (square-root warp).
pub(super) fn area_uniform(tris: &[Tri], m: usize, seed: u64) -> Vec<(DVec3, usize)> {
    let mut cdf = Vec::with_capacity(tris.len());
    let mut acc = 0.0;
    for t in tris {
        acc += t.area;
        cdf.push(acc);
    }
    let key = StreamKey { table: seed, cell: CELL_CANDIDATES };
    (0..m as u64)
        .into_par_iter()
        .map(|i| {
            let s = key.sample(i);
            let target = s.uniform(0) * acc;
            let ti = cdf.partition_point(|&c| c <= target).min(tris.len() - 1);
            let (r1, r2) = (s.uniform(1).sqrt(), s.uniform(2));
            let v = tris[ti].v;
            (v[0] * (1.0 - r1) + v[1] * (r1 * (1.0 - r2)) + v[2] * (r1 * r2), ti)
        })
        .collect()
}

/// Heap entry of the elimination: largest weight first, then lowest index.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Entry {
    pub(super) w: f64,
    pub(super) i: u32,
}

impl Eq for Entry {}

impl Ord for Entry {
    fn cmp(&self, o: &Self) -> Ordering {
        self.w.total_cmp(&o.w).then(o.i.cmp(&self.i))
    }
}

impl PartialOrd for Entry {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}

/// Weighted sample elimination (Yuksel 2015) of `points` down to `n` on a surface of area `area`:
/// returns the kept indices in increasing order.
pub(super) fn eliminate(points: &[DVec3], n: usize, area: f64) -> Vec<usize> {
    if points.len() <= n {
        return (0..points.len()).collect();
    }
    // Maximal Poisson-disk radius of n points on a 2D domain of this area (hexagonal packing).
    let r_max = (area / (2.0 * 3f64.sqrt() * n as f64)).sqrt();
    let r_min = r_max * 0.65 * (1.0 - (n as f64 / points.len() as f64).powf(1.5));
    let reach = 2.0 * r_max;
    let weight = |d: f64| (1.0 - d.max(r_min) / reach).max(0.0).powi(8);
    let cell = |p: DVec3| {
        let q = (p / reach).floor();
        [q.x as i64, q.y as i64, q.z as i64]
    };
    let mut grid: HashMap<[i64; 3], Vec<u32>> = HashMap::new();
    for (i, p) in points.iter().enumerate() {
        grid.entry(cell(*p)).or_default().push(i as u32);
    }
    let neighbours: Vec<Vec<(u32, f64)>> = points
        .par_iter()
        .enumerate()
        .map(|(i, p)| {
            let c = cell(*p);
            let mut out = Vec::new();
            for dx in -1..=1 {
                for dy in -1..=1 {
                    for dz in -1..=1 {
                        let Some(list) = grid.get(&[c[0] + dx, c[1] + dy, c[2] + dz]) else { continue };
                        for &j in list {
                            let d = points[j as usize].distance(*p);
                            if j as usize != i && d < reach {
                                out.push((j, weight(d)));
                            }
                        }
                    }
                }
            }
            out
        })
        .collect();
    let mut w: Vec<f64> = neighbours.iter().map(|l| l.iter().map(|x| x.1).sum()).collect();
    let mut alive = vec![true; points.len()];
    let mut heap: BinaryHeap<Entry> = w.iter().enumerate().map(|(i, &w)| Entry { w, i: i as u32 }).collect();
    let mut remaining = points.len();
    while remaining > n {
        let Some(e) = heap.pop() else { break };
        let i = e.i as usize;
        // Lazy deletion: skip entries superseded by a later weight update.
        if !alive[i] || e.w.to_bits() != w[i].to_bits() {
            continue;
        }
        alive[i] = false;
        remaining -= 1;
        for &(j, wij) in &neighbours[i] {
            let j = j as usize;
            if alive[j] {
                w[j] -= wij;
                heap.push(Entry { w: w[j], i: j as u32 });
            }
        }
    }
    (0..points.len()).filter(|&i| alive[i]).collect()
}
