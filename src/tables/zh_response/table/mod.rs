//! The consumer side of `ZhResponse` (dubouchet2019 Sec. 4.3–4.5, 5.1–5.2, Appendix A): a loaded table
//! (all or some g slices and emitter profiles) and the queries a lightmap baker makes.
//!
//! **Input → output.** A `.vtab` (only the needed g slices are decompressed), a [`HomogeneousMedium`] (σ_s, σ_a, g
//! in scene units; call once per colour channel), an [`Emitter`] and a [`Receiver`] → the irradiance on
//! the receiver split into direct / single / multiple (`b ≥ 2`, of which `tail` is the part from
//! `b > B` when a tail is tabulated) / total ([`ZhResponseTable::irradiance`]), or the incident scattered radiance as a ZH lobe and as world
//! SH ([`ZhResponseTable::radiance`]).
//!
//! **Remapping** (derivation in `crate::physics::zh_transport::query`): lengths in mean free paths of the
//! real medium, `d_q = σ_t d`; a path with `b` scattering events carries `α^b`, `α = σ_s/σ_t` (Sec. 5.1's
//! per-bounce weights); point entries scale by `σ_t²` (the `σ_r²` of Sec. 4.3), directional entries are
//! unscaled. The direct term is analytic in scene units. Heterogeneous media: pass the effective
//! coefficients along the connecting segment (Sec. 4.4, `zh_transport::query::effective_sigma`).
//!
//! **g.** Responses are interpolated linearly in g between the two neighbouring slices (Sec. 4.5); a g
//! outside the tabulated range is refused (an error naming the range), never extrapolated. With
//! [`QueryOptions::similarity`] the multiple-scattering orders use the similarity relation
//! `σ_s* = (1 − g) σ_s`, `g* = 0` (Sec. 5.1), so they need the g = 0 response (interpolated).
//!
//! **Back-scatter compensation** (Sec. 5.2). The paper shifts the receiver by `ε n` during tabulation and
//! gathers over the whole sphere. Our canonical responses already cover the whole sphere (an infinite
//! medium around the receiver), so the shift is applied here: the scattered orders are looked up for the
//! receiver moved `ε` mean free paths along its normal (ε = the table's `backscatter_shift`), the direct
//! term for the true position. For a point light the shift is at most
//! half the distance to it (`d_s ≥ d/2`), so receivers closer than `2ε` stay finite and continuous.
//!
//! **Speed.** Each bounce is interpolated in `ln d` with the law of
//! [`crate::physics::zh_transport::Response::zh_at`] (the one the recursion itself used: `ln(e^{d} c_0)` and
//! the shape `c_l/c_0` linear), from logarithms and shapes precomputed at load in node-major layout
//! `[d][b][l]` (one query reads two contiguous blocks, one `exp` per bounce); the α-weighted lobes are
//! summed and dotted once with the clamped cosine in `O(N)` (Appendix A), single and multiple together.
//! A cheaper law linear in `c · d e^{d}` was tried and rejected: on a 48-node axis it differed from this one
//! by up to 3 % of `c_0` at middle orders, and was the less accurate of the two against the walk.

use std::path::Path;

use glam::DVec3;

use super::{EmitterProfile, TAIL_ALBEDOS, ZhResponse, ZhResponseRaw};
use crate::container::{ArrayDesc, ArrayValues};
use crate::physics::medium::HomogeneousMedium;
use crate::physics::sh;
use crate::physics::zh_transport::area::{AreaEntry, AreaResponse};
use crate::physics::zh_transport::tail;
use crate::tables::TableDef;

mod query;
mod slice;

pub use query::{Emitter, Irradiance, QueryError, QueryOptions, Radiance, Receiver};
use slice::{Loc, Slice};

/// Array names of a table with definition `def`, in file order.
pub fn array_names(def: &ZhResponse) -> Vec<String> {
    let mut out = Vec::new();
    for e in &def.emitters {
        let p = e.prefix();
        if *e == EmitterProfile::Area {
            out.extend(["area_direct".to_string(), "area_zh".into(), "area_axis".into()]);
            continue;
        }
        out.extend([format!("{p}_direct"), format!("{p}_zh"), format!("{p}_zh_sum")]);
        if def.tail_closure {
            out.push(format!("{p}_tail"));
        }
    }
    out
}

/// Failure to load a `ZhResponse` table.
pub type ZhReadError = crate::tables::TableReadError;

