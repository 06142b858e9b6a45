//! Diagnostic (not part of the pipeline): per-component bias and error of the point-based translucent
//! renderer (wang2018) against the path-traced reference on the bundled scene at the default
//! pipeline's settings (48 × 48, 2048 surface samples, k_max 4).
//!
//! **Input → output.** A Table 2 material name, reference paths per pixel per seed, and optional
//! `key=value` knobs (`k_max`, `eps1`, `eps2`, `epsm`, `clamp`, `surf`, `terms`, `image=0|1` (image
//! beams), `stride` (anchor-pixel stride), `ior` (override the object's), `black=1` (black ground: the
//! lamp alone lights the object), `drays` (diffuse rays per primary opaque hit), `srays` (scene rays
//! per camera sample; 0: the surface samples), `graze` (grazing beams per surface sample), `epsb` (the
//! beams' cut \[sr\]), `disk` (points per tube disk in Eq. 6), `olight=0` (no caustic and glow photons), `dump=PATH`
//! (both images and the components as JSON), `table=PATH` (another `MsLobes` table)) → per component (rest,
//! single, double, multiple + bounced against the reference's 0 / 1 / 2 / ≥ 3 medium events) the
//! normalised MSE, the reference's own noise from two independent seeds (`E[(A − B)²]/4` for their
//! mean), their difference, and the ratio of the component sums over the object's pixels (the bias).
//! Normalisation as in `stages::translucent::compare` (the reference's 99th-percentile object value).
//! The references are cached as JSON in `$TMPDIR/translucent_ref`.
//!
//! Needs `out/ms_lobes_table2.vtab` (`voltab compile`). Run from the repository root:
//! `cargo run --example translucent_diag -- Wax 1024`.

use std::path::PathBuf;
use std::time::Instant;

use voltab::reference::translucent::{self as reference, ReferenceOptions};
use voltab::render::ViewCamera;
use voltab::render::dielectric::{Material, Setup, emitters, find_object};
use voltab::scene::Scene;
use voltab::scene::bvh::SceneBvh;
use voltab::stages::translucent::points::PointOptions;
use voltab::stages::translucent::render::{self, RenderOptions};
use voltab::tables::ms_lobes::MsLobesTable;

