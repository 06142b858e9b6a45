//! Tests of the plot module.
//!
//! Input: small synthetic plots (and axis spans for the tick tests).
//! Output: pass/fail — PNGs are written to per-test temporary folders,
//! decoded with the `image` crate and checked for size, content and
//! determinism; error cases are checked for their [`PlotError`] variant.

use std::fs;
use std::path::{Path, PathBuf};

use super::axis::{linear_ticks, log_axis};
use super::render::render_rgb;
use super::*;

/// A decoded 8-bit RGB PNG.
struct Decoded {
    width: u32,
    height: u32,
    rgb: Vec<u8>,
}

/// Decodes PNG `bytes`, insisting on the 8-bit RGB layout the plots use.
fn decode(bytes: &[u8]) -> Decoded {
    assert_eq!(image::guess_format(bytes).expect("format"), image::ImageFormat::Png);
    let img = image::load_from_memory(bytes).expect("decode");
    assert_eq!(img.color(), image::ColorType::Rgb8);
    let img = img.into_rgb8();
    Decoded { width: img.width(), height: img.height(), rgb: img.into_raw() }
}

fn tempdir(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("voltab-plot-test-{}-{tag}", std::process::id()));
    let _ = fs::remove_dir_all(&dir);
    fs::create_dir_all(&dir).expect("create test dir");
    dir
}

fn sample_series() -> Vec<Series> {
    (0..3)
        .map(|s| Series {
            name: format!("order {}", s + 1),
            points: (0..12)
                .map(|i| {
                    let t = 10f64.powf(-3.0 + 0.25 * f64::from(i));
                    (t, 0.5 * t.powi(s + 1))
                })
                .collect(),
        })
        .collect()
}

fn plot_of(series: &[Series], x: Scale, y: Scale) -> Plot<'_> {
    Plot {
        title: "Error vs time step",
        x_label: "dt [s]",
        y_label: "max abs error",
        x_scale: x,
        y_scale: y,
        series,
        width: 640,
        height: 480,
    }
}

#[test]
fn writes_png_of_requested_size() {
    let dir = tempdir("size");
    let series = sample_series();
    let mut plot = plot_of(&series, Scale::Log10, Scale::Log10);
    plot.width = 500;
    plot.height = 333;
    let path = dir.join("a.png");
    let outcome = write_png(&path, &plot).expect("write");
    assert_eq!(outcome.points_drawn, 36);
    assert_eq!(outcome.points_skipped, 0);
    let img = decode(&fs::read(&path).expect("read"));
    assert_eq!((img.width, img.height), (500, 333));
    assert_eq!(img.rgb.len(), 500 * 333 * 3);
    // Only the PNG remains: the temporary file was renamed away.
    let names: Vec<_> = fs::read_dir(&dir).expect("list").flatten().collect();
    assert_eq!(names.len(), 1);
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let mode = fs::metadata(&path).expect("stat").permissions().mode();
        assert_eq!(mode & 0o777, 0o644, "{mode:o}");
    }
    let _ = fs::remove_dir_all(&dir);
}

#[test]
fn encode_rejects_mismatched_buffer() {
    let err = encode_png(&[255; 10], MIN_SIDE, MIN_SIDE).expect_err("short buffer");
    assert!(err.contains("expected"), "{err}");
}

#[test]
fn decoded_pixels_match_render_and_show_data() {
    let dir = tempdir("pixels");
    let series = sample_series();
    let plot = plot_of(&series, Scale::Log10, Scale::Log10);
    let path = dir.join("p.png");
    write_png(&path, &plot).expect("write");
    let img = decode(&fs::read(&path).expect("read"));
    let (rendered, _) = render_rgb(&plot).map_err(|e| format!("{e:?}")).expect("render");
    assert!(img.rgb == rendered, "PNG decodes to the rendered pixels");

    // Saturated (series-coloured) pixels inside the central plot area.
    let (w, h) = (img.width as usize, img.height as usize);
    let mut coloured = 0;
    for y in h / 5..h * 4 / 5 {
        for x in w / 5..w * 4 / 5 {
            let p = &img.rgb[(y * w + x) * 3..(y * w + x) * 3 + 3];
            let max = p.iter().max().copied().unwrap_or(0);
            let min = p.iter().min().copied().unwrap_or(0);
            if max - min > 60 {
                coloured += 1;
            }
        }
    }
    assert!(coloured > 200, "only {coloured} coloured pixels");
    let _ = fs::remove_dir_all(&dir);
}