/// A loaded `ZhResponse` table (all or some slices) with the query API.
#[derive(Debug, Clone)]
pub struct ZhResponseTable {
    /// Every g slice in the file.
    pub g: Vec<f64>,
    /// Emitter profiles in the file.
    pub emitters: Vec<EmitterProfile>,
    /// Tabulated bounces `B`.
    pub bounces: usize,
    /// ZH order `N`.
    pub order: usize,
    /// Distance axis (mean free paths).
    pub distances: Vec<f64>,
    /// Back-scatter shift ε (mean free paths) the table was made for.
    pub backscatter_shift: f64,
    slices: Vec<Slice>,
    /// Loaded area-emitter slices: (g index, response).
    area: Vec<(usize, AreaResponse)>,
    /// Patch angles of the area emitter (radians).
    pub thetas: Vec<f64>,
    /// `ln(d_{i+1}/d_i)` per interval.
    log_steps: Vec<f64>,
    /// Per band `l`: (clamped-cosine coefficient `A_l`, `(2l − 1)/l`, `(l − 1)/l`) — the Appendix A dot
    /// product with the Legendre recurrence free of divisions.
    shading: Vec<(f64, f64, f64)>,
}

impl ZhResponseTable {
    /// `(Σ_l a_l A_l P_l(x), Σ_l b_l A_l P_l(x))`: the irradiance of two ZH lobes about the same axis on a
    /// normal at cosine `x` from it (Appendix A; `sh::zh_irradiance` for two lobes at once).
    fn shade_pair(&self, a: &[f64], b: &[f64], x: f64) -> (f64, f64) {
        let (mut p_prev, mut p) = (0.0, 1.0);
        let (mut sa, mut sb) = (0.0, 0.0);
        for (l, ((ca, cb), &(al, r1, r2))) in a.iter().zip(b).zip(&self.shading).enumerate() {
            if l > 0 {
                let next = r1 * x * p - r2 * p_prev;
                (p_prev, p) = (p, next);
            }
            sa += ca * al * p;
            sb += cb * al * p;
        }
        (sa, sb)
    }
}

fn invalid(msg: String) -> QueryError {
    QueryError::Invalid(msg)
}

fn finite_non_negative(name: &str, v: f64) -> Result<f64, QueryError> {
    if v.is_finite() && v >= 0.0 { Ok(v) } else { Err(invalid(format!("{name} = {v} must be finite and >= 0"))) }
}

/// `v / |v|` for a finite non-zero `v`, else an error naming `name`.
fn unit(name: &str, v: [f64; 3]) -> Result<DVec3, QueryError> {
    let u = DVec3::from_array(v);
    let len = u.length();
    if u.is_finite() && len > 0.0 && len.is_finite() {
        Ok(u / len)
    } else {
        Err(invalid(format!("{name} = {v:?} must be a finite non-zero vector")))
    }
}

fn finite3(name: &str, v: [f64; 3]) -> Result<DVec3, QueryError> {
    let u = DVec3::from_array(v);
    if u.is_finite() { Ok(u) } else { Err(invalid(format!("{name} = {v:?} must be finite"))) }
}

impl ZhResponseTable {
    /// Opens a `.vtab`, loading only the emitter profiles in `emitters` (all when `None`) and only the g
    /// slices needed to answer queries for the media g values in `media_g` (all when `None`; each g
    /// loads its two neighbouring slices, and the slices around g = 0 are added for the similarity
    /// option). A g outside the table's range is an error naming the range.
    pub fn open(
        path: &Path,
        emitters: Option<&[EmitterProfile]>,
        media_g: Option<&[f64]>,
    ) -> Result<Self, ZhReadError> {
        let r = crate::container::VtabReader::open(path)
            .map_err(|source| ZhReadError::Container { path: path.to_path_buf(), source })?;
        Self::from_reader(r, path, emitters, media_g)
    }

