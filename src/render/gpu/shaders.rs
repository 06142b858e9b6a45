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
mod tests {
    use super::*;

    /// Every technique's shader list.
    const ALL: &[&[Shader]] = &[
        crate::stages::god_rays::shaders::ALL,
        crate::stages::image_fog::shaders::ALL,
        crate::stages::pop::shaders::ALL,
    ];

    #[test]
    fn every_shader_file_is_listed_and_validates() {
        // A file under src/stages/*/shaders that ALL forgets would never be validated.
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let mut files: Vec<String> = Vec::new();
        for stage in std::fs::read_dir(root.join("src/stages")).expect("stages folder").filter_map(Result::ok) {
            let Ok(dir) = std::fs::read_dir(stage.path().join("shaders")) else { continue };
            for e in dir.filter_map(Result::ok) {
                let name = e.file_name().to_string_lossy().into_owned();
                if name.ends_with(".wgsl") {
                    files.push(format!("src/stages/{}/shaders/{name}", stage.file_name().to_string_lossy()));
                }
            }
        }
        files.sort();
        let mut listed: Vec<String> =
            ALL.iter().flat_map(|l| l.iter()).map(|s| format!("{}/{}", s.dir, s.name)).collect();
        listed.sort();
        assert_eq!(files, listed);
        assert_eq!(files.len(), 13, "god rays 6, image fog 4, POP 3");
        for s in ALL.iter().flat_map(|l| l.iter()) {
            if let Err(e) = s.validate() {
                panic!("{e}");
            }
        }
    }

    #[test]
    fn a_broken_shader_is_reported_with_its_file_and_line() {
        let broken = Shader {
            dir: "src/stages/test/shaders",
            name: "broken.wgsl",
            source: "@compute @workgroup_size(64)\nfn main() {\n  let x: f32 = 1u;\n}\n",
        };
        let e = broken.validate().unwrap_err();
        assert!(e.contains("src/stages/test/shaders/broken.wgsl:3:"), "{e}");
    }
}
