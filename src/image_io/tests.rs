//! EXR round trips and PNG preview exposure, pinned against hand-computed values.

use super::*;

/// A deterministic, awkward pattern: negative, tiny, huge and subnormal values (bit-exactness test).
fn pattern(n: usize, seed: u32) -> Vec<[f32; 3]> {
    (0..n as u32)
        .map(|i| {
            let k = i.wrapping_mul(2_654_435_761).wrapping_add(seed);
            [f32::from_bits(k % 0x7f00_0000), -(i as f32) * 0.1 - 1e-30, 1.0 / (i as f32 + 0.37)]
        })
        .collect()
}

fn bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|x| x.to_bits()).collect()
}

#[test]
fn exr_round_trip_is_bit_exact_with_layers_and_odd_sizes() {
    let dir = tempfile::tempdir().expect("tempdir");
    for (w, h) in [(1, 1), (7, 3), (3, 7)] {
        let main = pattern(w * h, 1);
        let direct = pattern(w * h, 2);
        let scattered = pattern(w * h, 3);
        let path = dir.path().join(format!("lm_{w}x{h}.exr"));
        write_exr_rgb(&path, w, h, &main, &[("direct", &direct), ("scattered", &scattered)]).expect("write");
        let img = read_exr_rgb(&path).expect("read");
        assert_eq!((img.width, img.height), (w, h));
        let names: Vec<&str> = img.channels.keys().map(String::as_str).collect();
        assert_eq!(
            names,
            ["B", "G", "R", "direct.B", "direct.G", "direct.R", "scattered.B", "scattered.G", "scattered.R"]
        );
        for (layer, data) in [(None, &main), (Some("direct"), &direct), (Some("scattered"), &scattered)] {
            let got = img.rgb(layer).expect("layer present");
            for c in 0..3 {
                let want: Vec<f32> = data.iter().map(|p| p[c]).collect();
                let have: Vec<f32> = got.iter().map(|p| p[c]).collect();
                assert_eq!(bits(&have), bits(&want), "{w}x{h} layer {layer:?} channel {c}");
            }
        }
        assert!(img.rgb(Some("missing")).is_none());
    }
}

#[test]
fn exr_bytes_are_deterministic() {
    let dir = tempfile::tempdir().expect("tempdir");
    let px = pattern(12, 9);
    let (a, b) = (dir.path().join("a.exr"), dir.path().join("b.exr"));
    write_exr_rgb(&a, 4, 3, &px, &[]).expect("write a");
    write_exr_rgb(&b, 4, 3, &px, &[]).expect("write b");
    assert_eq!(std::fs::read(&a).expect("a"), std::fs::read(&b).expect("b"));
}

#[test]
fn exr_rejects_nan_naming_the_first_bad_pixel() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("bad.exr");
    let mut px = vec![[0.5f32; 3]; 7 * 3];
    px[7 + 4][1] = f32::NAN; // x 4, y 1, G
    px[2 * 7][0] = f32::INFINITY; // later
    let err = write_exr_rgb(&path, 7, 3, &px, &[]).expect_err("NaN");
    let msg = err.to_string();
    assert!(msg.contains("bad.exr: pixels: pixel (x 4, y 1) channel G is NaN"), "{msg}");
    assert!(!path.exists(), "nothing written");

    let good = vec![[0.5f32; 3]; 21];
    let mut layer = good.clone();
    layer[20][2] = f32::NEG_INFINITY;
    let err = write_exr_rgb(&path, 7, 3, &good, &[("scattered", &layer)]).expect_err("inf in layer");
    assert!(err.to_string().contains("layer \"scattered\": pixel (x 6, y 2) channel B is -inf"), "{err}");
}

#[test]
fn exr_rejects_bad_sizes_and_layer_names() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("x.exr");
    let px = vec![[0.0f32; 3]; 6];
    let msg = write_exr_rgb(&path, 4, 2, &px, &[]).expect_err("length").to_string();
    assert!(msg.contains("pixels holds 6 pixels but the image is 4×2 = 8"), "{msg}");
    let msg = write_exr_rgb(&path, 0, 6, &[], &[]).expect_err("zero").to_string();
    assert!(msg.contains("cannot write a 0×6 image"), "{msg}");
    let short = vec![[0.0f32; 3]; 5];
    let msg = write_exr_rgb(&path, 3, 2, &px, &[("direct", &short)]).expect_err("layer length").to_string();
    assert!(msg.contains("layer \"direct\" holds 5 pixels"), "{msg}");
    for (name, reason) in [("", "is empty"), ("a.b", "contains characters"), ("dïrect", "contains characters")] {
        let msg = write_exr_rgb(&path, 3, 2, &px, &[(name, &px)]).expect_err("name").to_string();
        assert!(msg.contains(reason), "{name}: {msg}");
    }
    let msg = write_exr_rgb(&path, 3, 2, &px, &[("d", &px), ("d", &px)]).expect_err("twice").to_string();
    assert!(msg.contains("\"d\" is given twice"), "{msg}");
}

#[test]
fn reading_missing_or_truncated_exr_errors() {
    let dir = tempfile::tempdir().expect("tempdir");
    let missing = dir.path().join("missing.exr");
    let msg = read_exr_rgb(&missing).expect_err("missing").to_string();
    assert!(msg.contains("missing.exr: cannot read the image"), "{msg}");

    let path = dir.path().join("full.exr");
    write_exr_rgb(&path, 7, 3, &pattern(21, 4), &[]).expect("write");
    let bytes = std::fs::read(&path).expect("bytes");
    let cut = dir.path().join("cut.exr");
    for keep in [0, 3, bytes.len() / 2, bytes.len() - 1] {
        std::fs::write(&cut, &bytes[..keep]).expect("write cut");
        let msg = read_exr_rgb(&cut).expect_err("truncated").to_string();
        assert!(msg.contains("cut.exr: not a readable EXR image"), "keep {keep}: {msg}");
    }
}