    /// [`Self::open`] on an open reader (e.g. made from bytes); `path` names it in messages.
    pub fn from_reader(
        r: crate::container::VtabReader,
        path: &Path,
        emitters: Option<&[EmitterProfile]>,
        media_g: Option<&[f64]>,
    ) -> Result<Self, ZhReadError> {
        let layout = |m: String| ZhReadError::Layout(format!("{}: {m}", path.display()));
        let container = |source| ZhReadError::Container { path: path.to_path_buf(), source };
        let (mut r, def) = crate::tables::check_kind(r, (ZhResponseRaw::KIND, super::KIND_SCHEMA_VERSION), layout)?;
        let TableDef::ZhResponse(def) = def else {
            return Err(layout("its stored definition is not a readable ZhResponse definition".into()));
        };
        let h = r.header().clone();
        let mut table = Self::from_arrays(&def, &h.arrays, &[]).map_err(layout)?;
        let profiles: Vec<EmitterProfile> = match emitters {
            None => table.emitters.clone(),
            Some(w) => {
                for e in w {
                    if !table.emitters.contains(e) {
                        return Err(layout(format!("has no {e:?} responses; it holds {:?}", table.emitters)));
                    }
                }
                w.to_vec()
            }
        };
        let gis: Vec<usize> = match media_g {
            None => (0..table.g.len()).collect(),
            Some(gs) => {
                let mut set = std::collections::BTreeSet::new();
                for &g in gs.iter().chain(std::iter::once(&0.0)) {
                    match table.bracket(g) {
                        Ok(b) => set.extend(b.iter().filter(|(_, w)| *w > 0.0).map(|(i, _)| *i)),
                        Err(e) if g != 0.0 => return Err(layout(e.to_string())),
                        Err(_) => {}
                    }
                }
                set.into_iter().collect()
            }
        };
        let names: Vec<String> = h.arrays.iter().map(|a| a.name.clone()).collect();
        let index = |name: String| names.iter().position(|n| *n == name);
        for profile in profiles {
            if profile == EmitterProfile::Area {
                let idx = |name: &str| index(name.into()).ok_or_else(|| layout(format!("lacks the {name} array")));
                let (di, zi, ai) = (idx("area_direct")?, idx("area_zh")?, idx("area_axis")?);
                for &gi in &gis {
                    let direct = r.read_slice(di, gi as u64).map_err(container)?.to_f64();
                    let zh = r.read_slice(zi, gi as u64).map_err(container)?.to_f64();
                    let axis = r.read_slice(ai, gi as u64).map_err(container)?.to_f64();
                    let resp = table.make_area(&direct, &zh, &axis).map_err(layout)?;
                    table.area.push((gi, resp));
                }
                continue;
            }
            let zh_index = index(format!("{}_zh", profile.prefix()))
                .ok_or_else(|| layout(format!("lacks the {}_zh array", profile.prefix())))?;
            let tail_index = index(format!("{}_tail", profile.prefix()));
            for &gi in &gis {
                let values = r.read_slice(zh_index, gi as u64).map_err(container)?.to_f64();
                let tail = match tail_index {
                    Some(t) => r.read_slice(t, gi as u64).map_err(container)?.to_f64(),
                    None => Vec::new(),
                };
                table.slices.push(table.make_slice(profile, gi, &values, &tail).map_err(layout)?);
            }
        }
        Ok(table)
    }

    /// Builds a table from in-memory arrays as generated (every slice loaded), checking the layout.
    /// With `values` empty only the layout is checked and nothing is loaded.
    pub fn from_arrays(def: &ZhResponse, descs: &[ArrayDesc], values: &[ArrayValues]) -> Result<Self, String> {
        let want = array_names(def);
        let names: Vec<&str> = descs.iter().map(|d| d.name.as_str()).collect();
        if names != want {
            return Err(format!("unexpected ZhResponse arrays {names:?}; expected {want:?}"));
        }
        let g = def.g.values();
        let bounces = def.bounces as usize;
        let order = def.zh_order as usize;
        let distances = def.distance_axis().values_vec();
        let (ng, nb, nd, nt) = (g.len() as u64, bounces as u64, distances.len() as u64, u64::from(def.theta_bins));
        for d in descs {
            let shape = d.shape();
            let expect: Vec<u64> = match d.name.as_str() {
                "area_direct" => vec![ng, nd, nt],
                "area_zh" => vec![ng, nb, nd, nt, order as u64],
                "area_axis" => vec![ng, nb, nd, nt],
                n if n.ends_with("_direct") => vec![ng, nd],
                n if n.ends_with("_zh") => vec![ng, nb, nd, order as u64],
                n if n.ends_with("_zh_sum") => vec![ng, nd, order as u64],
                _ => vec![ng, TAIL_ALBEDOS.len() as u64, nd, 2],
            };
            if shape != expect {
                return Err(format!("array {} has shape {shape:?}, expected {expect:?} from the definition", d.name));
            }
        }
        if distances.len() < 2 || !distances.windows(2).all(|w| w[0] < w[1] && w[0] > 0.0) {
            return Err("distance axis unusable: need >= 2 positive, strictly increasing values".into());
        }
        let mut table = Self {
            g,
            emitters: def.emitters.clone(),
            bounces,
            order,
            distances,
            backscatter_shift: def.backscatter_shift,
            slices: Vec::new(),
            area: Vec::new(),
            thetas: def.thetas(),
            log_steps: Vec::new(),
            shading: sh::clamped_cosine_zh(order)
                .into_iter()
                .enumerate()
                .map(|(l, a)| {
                    let lf = l.max(1) as f64;
                    (a, (2.0 * lf - 1.0) / lf, (lf - 1.0) / lf)
                })
                .collect(),
        };
        table.log_steps = table.distances.windows(2).map(|w| (w[1] / w[0]).ln()).collect();
        if values.is_empty() {
            return Ok(table);
        }
        if values.len() != descs.len() {
            return Err(format!("{} arrays of values for {} descriptions", values.len(), descs.len()));
        }
        let per_g = bounces * table.distances.len() * order;
        let per_g_tail = TAIL_ALBEDOS.len() * table.distances.len() * 2;
        let named = |name: String| values[want.iter().position(|n| *n == name).unwrap_or(0)].to_f64();
        for &profile in &def.emitters {
            if profile == EmitterProfile::Area {
                let (direct, zh, axis) =
                    (named("area_direct".into()), named("area_zh".into()), named("area_axis".into()));
                let (pd, pz, pa) = (direct.len() / g_len(&table), zh.len() / g_len(&table), axis.len() / g_len(&table));
                for gi in 0..table.g.len() {
                    let r = table.make_area(
                        &direct[gi * pd..(gi + 1) * pd],
                        &zh[gi * pz..(gi + 1) * pz],
                        &axis[gi * pa..(gi + 1) * pa],
                    )?;
                    table.area.push((gi, r));
                }
                continue;
            }
            let p = profile.prefix();
            let all = named(format!("{p}_zh"));
            let tails = if def.tail_closure { named(format!("{p}_tail")) } else { Vec::new() };
            for gi in 0..table.g.len() {
                let tail = if def.tail_closure { &tails[gi * per_g_tail..(gi + 1) * per_g_tail] } else { &[][..] };
                let slice = table.make_slice(profile, gi, &all[gi * per_g..(gi + 1) * per_g], tail)?;
                table.slices.push(slice);
            }
        }
        Ok(table)
    }