#[test]
fn output_is_deterministic() {
    let dir = tempdir("det");
    let series = sample_series();
    let plot = plot_of(&series, Scale::Log10, Scale::Linear);
    let a = dir.join("a.png");
    let b = dir.join("b.png");
    write_png(&a, &plot).expect("write a");
    write_png(&b, &plot).expect("write b");
    write_png(&a, &plot).expect("overwrite a");
    let bytes_a = fs::read(&a).expect("read a");
    assert!(bytes_a == fs::read(&b).expect("read b"));
    assert!(bytes_a.starts_with(b"\x89PNG\r\n\x1a\n"));
    // The file holds exactly the in-memory encoding, which is repeatable.
    let (pixels, _) = render_rgb(&plot).map_err(|e| format!("{e:?}")).expect("render");
    let png = encode_png(&pixels, plot.width, plot.height).expect("encode");
    assert!(png == bytes_a, "file bytes equal the in-memory PNG");
    assert!(encode_png(&pixels, plot.width, plot.height).expect("encode again") == png);
    let _ = fs::remove_dir_all(&dir);
}

#[test]
fn empty_and_all_invalid_give_axes_only_png() {
    let dir = tempdir("empty");
    let bad = [
        Series { name: "empty".into(), points: vec![] },
        Series {
            name: "invalid".into(),
            points: vec![(f64::NAN, 1.0), (1.0, f64::INFINITY), (0.0, 1.0), (1.0, -2.0), (f64::NEG_INFINITY, f64::NAN)],
        },
    ];
    for (name, series, scale) in [
        ("none.png", &[][..], Scale::Linear),
        ("none_log.png", &[][..], Scale::Log10),
        ("bad.png", &bad[..], Scale::Log10),
    ] {
        let path = dir.join(name);
        let outcome = write_png(&path, &plot_of(series, scale, scale)).expect(name);
        let expected_skipped = if series.is_empty() { 0 } else { 5 };
        assert_eq!(outcome, PlotOutcome { points_drawn: 0, points_skipped: expected_skipped });
        let img = decode(&fs::read(&path).expect("read"));
        assert_eq!((img.width, img.height), (640, 480));
        // Axes and text are drawn: some dark pixels.
        assert!(img.rgb.chunks(3).any(|p| p.iter().all(|&c| c < 64)));
    }
    let _ = fs::remove_dir_all(&dir);
}

#[test]
fn log_axis_skips_nonpositive_and_counts_them() {
    let dir = tempdir("skip");
    let series = vec![Series {
        name: "s".into(),
        points: vec![(1.0, 1.0), (2.0, 0.0), (3.0, -1.0), (4.0, 1e-3), (f64::NAN, 2.0)],
    }];
    let log = write_png(&dir.join("l.png"), &plot_of(&series, Scale::Linear, Scale::Log10)).expect("log");
    assert_eq!(log, PlotOutcome { points_drawn: 2, points_skipped: 3 });
    let lin = write_png(&dir.join("n.png"), &plot_of(&series, Scale::Linear, Scale::Linear)).expect("linear");
    assert_eq!(lin, PlotOutcome { points_drawn: 4, points_skipped: 1 });
    let _ = fs::remove_dir_all(&dir);
}

#[test]
fn degenerate_and_extreme_ranges_do_not_fail() {
    let dir = tempdir("degenerate");
    let cases: Vec<Vec<(f64, f64)>> = vec![
        vec![(1.0, 1.0)],
        vec![(0.0, 0.0)],
        vec![(5.0, 3.0), (5.0, 3.0)],
        vec![(1e-300, 1e300), (1e300, 1e-300)],
        vec![(1e16, 1.0), (1e16 + 2.0, 1.0 + 1e-15)],
        vec![(3.1, 3.2), (3.3, 3.4)],
        vec![(f64::MIN_POSITIVE, 1.0), (f64::MAX, 2.0)],
        vec![(-1e-9, 1e-9), (1e-9, -1e-9)],
    ];
    for (i, points) in cases.into_iter().enumerate() {
        let series = vec![Series { name: format!("case {i}"), points }];
        for (x, y) in [(Scale::Linear, Scale::Linear), (Scale::Log10, Scale::Log10), (Scale::Linear, Scale::Log10)] {
            let mut plot = plot_of(&series, x, y);
            plot.width = MIN_SIDE;
            plot.height = MIN_SIDE;
            let path = dir.join(format!("c{i}.png"));
            match write_png(&path, &plot) {
                Ok(outcome) => {
                    assert_eq!(outcome.points_drawn + outcome.points_skipped, series[0].points.len());
                }
                // Only f64::MAX on a linear axis overflows the padded span.
                Err(PlotError::InvalidRange { .. }) if i == 6 && x == Scale::Linear => {}
                Err(e) => panic!("case {i}: {e}"),
            }
        }
    }
    let _ = fs::remove_dir_all(&dir);
}