#[test]
fn srgb_oetf_matches_iec_61966_2_1() {
    // Values from the standard's piecewise formula, evaluated independently (Python, f64).
    assert_eq!(srgb_oetf(0.0), 0.0);
    assert!((srgb_oetf(1.0) - 1.0).abs() < 1e-15);
    assert!((srgb_oetf(0.001) - 0.012_92).abs() < 1e-15);
    assert!((srgb_oetf(0.003_130_8) - 0.040_449_936).abs() < 1e-9);
    assert!((srgb_oetf(0.18) - 0.461_356_129_500_441_6).abs() < 1e-12);
    assert!((srgb_oetf(0.5) - 0.735_356_983_052_449_5).abs() < 1e-12);
    assert_eq!(srgb_oetf(-1.0), 0.0);
    assert_eq!(srgb_oetf(7.0), srgb_oetf(1.0));
}

#[test]
fn shoulder_is_identity_below_the_knee_and_c1_at_it() {
    assert_eq!(shoulder(0.25), 0.25);
    assert_eq!(shoulder(0.6), 0.6);
    // 0.6 + 0.4 · 0.2 / 0.6 = 0.7333…
    assert!((shoulder(0.8) - 0.733_333_333_333_333_4).abs() < 1e-15);
    let slope = (shoulder(0.6 + 1e-7) - 0.6) / 1e-7;
    assert!((slope - 1.0).abs() < 1e-6, "{slope}");
    assert!(shoulder(1e9) < 1.0 && shoulder(1e9) > 0.999_999);
    assert_eq!(shoulder(-3.0), 0.0);
}

fn decode(path: &Path) -> image::RgbImage {
    image::load_from_memory(&std::fs::read(path).expect("png")).expect("decode").to_rgb8()
}

#[test]
fn png_constant_image_exposure_is_key_over_luminance() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("c.png");
    // Luminance of a grey (2, 2, 2) is 2 → exposure 0.8 / 2 = 0.4; 0.8 → shoulder 0.7333 → sRGB
    // 0.872103 → 222.39 → 222 (Python).
    let e = write_png_preview(&path, 5, 3, &[[2.0; 3]; 15], None).expect("png");
    assert!((e - 0.4).abs() < 1e-15, "{e}");
    let img = decode(&path);
    assert_eq!(img.dimensions(), (5, 3));
    assert!(img.pixels().all(|p| p.0 == [222; 3]));
}

#[test]
fn png_exposure_uses_the_99th_percentile_of_valid_pixels() {
    // 199 grey pixels of luminance 1 and one at 1e6: nearest rank ⌈0.99·200⌉ = 198 → Y₉₉ = 1.
    let mut px = vec![[1.0f32; 3]; 200];
    px[17] = [1e6; 3];
    assert!((preview_exposure(&px, None) - 0.8).abs() < 1e-15);
    // Luminances 1..=100: rank 99 → Y₉₉ = 99.
    let ramp: Vec<[f32; 3]> = (1..=100).map(|k| [k as f32; 3]).collect();
    assert!((preview_exposure(&ramp, None) - 0.8 / 99.0).abs() < 1e-15);
    // Coloured: pure red 5 has luminance 0.2126 · 5 = 1.063.
    assert!((preview_exposure(&[[5.0, 0.0, 0.0]], None) - 0.8 / 1.063).abs() < 1e-12);
    // All black, or nothing valid: exposure 1.
    assert_eq!(preview_exposure(&[[0.0; 3]; 4], None), 1.0);
    assert_eq!(preview_exposure(&[[3.0; 3]; 2], Some(&[false, false])), 1.0);
}

#[test]
fn png_invalid_pixels_are_a_checker_and_ignored_by_exposure() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("v.png");
    let (w, h) = (8, 2);
    let mut px = vec![[0.5f32; 3]; w * h];
    let mut valid = vec![true; w * h];
    for x in 0..w {
        valid[w + x] = false; // second row invalid, holding garbage
        px[w + x] = [f32::NAN, 1e30, -4.0];
    }
    let e = write_png_preview(&path, w, h, &px, Some(&valid)).expect("png");
    // Valid luminance 0.5 → exposure 1.6; 0.5 · 1.6 = 0.8 → 222 as above.
    assert!((e - 1.6).abs() < 1e-15, "{e}");
    let img = decode(&path);
    assert_eq!(img.get_pixel(0, 0).0, [222; 3]);
    // Checker squares of 4 pixels: (x / 4 + y / 4) even → 24, odd → 40.
    assert_eq!(img.get_pixel(0, 1).0, [24; 3]);
    assert_eq!(img.get_pixel(3, 1).0, [24; 3]);
    assert_eq!(img.get_pixel(4, 1).0, [40; 3]);
}

#[test]
fn png_rejects_nan_and_bad_masks() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("p.png");
    let mut px = vec![[0.1f32; 3]; 6];
    px[5][2] = f32::NAN;
    let msg = write_png_preview(&path, 3, 2, &px, None).expect_err("nan").to_string();
    assert!(msg.contains("p.png: pixels: pixel (x 2, y 1) channel B is NaN"), "{msg}");
    let msg = write_png_preview(&path, 3, 2, &px, Some(&[true; 4])).expect_err("mask").to_string();
    assert!(msg.contains("valid mask holds 4 pixels"), "{msg}");
    assert!(!path.exists());
}