type Img = Vec<[f64; 3]>;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let name = args.get(1).cloned().unwrap_or("Wax".into());
    let spp: u32 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(1024);
    let mut scene = Scene::load(std::path::Path::new("scenes/translucent.gltf")).unwrap();
    let black = args[3..].iter().any(|a| a == "black=1");
    if black {
        // Black ground: only the lamp lights the object.
        let mi = scene.meshes[0].material.unwrap();
        scene.materials[mi].base_color = [0.0; 3];
    }
    let bvh = SceneBvh::build(&scene);
    let (object, ior) = find_object(&scene, &bvh).unwrap();
    let (ems, _) = emitters(&scene, 0.02);
    let ior_arg: Option<f64> = args[3..].iter().find_map(|kv| kv.strip_prefix("ior=").map(|v| v.parse().unwrap()));
    let material = Material::preset(&name, 0.01, ior_arg.unwrap_or(ior)).unwrap();
    let setup = Setup { scene: &scene, bvh: &bvh, object, material, emitters: &ems };
    let m = voltab::tables::ms_lobes::material(&name).unwrap();
    let needs: Vec<(f64, f64)> = m.albedo.iter().map(|&a| (a, m.g)).collect();
    let table_path =
        args[3..].iter().find_map(|kv| kv.strip_prefix("table=")).unwrap_or("out/ms_lobes_table2.vtab").to_string();
    let table = MsLobesTable::open(std::path::Path::new(&table_path), Some(&needs)).unwrap();
    let w = 48;
    let cam = ViewCamera::from_scene(&scene.cameras[0], w, w).unwrap();
    let mut popts = PointOptions { surface_samples: 2048, ..PointOptions::default() };
    let mut ropts = RenderOptions { k_max: 4, ..RenderOptions::default() };
    for kv in &args[3..] {
        let (k, v) = kv.split_once('=').unwrap();
        match k {
            "k_max" => ropts.k_max = v.parse().unwrap(),
            "eps1" => ropts.epsilon1 = v.parse().unwrap(),
            "eps2" => ropts.epsilon2 = v.parse().unwrap(),
            "epsm" => ropts.epsilon_multiple = v.parse().unwrap(),
            "epsb" => ropts.epsilon_beams = v.parse().unwrap(),
            "disk" => ropts.double_disk = v.parse().unwrap(),
            "clamp" => ropts.clamp_mfp = v.parse().unwrap(),
            "surf" => popts.surface_samples = v.parse().unwrap(),
            "terms" => ropts.reflection_terms = v.parse().unwrap(),
            "image" => ropts.boundary_image = v == "1",
            "stride" => ropts.smooth_stride = v.parse().unwrap(),
            "drays" => ropts.diffuse_rays = v.parse().unwrap(),
            "srays" => ropts.scene_rays = v.parse().unwrap(),
            "graze" => ropts.grazing_beams = v.parse().unwrap(),
            "olight" => popts.object_light = v == "1",
            "ior" | "black" | "dump" | "table" => {}
            _ => panic!("unknown {k}"),
        }
    }
    // Reference: two seeds, cached.
    let dir: PathBuf = std::env::temp_dir().join("translucent_ref");
    std::fs::create_dir_all(&dir).unwrap();
    let mut refs: Vec<([Img; 4], Vec<bool>)> = Vec::new();
    for seed in 0..2u64 {
        let f = dir.join(format!("{name}_{w}_{spp}_{seed}_{}{}.json", material.ior, if black { "_black" } else { "" }));
        let r: ([Img; 4], Vec<bool>) = if let Ok(b) = std::fs::read(&f) {
            serde_json::from_slice(&b).unwrap()
        } else {
            let t = Instant::now();
            let opts = ReferenceOptions { samples: spp, seed: 1000 + seed, ..ReferenceOptions::default() };
            let r = reference::render(&setup, &cam, &opts, &|_| {});
            eprintln!("reference {name} seed {seed}: {:.1} s", t.elapsed().as_secs_f64());
            let v = (r.components.clone(), r.object.clone());
            std::fs::write(&f, serde_json::to_vec(&v).unwrap()).unwrap();
            v
        };
        refs.push(r);
    }
    let mask = refs[0].1.clone();
    let avg: [Img; 4] = std::array::from_fn(|k| {
        refs[0].0[k].iter().zip(&refs[1].0[k]).map(|(a, b)| std::array::from_fn(|c| 0.5 * (a[c] + b[c]))).collect()
    });
    let total = |v: &[Img]| -> Img {
        (0..mask.len()).map(|i| std::array::from_fn(|c| v.iter().map(|x| x[i][c]).sum())).collect()
    };
    let ref_total = total(&avg);
    let mut vals: Vec<f64> = ref_total.iter().zip(&mask).filter(|p| *p.1).flat_map(|p| p.0.iter().copied()).collect();
    vals.sort_by(f64::total_cmp);
    let scale = vals[((0.99 * vals.len() as f64).ceil() as usize).clamp(1, vals.len()) - 1];
    let mse = |a: &Img, b: &Img| -> f64 {
        let (mut s, mut n) = (0.0, 0);
        for i in 0..mask.len() {
            if mask[i] {
                for c in 0..3 {
                    s += ((a[i][c] - b[i][c]) / scale).powi(2);
                    n += 1;
                }
            }
        }
        s / n as f64
    };
    let sums = |a: &Img| -> [f64; 3] {
        let mut s = [0.0; 3];
        for i in 0..mask.len() {
            if mask[i] {
                for c in 0..3 {
                    s[c] += a[i][c] / scale;
                }
            }
        }
        s
    };
    // Noise of the two-seed average: E[(A − B)²]/4.
    let noise = |a: &Img, b: &Img| mse(a, b) / 4.0;
    let t = Instant::now();
    let prep = render::prepare(&setup, &table, &popts, &ropts).unwrap();
    let st = prep.points.stats;
    println!(
        "pre-processing: surface {:.0} ms, light rays {:.0} ms, photons {:.0} ms, indirect {:.0} ms, the rest (trees, inner irradiance, emission) {:.0} ms; {} volume samples",
        st.surface_ms,
        st.volume_ms,
        st.photon_ms,
        st.indirect_ms,
        prep.preprocess_ms - st.surface_ms - st.volume_ms - st.photon_ms - st.indirect_ms,
        prep.points.volume.len()
    );
    let frame = render::render(&setup, &table, &prep, &cam, &ropts, &|_| {}).unwrap();
    let ms = t.elapsed().as_secs_f64() * 1e3;
    let mb: Img =
        frame.multiple.iter().zip(&frame.bounced).map(|(a, b)| std::array::from_fn(|c| a[c] + b[c])).collect();
    let pt = frame.total();
    let rt0 = total(&refs[0].0);
    let rt1 = total(&refs[1].0);
    println!(
        "{name} spp {spp}x2 scale {scale:.4e} | point {ms:.0} ms (pre {:.0}, single {:.0}, dm {:.0}, bounced {:.0}, rest {:.0}) cut {:.0} terms {} interp {}/{}",
        prep.preprocess_ms,
        frame.times.single_ms,
        frame.times.double_multiple_ms,
        frame.times.bounced_ms,
        frame.times.rest_ms,
        frame.stats.mean_cut,
        prep.reflection_terms,
        frame.stats.interpolated,
        frame.stats.segments
    );
    let rows: [(&str, &Img, usize); 4] =
        [("rest", &frame.rest, 0), ("single", &frame.single, 1), ("double", &frame.double, 2), ("mult+bnc", &mb, 3)];
    for (label, img, k) in rows {
        let n = noise(&refs[0].0[k], &refs[1].0[k]);
        let e = mse(img, &avg[k]);
        let (sp, sr) = (sums(img), sums(&avg[k]));
        println!(
            "  {label:9} mse {e:.2e} noise {n:.2e} corr {:.2e} | sum point/ref R {:.3} G {:.3} B {:.3} (ref sums {:.1} {:.1} {:.1})",
            e - n,
            sp[0] / sr[0],
            sp[1] / sr[1],
            sp[2] / sr[2],
            sr[0],
            sr[1],
            sr[2]
        );
    }
    let n = noise(&rt0, &rt1);
    let e = mse(&pt, &ref_total);
    let (sp, sr) = (sums(&pt), sums(&ref_total));
    println!(
        "  TOTAL     mse {e:.2e} noise {n:.2e} corr {:.2e} | sum ratio {:.3} {:.3} {:.3}",
        e - n,
        sp[0] / sr[0],
        sp[1] / sr[1],
        sp[2] / sr[2]
    );
    for k in 0..4 {
        let (a, b) = (sums(&refs[0].0[k]), sums(&refs[1].0[k]));
        println!("  ref comp {k} seed sums {:.2} {:.2} {:.2} / {:.2} {:.2} {:.2}", a[0], a[1], a[2], b[0], b[1], b[2]);
    }
    // Images for inspection: point-based and reference totals, normalised, as JSON (`dump=PATH`).
    if let Some(path) = args[3..].iter().find_map(|kv| kv.strip_prefix("dump=")) {
        let v = serde_json::json!({ "w": w, "scale": scale, "point": pt, "reference": ref_total, "mask": mask,
            "components": [&frame.rest, &frame.single, &frame.double, &mb], "ref_components": &avg });
        std::fs::write(path, serde_json::to_vec(&v).unwrap()).unwrap();
    }
    // Multiple alone against ≥3 with bounced separately listed.
    let (sm, sb) = (sums(&frame.multiple), sums(&frame.bounced));
    println!(
        "  multiple sums {:.1} {:.1} {:.1} bounced sums {:.1} {:.1} {:.1}",
        sm[0], sm[1], sm[2], sb[0], sb[1], sb[2]
    );
}
