//! What the screen-space effect stages share: scene + camera → G-buffer, and images → EXR + PNG.
//!
//! **Input → output.** A scene file (relative to the pipeline file), a camera index and a raster size →
//! the scene, its BVH and a [`GBuffer`] (vacuum colour and distance, rendered by voltab's own ray tracer,
//! so `EpipolarShadows` and `ImageFog` run on any imported scene); and, for writing, linear RGB images →
//! `<name>.exr` (float RGB plus named layers) and a `<name>.png` preview, atomically.

use std::path::{Path, PathBuf};
use std::time::Instant;

use super::{StageContext, StageError};
use crate::render::gbuffer::{self, ColourOptions, GBuffer};
use crate::render::{RgbImage, ViewCamera};
use crate::scene::Scene;
use crate::scene::bvh::SceneBvh;
use crate::tables::FieldIssue;

/// The view fields both effect stages have.
#[derive(Debug, Clone, Copy)]
pub struct ViewFields<'a> {
    /// Scene path as written.
    pub scene: &'a str,
    /// Camera index in the scene.
    pub camera: u32,
    /// Raster width.
    pub width: u32,
    /// Raster height.
    pub height: u32,
    /// Colour paths per pixel.
    pub colour_samples: u32,
    /// Output folder name.
    pub output: &'a str,
}

/// Implements `fields()` (the shared [`ViewFields`]) and `scene_path()` for a stage whose resolved
/// parameters have `scene`, `camera`, `width`, `height`, `colour_samples` and `output`.
macro_rules! impl_view_fields {
    ($ty:ty) => {
        impl $ty {
            fn fields(&self) -> $crate::stages::view::ViewFields<'_> {
                $crate::stages::view::ViewFields {
                    scene: &self.scene,
                    camera: self.camera,
                    width: self.width,
                    height: self.height,
                    colour_samples: self.colour_samples,
                    output: &self.output,
                }
            }

            /// The scene file resolved against the pipeline's folder.
            pub fn scene_path(&self, base_dir: &std::path::Path) -> std::path::PathBuf {
                self.fields().scene_path(base_dir)
            }
        }
    };
}
pub(crate) use impl_view_fields;

/// A loaded view.
pub struct View {
    /// The scene.
    pub scene: std::sync::Arc<Scene>,
    /// Its BVH.
    pub bvh: SceneBvh,
    /// Colour and distance buffers of the chosen camera.
    pub gbuffer: GBuffer,
    /// Scene import \[ms\].
    pub import_ms: f64,
    /// BVH build \[ms\].
    pub bvh_ms: f64,
}

impl ViewFields<'_> {
    /// Range checks of the shared fields.
    pub fn validate(&self) -> Vec<FieldIssue> {
        let mut v = Vec::new();
        let mut issue = |field: &'static str, message: String, help: &str| {
            v.push(FieldIssue { field, message, help: help.into() });
        };
        if self.scene.is_empty() {
            issue("scene", "scene is empty".into(), "give the scene file, e.g. scene: \"../scenes/window_room.gltf\"");
        }
        for (field, n) in [("width", self.width), ("height", self.height)] {
            if !(1..=8192).contains(&n) {
                issue(field, format!("{field} = {n}"), "use 1 to 8192 pixels");
            }
        }
        if !(1..=65_536).contains(&self.colour_samples) {
            issue("colour_samples", format!("colour_samples = {}", self.colour_samples), "use 1 to 65536");
        }
        let plain = |s: &str| s.chars().all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.'));
        if !self.output.is_empty() && (!plain(self.output) || self.output.starts_with('.')) {
            issue(
                "output",
                format!("output = \"{}\" is not a plain folder name", self.output),
                "use letters, digits, '_', '-', '.'",
            );
        }
        v
    }

    /// The scene file resolved against the pipeline's folder.
    pub fn scene_path(&self, base_dir: &Path) -> PathBuf {
        base_dir.join(self.scene)
    }

    /// The stage's output folder, created.
    pub fn out_dir(&self, id: &str, ctx: &StageContext) -> Result<PathBuf, StageError> {
        let dir = ctx.out_dir.join(if self.output.is_empty() { id } else { self.output });
        std::fs::create_dir_all(&dir).map_err(|e| StageError::Output {
            stage: id.into(),
            path: dir.clone(),
            message: e.to_string(),
        })?;
        Ok(dir)
    }

    /// Imports the scene, builds its BVH, picks the camera and renders the G-buffer at `width × height`
    /// (or at the given override size).
    pub fn load(&self, id: &str, ctx: &StageContext, size: Option<(usize, usize)>) -> Result<View, StageError> {
        let fail = |message: String, help: &str| StageError::Input { stage: id.into(), message, help: help.into() };
        let path = self.scene_path(ctx.base_dir);
        let t0 = Instant::now();
        let scene = ctx.scenes.load(&path).map_err(|e| fail(e.to_string(), "fix the scene file or the scene field"))?;
        let import_ms = ms(t0);
        let t0 = Instant::now();
        let bvh = SceneBvh::build(&scene);
        let bvh_ms = ms(t0);
        let cam = self.camera(id, &scene, &path, size)?;
        let opts = ColourOptions { samples: self.colour_samples, bounces: 0, seed: 0 };
        let gbuffer = gbuffer::render(&scene, &bvh, &cam, &opts);
        Ok(View { scene, bvh, gbuffer, import_ms, bvh_ms })
    }

    /// The chosen scene camera on this stage's raster.
    pub fn camera(
        &self,
        id: &str,
        scene: &Scene,
        path: &Path,
        size: Option<(usize, usize)>,
    ) -> Result<ViewCamera, StageError> {
        let fail = |message: String, help: String| StageError::Input { stage: id.into(), message, help };
        let (w, h) = size.unwrap_or((self.width as usize, self.height as usize));
        let c = scene.cameras.get(self.camera as usize).ok_or_else(|| {
            fail(
                format!(
                    "{} has {} cameras; camera = {} does not exist",
                    path.display(),
                    scene.cameras.len(),
                    self.camera
                ),
                "add a perspective camera to the scene, or set camera to an index below the scene's camera count"
                    .into(),
            )
        })?;
        ViewCamera::from_scene(c, w, h).ok_or_else(|| {
            fail(
                format!("{}: camera \"{}\" is not a usable perspective camera", path.display(), c.name),
                "use a perspective camera with 0 < yfov < π and orthogonal forward/up vectors".into(),
            )
        })
    }
}