    /// An area response from one g slice of `area_direct`, `area_zh` and `area_axis` (file layouts).
    fn make_area(&self, direct: &[f64], zh: &[f64], axis: &[f64]) -> Result<AreaResponse, String> {
        let (nd, nt, n) = (self.distances.len(), self.thetas.len(), self.order);
        if direct.len() != nd * nt || zh.len() != self.bounces * nd * nt * n || axis.len() != self.bounces * nd * nt {
            return Err("area arrays do not match the definition's axes".into());
        }
        let direct = direct.chunks(nt).map(<[f64]>::to_vec).collect();
        let bounces = (0..self.bounces)
            .map(|b| {
                (0..nd)
                    .map(|i| {
                        (0..nt)
                            .map(|j| {
                                let cell = (b * nd + i) * nt + j;
                                AreaEntry {
                                    zh: zh[cell * n..(cell + 1) * n].to_vec(),
                                    theta_fit: axis[cell],
                                    fit_error: 0.0,
                                }
                            })
                            .collect()
                    })
                    .collect()
            })
            .collect();
        AreaResponse::from_parts(self.distances.clone(), self.thetas.clone(), direct, bounces)
    }

    fn make_slice(&self, profile: EmitterProfile, gi: usize, values: &[f64], tail: &[f64]) -> Result<Slice, String> {
        let nd = self.distances.len();
        if values.len() != self.bounces * nd * self.order {
            return Err(format!("{} slice {gi} has {} values", profile.prefix(), values.len()));
        }
        if !(tail.is_empty() || tail.len() == TAIL_ALBEDOS.len() * nd * 2) {
            return Err(format!("{} tail slice {gi} has {} values", profile.prefix(), tail.len()));
        }
        if let Some(v) = values.iter().chain(tail).find(|v| !v.is_finite()) {
            return Err(format!("{} slice {gi} holds the non-finite value {v}", profile.prefix()));
        }
        let mut slice = Slice::new(profile, gi, values, &self.distances, self.bounces, self.order);
        slice.tail = tail.to_vec();
        if !tail.is_empty() {
            slice.tail_nu = TAIL_ALBEDOS.iter().map(|&a| tail::diffusion(self.g[gi], a).decay).collect();
            slice.tail_log_c0 = tail.chunks(2).map(|c| if c[0] > 0.0 { c[0].ln() } else { f64::NAN }).collect();
        }
        Ok(slice)
    }

    /// [`Self::accumulate_tail_at`] at distance `d` (tests compare it with `tail::tail_at`).
    #[cfg(test)]
    #[allow(clippy::too_many_arguments)]
    pub(super) fn accumulate_tail(
        &self,
        profile: EmitterProfile,
        g: f64,
        d: f64,
        alpha: f64,
        weight: f64,
        acc: &mut [f64; 2],
    ) -> Result<(), QueryError> {
        self.accumulate_tail_at(profile, g, self.locate(d), alpha, weight, acc)
    }