#[test]
fn overflowing_linear_span_is_a_clear_error() {
    let dir = tempdir("overflow");
    let series = vec![Series { name: "huge".into(), points: vec![(-f64::MAX, 0.0), (f64::MAX, 1.0)] }];
    let path = dir.join("o.png");
    let err = write_png(&path, &plot_of(&series, Scale::Linear, Scale::Linear)).expect_err("overflow");
    assert!(matches!(err, PlotError::InvalidRange { .. }), "{err}");
    assert!(err.to_string().contains("o.png"), "{err}");
    assert!(!path.exists());
    let _ = fs::remove_dir_all(&dir);
}

#[test]
fn many_series_and_sizes() {
    let dir = tempdir("many");
    let series: Vec<Series> = (0..12)
        .map(|i| Series { name: format!("s{i}"), points: (0..5).map(|j| (f64::from(j), f64::from(i * j))).collect() })
        .collect();
    for (w, h) in [(MIN_SIDE, MIN_SIDE), (1200, 300), (300, 900), (1600, 1200)] {
        let mut plot = plot_of(&series, Scale::Linear, Scale::Linear);
        plot.width = w;
        plot.height = h;
        let path = dir.join("m.png");
        let outcome = write_png(&path, &plot).expect("write");
        assert_eq!(outcome.points_drawn, 60);
        let img = decode(&fs::read(&path).expect("read"));
        assert_eq!((img.width, img.height), (w, h));
    }
    let _ = fs::remove_dir_all(&dir);
}

#[test]
fn rejects_bad_size_and_path() {
    let series = sample_series();
    let mut plot = plot_of(&series, Scale::Linear, Scale::Linear);
    plot.width = 0;
    let err = write_png(Path::new("x.png"), &plot).expect_err("zero width");
    assert!(matches!(err, PlotError::InvalidSize { .. }));
    assert!(err.to_string().contains("x.png"));
    plot.width = MAX_SIDE + 1;
    assert!(matches!(write_png(Path::new("x.png"), &plot), Err(PlotError::InvalidSize { .. })));
    plot.width = 640;
    assert!(matches!(write_png(Path::new("/"), &plot), Err(PlotError::InvalidPath { .. })));
}

#[test]
fn unwritable_directory_is_an_error() {
    let dir = tempdir("unwritable");
    let series = sample_series();
    let plot = plot_of(&series, Scale::Log10, Scale::Log10);
    // A directory that does not exist.
    let missing = dir.join("no/such/dir/p.png");
    let err = write_png(&missing, &plot).expect_err("missing dir");
    assert!(matches!(err, PlotError::Io { .. }), "{err}");
    assert!(err.to_string().contains("p.png"), "{err}");
    let source = std::error::Error::source(&err).expect("source");
    assert!(source.is::<crate::cache::CacheError>(), "{source}");
    // A regular file used as the directory.
    let file = dir.join("file");
    fs::write(&file, b"x").expect("write file");
    let err = write_png(&file.join("p.png"), &plot).expect_err("file as dir");
    assert!(matches!(err, PlotError::Io { .. }), "{err}");
    // The destination is an existing directory: the rename fails and
    // the temporary file is cleaned up.
    let target = dir.join("target.png");
    fs::create_dir(&target).expect("mkdir");
    fs::write(target.join("keep"), b"x").expect("write keep");
    let err = write_png(&target, &plot).expect_err("dir as target");
    assert!(matches!(err, PlotError::Io { .. }), "{err}");
    let leftovers: Vec<_> = fs::read_dir(&dir)
        .expect("list")
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().contains(".tmp"))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
    let _ = fs::remove_dir_all(&dir);
}

