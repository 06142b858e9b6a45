//! The shader type of the GPU passes and its validation by naga (the front end and validator wgpu
//! itself compiles them with). Each technique keeps its `.wgsl` files in `src/stages/<technique>/shaders/`
//! and lists them in its own `shaders.rs`; a test here checks that every file is listed and validates.
//!
//! **Input → output.** The shader files (compiled into the binary with `include_str!`) → a parsed
//! and validated naga module, or a diagnostic naming the file, line and column. Every kernel goes
//! through [`Shader::validate`] before wgpu sees it, and a test validates every file, so a typo in a
//! shader fails `cargo test`, not a user's run. Each file's header comment documents its bindings.

use wgpu::naga;

/// One shader file.
#[derive(Debug, Clone, Copy)]
pub struct Shader {
    /// The folder holding the file, relative to the crate root (`src/stages/<technique>/shaders`).
    pub dir: &'static str,
    /// File name in `dir`.
    pub name: &'static str,
    /// WGSL source.
    pub source: &'static str,
}

impl Shader {
    /// Parses and validates the source with naga.
    ///
    /// # Errors
    /// The rendered diagnostic (`file:line:column` and the offending source line).
    pub fn validate(&self) -> Result<naga::valid::ModuleInfo, String> {
        let path = format!("{}/{}", self.dir, self.name);
        let module =
            naga::front::wgsl::parse_str(self.source).map_err(|e| e.emit_to_string_with_path(self.source, &path))?;
        naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::default())
            .validate(&module)
            .map_err(|e| e.emit_to_string_with_path(self.source, &path))
    }
}

#[cfg(test)]
mod tests;