    /// `acc += weight · tail(α)` (`[c_0, c_1]`) at a located distance, interpolated in g and in α between
    /// [`TAIL_ALBEDOS`] nodes (with [`blend`]); nothing when the table has no tail.
    fn accumulate_tail_at(
        &self,
        profile: EmitterProfile,
        g: f64,
        loc: Loc,
        alpha: f64,
        weight: f64,
        acc: &mut [f64; 2],
    ) -> Result<(), QueryError> {
        let alpha = alpha.clamp(0.0, 1.0);
        let j = TAIL_ALBEDOS.partition_point(|&a| a <= alpha).clamp(1, TAIL_ALBEDOS.len() - 1) - 1;
        // Interpolation variable √(1 − α): the tail's far field decays like e^{−ν d} with the diffusion
        // decay ν ≈ √(3(1 − α)(1 − g)), so ln c_0 is nearly linear in it.
        let s = |a: f64| (1.0 - a).max(0.0).sqrt();
        let u = (s(TAIL_ALBEDOS[j]) - s(alpha)) / (s(TAIL_ALBEDOS[j]) - s(TAIL_ALBEDOS[j + 1]));
        for (gi, w) in self.bracket(g)? {
            if w == 0.0 {
                continue;
            }
            let slice = self.slice(profile, gi)?;
            if slice.tail.is_empty() {
                return Ok(());
            }
            // The tail starts at order B + 1: blend tail/α^{B+1} (smooth in α), then restore the power.
            // Below the first non-zero node (α = 0 carries nothing) the scaled value is held.
            let p = self.bounces as i32 + 1;
            let scaled = |k: usize| {
                let t = slice.tail_at_node(k, loc, &self.distances);
                let s = TAIL_ALBEDOS[k].powi(p);
                [t[0] / s, t[1] / s]
            };
            let hi = scaled(j + 1);
            let lo = if TAIL_ALBEDOS[j] > 0.0 { scaled(j) } else { hi };
            let t = blend(lo, hi, u);
            let f = weight * w * alpha.powi(p);
            acc[0] += f * t[0];
            acc[1] += f * t[1];
        }
        Ok(())
    }

    /// The slice indices and weights that interpolate g: one slice within 1e-9, else its neighbours.
    fn bracket(&self, g: f64) -> Result<[(usize, f64); 2], QueryError> {
        let (min, max) = (self.g[0], self.g[self.g.len() - 1]);
        if !g.is_finite() || g < min - 1e-9 || g > max + 1e-9 {
            return Err(QueryError::GOutOfRange { g, min, max });
        }
        if let Some(i) = self.g.iter().position(|x| (x - g).abs() <= 1e-9) {
            return Ok([(i, 1.0), (i, 0.0)]);
        }
        let i = self.g.partition_point(|&x| x <= g) - 1;
        let w = (g - self.g[i]) / (self.g[i + 1] - self.g[i]);
        Ok([(i, 1.0 - w), (i + 1, w)])
    }

    fn slice(&self, profile: EmitterProfile, gi: usize) -> Result<&Slice, QueryError> {
        self.slices.iter().find(|s| s.profile == profile && s.gi == gi).ok_or_else(|| {
            QueryError::NotLoaded(format!(
                "the {profile:?} slice for g = {} is not loaded; open the table with this g (or all slices)",
                self.g[gi]
            ))
        })
    }

    /// Locates canonical distance `d` (NaN counts as `∞`, `d` is clamped to `≥ 1e-150`).
    fn locate(&self, d: f64) -> Loc {
        let ds = &self.distances;
        let n = ds.len();
        let d = if d.is_nan() { f64::INFINITY } else { d.max(1e-150) };
        if d <= ds[0] {
            Loc::Below { ratio: d / ds[0] }
        } else if d >= ds[n - 1] {
            Loc::Above { decay: (-(d - ds[n - 1])).exp(), d }
        } else {
            let i = ds.partition_point(|&x| x <= d) - 1;
            Loc::Between { i, lambda: (d / ds[i]).ln() / self.log_steps[i], d }
        }
    }

    /// [`Self::accumulate_at`] at distance `d` (tests compare it with `Response::zh_at`).
    #[cfg(test)]
    #[allow(clippy::too_many_arguments)]
    pub(super) fn accumulate(
        &self,
        profile: EmitterProfile,
        g: f64,
        d: f64,
        orders: std::ops::RangeInclusive<usize>,
        alpha: f64,
        weight: f64,
        acc: &mut [f64],
    ) -> Result<(), QueryError> {
        self.accumulate_at(profile, g, self.locate(d), orders, alpha, weight, acc)
    }

    /// `acc += weight · Σ_{b ∈ orders} α^b c_b` at a located distance, interpolated in g (a query locates
    /// each distance once and shares it between single, multiple and tail).
    #[allow(clippy::too_many_arguments)]
    fn accumulate_at(
        &self,
        profile: EmitterProfile,
        g: f64,
        loc: Loc,
        orders: std::ops::RangeInclusive<usize>,
        alpha: f64,
        weight: f64,
        acc: &mut [f64],
    ) -> Result<(), QueryError> {
        for (gi, w) in self.bracket(g)? {
            if w == 0.0 {
                continue;
            }
            let slice = self.slice(profile, gi)?;
            slice.accumulate(loc, &self.distances, (self.bounces, self.order), orders.clone(), alpha, weight * w, acc);
        }
        Ok(())
    }