/// Writes `<dir>/<name>.exr` (`main` as RGB plus `layers`) and `<dir>/<name>.png` (a preview of `main`),
/// returning both paths.
pub fn write_image(
    id: &str,
    dir: &Path,
    name: &str,
    main: &RgbImage,
    layers: &[(&str, &RgbImage)],
) -> Result<Vec<PathBuf>, StageError> {
    let exr = dir.join(format!("{name}.exr"));
    let png = dir.join(format!("{name}.png"));
    let io = |path: &Path, e: crate::image_io::ImageError| StageError::Output {
        stage: id.into(),
        path: path.to_path_buf(),
        message: e.to_string(),
    };
    let extra: Vec<(&str, &[[f32; 3]])> = layers.iter().map(|(n, img)| (*n, img.data.as_slice())).collect();
    crate::image_io::write_exr_rgb(&exr, main.width, main.height, &main.data, &extra).map_err(|e| io(&exr, e))?;
    crate::image_io::write_png_preview(&png, main.width, main.height, &main.data, None).map_err(|e| io(&png, e))?;
    Ok(vec![exr, png])
}

/// Writes a JSON summary atomically.
pub fn write_json<T: serde::Serialize>(id: &str, path: &Path, value: &T) -> Result<PathBuf, StageError> {
    let out = |message: String| StageError::Output { stage: id.into(), path: path.to_path_buf(), message };
    let json = serde_json::to_vec_pretty(value).map_err(|e| out(e.to_string()))?;
    crate::cache::write_atomic(path, &json).map_err(|e| out(e.to_string()))?;
    Ok(path.to_path_buf())
}

/// Milliseconds since `t0`.
pub fn ms(t0: Instant) -> f64 {
    t0.elapsed().as_secs_f64() * 1e3
}

/// Per pixel of `cam`: the path-traced radiance (mean) and its standard error (see [`path_trace`]).
pub fn path_trace_pixels(
    scene: &Scene,
    bvh: &SceneBvh,
    cam: &ViewCamera,
    samples: u32,
    depth: u32,
    media: bool,
) -> Vec<([f64; 3], [f64; 3])> {
    let opts = crate::reference::volpath::VolPathOptions {
        samples,
        max_depth: depth,
        rr_depth: 4,
        seed: if media { 0x5eed } else { 0x5eed ^ 1 },
        surface_bounces: u32::MAX,
        eye_surfaces: true,
        media,
    };
    path_trace_pixels_with(scene, bvh, cam, &opts)
}

/// Per pixel of `cam` (row-major), the path-traced radiance through the pixel's centre and its standard
/// error with any [`VolPathOptions`](crate::reference::volpath::VolPathOptions).
pub fn path_trace_pixels_with(
    scene: &Scene,
    bvh: &SceneBvh,
    cam: &ViewCamera,
    opts: &crate::reference::volpath::VolPathOptions,
) -> Vec<([f64; 3], [f64; 3])> {
    use crate::reference::volpath::{self, CameraRay};
    let rays: Vec<CameraRay> = (0..cam.height)
        .flat_map(|y| (0..cam.width).map(move |x| (x, y)))
        .map(|(x, y)| CameraRay { origin: cam.position.to_array(), direction: cam.pixel_dir(x, y).to_array() })
        .collect();
    let (est, _) = volpath::radiance(scene, bvh, &rays, opts);
    est.iter().map(|e| (e.mean, e.stderr)).collect()
}

/// Path-traced image of `cam` ([`volpath::radiance`], surfaces bounce, `samples` paths per pixel, at
/// most `depth` vertices) with or without media, and the variance of each pixel's mean (non-finite
/// estimates read 0). The two settings of `media` use independent random streams.
///
/// [`volpath::radiance`]: crate::reference::volpath::radiance
pub fn path_trace(
    scene: &Scene,
    bvh: &SceneBvh,
    cam: &ViewCamera,
    samples: u32,
    depth: u32,
    media: bool,
) -> (RgbImage, Vec<[f64; 3]>) {
    let est = path_trace_pixels(scene, bvh, cam, samples, depth, media);
    let finite = |v: [f64; 3]| v.map(|c| if c.is_finite() { c } else { 0.0 });
    let img = crate::render::Image {
        width: cam.width,
        height: cam.height,
        data: est.iter().map(|e| finite(e.0).map(|c| c as f32)).collect(),
    };
    (img, est.iter().map(|e| finite(e.1.map(|s| s * s))).collect())
}