#[cfg(unix)]
#[test]
fn read_only_directory_is_an_error() {
    use std::os::unix::fs::PermissionsExt;
    let dir = tempdir("readonly");
    let ro = dir.join("ro");
    fs::create_dir(&ro).expect("mkdir");
    fs::set_permissions(&ro, fs::Permissions::from_mode(0o555)).expect("chmod");
    // Root ignores directory permissions; only check when they apply.
    let probe = ro.join("probe");
    let enforced = fs::write(&probe, b"x").is_err();
    let _ = fs::remove_file(&probe);
    if enforced {
        let series = sample_series();
        let err =
            write_png(&ro.join("p.png"), &plot_of(&series, Scale::Linear, Scale::Linear)).expect_err("read-only dir");
        assert!(matches!(err, PlotError::Io { .. }), "{err}");
    }
    let _ = fs::set_permissions(&ro, fs::Permissions::from_mode(0o755));
    let _ = fs::remove_dir_all(&dir);
}

#[test]
fn log_ticks_are_decades() {
    let axis = log_axis(Some((-3.0, 0.0)), 6);
    assert_eq!(axis.labels, ["1e-3", "1e-2", "1e-1", "1e0"]);
    assert_eq!(axis.ticks, [-3.0, -2.0, -1.0, 0.0]);
    assert!(axis.lo < -3.0 && axis.lo > -3.5 && axis.hi > 0.0 && axis.hi < 0.5);
    assert!(!axis.minor.is_empty());
    let wide = log_axis(Some((-30.0, 30.0)), 6);
    assert!(wide.ticks.len() <= 8 && wide.ticks.len() >= 2, "{:?}", wide.labels);
    assert!(wide.labels.iter().all(|l| l.starts_with("1e")));
    let (strides, labels): (Vec<f64>, Vec<&str>) =
        (wide.ticks.windows(2).map(|w| w[1] - w[0]).collect(), wide.labels.iter().map(String::as_str).collect());
    assert!(strides.iter().all(|&d| d == 10.0 || d == 20.0), "{labels:?}");
    let narrow = log_axis(Some((0.3, 0.7)), 6);
    assert_eq!(narrow.labels, ["2", "3", "4", "5", "6"]);
    let tiny = log_axis(Some((-5.5, -5.0)), 6);
    assert!(tiny.labels.len() >= 3 && tiny.labels.iter().all(|l| l.contains("e-")), "{:?}", tiny.labels);
    let very_narrow = log_axis(Some((0.50, 0.51)), 6);
    assert!(very_narrow.ticks.len() >= 3, "{:?}", very_narrow.labels);
    for axis in [&axis, &wide, &narrow, &tiny, &very_narrow] {
        assert!(axis.ticks.windows(2).all(|w| w[0] < w[1]));
        assert!(axis.ticks.iter().all(|t| (axis.lo..=axis.hi).contains(t)));
        assert_eq!(axis.ticks.len(), axis.labels.len());
    }
}

#[test]
fn legend_fits_many_series_and_odd_names() {
    let dir = tempdir("legend");
    let series: Vec<Series> = (0..40)
        .map(|i| Series {
            name: format!("series\twith a very long name that cannot fit {i}\n"),
            points: vec![(1.0, f64::from(i) + 1.0), (2.0, f64::from(i) + 2.0)],
        })
        .collect();
    for n in [1, 3, 40] {
        let plot = plot_of(&series[..n], Scale::Log10, Scale::Log10);
        let outcome = write_png(&dir.join("l.png"), &plot).expect("write");
        assert_eq!(outcome.points_drawn, 2 * n);
    }
    let _ = fs::remove_dir_all(&dir);
}

#[test]
fn linear_ticks_are_nice() {
    let (ticks, labels) = linear_ticks(-0.05, 1.05, 6);
    assert_eq!(ticks, [0.0, 0.2, 0.4, 0.6000000000000001, 0.8, 1.0]);
    assert_eq!(labels, ["0", "0.2", "0.4", "0.6", "0.8", "1.0"]);
    let (_, labels) = linear_ticks(0.0, 3e7, 4);
    assert_eq!(labels, ["0", "1e7", "2e7", "3e7"]);
    let (_, labels) = linear_ticks(-2.0, 2.0, 4);
    assert_eq!(labels, ["-2", "-1", "0", "1", "2"]);
}