    /// The scattered parts as ZH lobes about one axis, with the direct irradiance and the geometry.
    fn lobes(
        &self,
        medium: &HomogeneousMedium,
        emitter: &Emitter,
        receiver: &Receiver,
        opts: &QueryOptions,
        (single, multiple, tail): (&mut [f64], &mut [f64], &mut [f64; 2]),
    ) -> Result<(f64, DVec3, DVec3), QueryError> {
        let (sigma_s, sigma_a) = medium.checked()?;
        let x = finite3("receiver position", receiver.position)?;
        let n = unit("receiver normal", receiver.normal)?;
        let profile = emitter.profile();
        if !self.emitters.contains(&profile) {
            return Err(QueryError::NotLoaded(format!("the table has no {profile:?} responses ({:?})", self.emitters)));
        }
        let sigma_t = sigma_s + sigma_a;
        let shift = if opts.backscatter && sigma_t > 0.0 { self.backscatter_shift / sigma_t } else { 0.0 };
        let max_b = opts.max_bounce.unwrap_or(self.bounces).min(self.bounces);
        // (direct irradiance, remapped strength, shifted distance, axis from the shifted receiver)
        let (direct, strength, d_s, axis) = match *emitter {
            Emitter::Point { intensity, position } => {
                let intensity = finite_non_negative("intensity", intensity)?;
                let p = finite3("emitter position", position)?;
                let s = p - x;
                let d = s.length();
                if d == 0.0 {
                    return Err(invalid(
                        "the receiver is at the point light: the irradiance is infinite; move it off the light".into(),
                    ));
                }
                let a = s / d;
                let direct = intensity * (-sigma_t * d).exp() * n.dot(a).max(0.0) / (d * d);
                // Never more than half the way to the light: d_s ≥ d/2, so a receiver inside the shift
                // distance gets at most twice its unshifted 1/d (continuous in d, no singularity).
                let shift = shift.min(0.5 * d);
                let s2 = p - (x + shift * n);
                let d2 = s2.length();
                let (d_s, axis) = if d2 > 0.0 { (d2, s2 / d2) } else { (d, a) };
                (direct, intensity * sigma_t * sigma_t, d_s, axis)
            }
            Emitter::Area { .. } => return Err(invalid("internal: area emitters take the area path".into())),
            Emitter::Directional { irradiance, toward_light, depth } => {
                let e0 = finite_non_negative("irradiance", irradiance)?;
                let a = unit("toward_light", toward_light)?;
                let depth = finite_non_negative("depth", depth)?;
                let direct = e0 * (-sigma_t * depth).exp() * n.dot(a).max(0.0);
                (direct, e0, (depth - shift * n.dot(a)).max(0.0), a)
            }
        };
        if !direct.is_finite() {
            return Err(invalid(format!("the direct irradiance overflowed ({direct}); check the emitter strength")));
        }
        let with_tail = opts.tail && max_b == self.bounces;
        if sigma_s > 0.0 && max_b >= 1 {
            let alpha = sigma_s / sigma_t;
            let scale = strength;
            let loc = self.locate(sigma_t * d_s);
            self.accumulate_at(profile, medium.g, loc, 1..=1, alpha, scale, single)?;
            if max_b >= 2 {
                if opts.similarity {
                    let s2 = (1.0 - medium.g) * sigma_s;
                    let t2 = s2 + sigma_a;
                    let scale2 = match profile {
                        EmitterProfile::Point | EmitterProfile::Area => strength / (sigma_t * sigma_t) * t2 * t2,
                        EmitterProfile::Directional => strength,
                    };
                    if s2 > 0.0 {
                        let loc2 = self.locate(t2 * d_s);
                        self.accumulate_at(profile, 0.0, loc2, 2..=max_b, s2 / t2, scale2, multiple)?;
                        if with_tail {
                            self.accumulate_tail_at(profile, 0.0, loc2, s2 / t2, scale2, tail)?;
                        }
                    }
                } else {
                    self.accumulate_at(profile, medium.g, loc, 2..=max_b, alpha, scale, multiple)?;
                    if with_tail {
                        self.accumulate_tail_at(profile, medium.g, loc, alpha, scale, tail)?;
                    }
                }
            }
        }
        Ok((direct, axis, n))
    }

