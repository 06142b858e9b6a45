//! Writes the bundled sky map `scenes/sky.exr` (voltab's procedural sky without a sun, 128 × 64,
//! latitude-longitude, relative radiance; see `render::environment::bundled_sky`).
//!
//! Usage: `cargo run --example make_sky` (from the repository root). A unit test checks the file
//! against the code, so rerun this when the sky changes.

use std::path::Path;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let sky = voltab::render::environment::bundled_sky();
    let pixels: Vec<[f32; 3]> = sky.radiance.iter().map(|v| v.map(|c| c as f32)).collect();
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/sky.exr");
    voltab::image_io::write_exr_rgb(&path, sky.width, sky.height, &pixels, &[])?;
    let png = path.with_extension("png");
    voltab::image_io::write_png_preview(&png, sky.width, sky.height, &pixels, None)?;
    println!("wrote {} and {}", path.display(), png.display());
    Ok(())
}