    /// The area emitter's scattered lobes in world space: calls `visit(b, lobe, axis)` for each order
    /// `b ≥ 1` (weighted by the remapping, the albedo power and the g interpolation; several calls per
    /// order when two g slices are blended) and returns the direct irradiance. The patch angle θ is taken
    /// between the patch normal and the direction from the patch to the (shifted) receiver; the stored
    /// axis angle turns from the light axis toward the tangential part of the patch normal. No tail.
    fn area_lobes(
        &self,
        medium: &HomogeneousMedium,
        emitter: &Emitter,
        receiver: &Receiver,
        opts: &QueryOptions,
        visit: LobeVisitor<'_>,
    ) -> Result<f64, QueryError> {
        let Emitter::Area { intensity, position, normal } = *emitter else {
            return Err(invalid("internal: not an area emitter".into()));
        };
        let (sigma_s, sigma_a) = medium.checked()?;
        let intensity = finite_non_negative("intensity", intensity)?;
        let p = finite3("emitter position", position)?;
        let ne = unit("emitter normal", normal)?;
        let x = finite3("receiver position", receiver.position)?;
        let n = unit("receiver normal", receiver.normal)?;
        if !self.emitters.contains(&EmitterProfile::Area) {
            return Err(QueryError::NotLoaded(format!("the table has no Area responses ({:?})", self.emitters)));
        }
        let s = p - x;
        let d = s.length();
        if d == 0.0 {
            return Err(invalid("the receiver is at the area emitter: the irradiance is infinite; move it off".into()));
        }
        let a = s / d;
        let sigma_t = sigma_s + sigma_a;
        let direct = intensity * (-ne.dot(a)).max(0.0) * (-sigma_t * d).exp() * n.dot(a).max(0.0) / (d * d);
        if !direct.is_finite() {
            return Err(invalid(format!("the direct irradiance overflowed ({direct}); check the emitter strength")));
        }
        let max_b = opts.max_bounce.unwrap_or(self.bounces).min(self.bounces);
        if sigma_s == 0.0 || max_b == 0 {
            return Ok(direct);
        }
        let shift = if opts.backscatter { (self.backscatter_shift / sigma_t).min(0.5 * d) } else { 0.0 };
        let s2 = p - (x + shift * n);
        let d2 = s2.length();
        let (d_s, a_s) = if d2 > 0.0 { (d2, s2 / d2) } else { (d, a) };
        let cos_theta = (-ne.dot(a_s)).clamp(-1.0, 1.0);
        let theta = cos_theta.acos();
        // Tangential direction of the patch normal (any perpendicular when the normal is along the axis).
        let t = ne + cos_theta * a_s;
        let tl = t.length();
        let e = if tl > 1e-12 {
            t / tl
        } else {
            let helper = if a_s.x.abs() < 0.9 { DVec3::X } else { DVec3::Y };
            let v = helper - helper.dot(a_s) * a_s;
            v / v.length()
        };
        // The stored axis (x: toward `e`, z: along `a_s`) in world space, as the SH code takes it.
        let world = |ax: [f64; 3]| {
            let w = ax[0] * e + ax[2] * a_s;
            let l = w.length();
            (if l > 0.0 { w / l } else { a_s }).to_array()
        };
        let mut run = |g: f64, s_eff: f64, orders: std::ops::RangeInclusive<usize>| -> Result<(), QueryError> {
            let t_eff = s_eff + sigma_a;
            let alpha = s_eff / t_eff;
            let scale = intensity * t_eff * t_eff;
            for (gi, w) in self.bracket(g)? {
                if w == 0.0 {
                    continue;
                }
                let resp = self.area.iter().find(|(i, _)| *i == gi).map(|(_, r)| r).ok_or_else(|| {
                    QueryError::NotLoaded(format!("the Area slice for g = {} is not loaded", self.g[gi]))
                })?;
                for b in orders.clone() {
                    let weight = scale * w * alpha.powi(b as i32);
                    if weight == 0.0 {
                        break;
                    }
                    let (mut lobe, ax) = resp.lobe_at(b, t_eff * d_s, theta);
                    for c in &mut lobe {
                        *c *= weight;
                    }
                    visit(b, &lobe, world(ax));
                }
            }
            Ok(())
        };
        run(medium.g, sigma_s, 1..=1)?;
        if max_b >= 2 {
            if opts.similarity {
                let s2 = (1.0 - medium.g) * sigma_s;
                if s2 > 0.0 {
                    run(0.0, s2, 2..=max_b)?;
                }
            } else {
                run(medium.g, sigma_s, 2..=max_b)?;
            }
        }
        Ok(direct)
    }

    /// Irradiance on `receiver` (W/m²) split by order; see the module doc for the remapping. Each
    /// scattered part is clamped at 0 (a band-limited lobe can ring slightly negative on normals facing
    /// away). Errors name the offending argument, a g outside the table, or a slice not loaded.
    pub fn irradiance(
        &self,
        medium: &HomogeneousMedium,
        emitter: &Emitter,
        receiver: &Receiver,
        opts: &QueryOptions,
    ) -> Result<Irradiance, QueryError> {
        let mut single = [0.0; super::MAX_ORDER as usize];
        let mut multiple = [0.0; super::MAX_ORDER as usize];
        let (single, multiple) = (&mut single[..self.order], &mut multiple[..self.order]);
        if let Emitter::Area { .. } = emitter {
            let n = unit("receiver normal", receiver.normal)?.to_array();
            let (mut single, mut multiple) = (0.0, 0.0);
            let direct = self.area_lobes(medium, emitter, receiver, opts, &mut |b, lobe, axis| {
                let e = sh::zh_irradiance(lobe, axis, n);
                if b == 1 { single += e } else { multiple += e }
            })?;
            let (single, multiple) = (single.max(0.0), multiple.max(0.0));
            let total = direct + single + multiple;
            if !total.is_finite() {
                return Err(invalid(format!("the irradiance overflowed ({total}); check the emitter strength")));
            }
            return Ok(Irradiance { direct, single, multiple, tail: 0.0, total });
        }
        let mut tail = [0.0; 2];
        let (direct, axis, n) = self.lobes(medium, emitter, receiver, opts, (single, multiple, &mut tail))?;
        let cos = axis.dot(n).clamp(-1.0, 1.0);
        let (single, multiple) = self.shade_pair(single, multiple, cos);
        let (single, multiple) = (single.max(0.0), multiple.max(0.0));
        let tail = if self.shading.len() >= 2 {
            (tail[0] * self.shading[0].0 + tail[1] * self.shading[1].0 * cos).max(0.0)
        } else {
            (tail[0] * self.shading[0].0).max(0.0)
        };
        let multiple = multiple + tail;
        let total = direct + single + multiple;
        if !total.is_finite() {
            return Err(invalid(format!("the irradiance overflowed ({total}); check the emitter strength")));
        }
        Ok(Irradiance { direct, single, multiple, tail, total })
    }

    /// The scattered incident radiance (all orders the options select) as a ZH lobe about the light
    /// axis and as world SH (Eq. 13), for consumers that shade with something other than a clamped
    /// cosine. The direct light is not included (it is a delta for a point light).
    pub fn radiance(
        &self,
        medium: &HomogeneousMedium,
        emitter: &Emitter,
        receiver: &Receiver,
        opts: &QueryOptions,
    ) -> Result<Radiance, QueryError> {
        if let Emitter::Area { .. } = emitter {
            let mut sh_sum = vec![0.0; self.order * self.order];
            let mut first_axis = [0.0, 0.0, 1.0];
            self.area_lobes(medium, emitter, receiver, opts, &mut |b, lobe, axis| {
                if b == 1 {
                    first_axis = axis;
                }
                for (s, x) in sh_sum.iter_mut().zip(sh::zh_rotate(lobe, axis)) {
                    *s += x;
                }
            })?;
            if sh_sum.iter().any(|c| !c.is_finite()) {
                return Err(invalid("the radiance overflowed; check the emitter strength".into()));
            }
            let zh = sh::zh_project_about(&sh_sum, first_axis);
            return Ok(Radiance { zh, axis: first_axis, sh: sh_sum });
        }
        let mut single = vec![0.0; self.order];
        let mut multiple = vec![0.0; self.order];
        let mut tail = [0.0; 2];
        let (_, axis, _) = self.lobes(medium, emitter, receiver, opts, (&mut single, &mut multiple, &mut tail))?;
        let axis = axis.to_array();
        let mut zh: Vec<f64> = single.iter().zip(&multiple).map(|(a, b)| a + b).collect();
        for (z, t) in zh.iter_mut().zip(tail) {
            *z += t;
        }
        if zh.iter().any(|c| !c.is_finite()) {
            return Err(invalid("the radiance overflowed; check the emitter strength".into()));
        }
        let sh = sh::zh_rotate(&zh, axis);
        Ok(Radiance { zh, axis, sh })
    }
}

/// `[c_0, c_1]` between two nodes at `λ`: `c_0` geometric when positive at both, else linear; `c_1` follows
/// `c_0`'s ratio linearly (so `|c_1| ≤ √3 c_0` is kept when both nodes satisfy it).
fn blend(a: [f64; 2], b: [f64; 2], lambda: f64) -> [f64; 2] {
    if lambda <= 0.0 {
        return a;
    }
    if lambda >= 1.0 {
        return b;
    }
    if a[0] > 0.0 && b[0] > 0.0 {
        let c0 = (a[0].ln() * (1.0 - lambda) + b[0].ln() * lambda).exp();
        let shape = (1.0 - lambda) * a[1] / a[0] + lambda * b[1] / b[0];
        [c0, c0 * shape]
    } else {
        [(1.0 - lambda) * a[0] + lambda * b[0], (1.0 - lambda) * a[1] + lambda * b[1]]
    }
}

/// Receives one weighted lobe of an area emitter: (order b, ZH coefficients, world axis).
type LobeVisitor<'a> = &'a mut dyn FnMut(usize, &[f64], [f64; 3]);

/// Number of g slices (at least 1, for dividing flat arrays).
fn g_len(t: &ZhResponseTable) -> usize {
    t.g.len().max(1)
}
