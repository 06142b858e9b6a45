//! The WGSL sources of the GPU passes, one `.wgsl` file per pass under `src/gpu/shaders/`, and their
//! validation by naga (the front end and validator wgpu itself compiles them with).
//!
//! **Input → output.** The shader files (compiled into the binary with `include_str!`) → a parsed
//! and validated naga module, or a diagnostic naming the file, line and column. Every kernel goes
//! through [`Shader::validate`] before wgpu sees it, and a test validates every file, so a typo in a
//! shader fails `cargo test`, not a user's run. Each file's header comment documents its bindings.

use wgpu::naga;

/// One shader file.
#[derive(Debug, Clone, Copy)]
pub struct Shader {
    /// File name under `src/gpu/shaders/`.
    pub name: &'static str,
    /// WGSL source.
    pub source: &'static str,
}

/// POP: one gathering iteration (elek2014 Eqs. 2–6) and the iterate's energy per workgroup.
pub const POP_STEP: Shader = Shader { name: "pop_step.wgsl", source: include_str!("shaders/pop_step.wgsl") };
/// POP: the stopping rule (energy below `ε_L` of the seed), decided on the GPU.
pub const POP_ENERGY: Shader = Shader { name: "pop_energy.wgsl", source: include_str!("shaders/pop_energy.wgsl") };
/// POP: accumulation toward the eye (Eqs. 7–8) and of the collided fluence.
pub const POP_ACCUMULATE: Shader =
    Shader { name: "pop_accumulate.wgsl", source: include_str!("shaders/pop_accumulate.wgsl") };

/// Image fog: one masked 4-tap MIP level of the colour and spread chains (iser2018 Secs. 4.2-4.3).
pub const FOG_DOWNSAMPLE: Shader =
    Shader { name: "fog_downsample.wgsl", source: include_str!("shaders/fog_downsample.wgsl") };
/// Image fog: per-pixel density integrals, `L_at`, `L_sc` and spread into MIP level 0 (Secs. 3.3, 4.1).
pub const FOG_INTEGRALS: Shader =
    Shader { name: "fog_integrals.wgsl", source: include_str!("shaders/fog_integrals.wgsl") };
/// Image fog: per-pixel level selection and B-spline/linear reconstruction (Secs. 4.2-4.3).
pub const FOG_FETCH: Shader = Shader { name: "fog_fetch.wgsl", source: include_str!("shaders/fog_fetch.wgsl") };
/// Image fog: compose L' = L_at + L'_sc (Sec. 4.4).
pub const FOG_COMPOSE: Shader = Shader { name: "fog_compose.wgsl", source: include_str!("shaders/fog_compose.wgsl") };

/// Epipolar god rays: the declarations all `epi_*` passes share (parameters, camera, shadow-map and
/// light functions). Prepended to each pass's source: WGSL has no include.
pub const EPI_COMMON: Shader = Shader { name: "epi_common.wgsl", source: include_str!("shaders/epi_common.wgsl") };
/// Epipolar: depth rectification per slice sample (baran2010 Sec. 3, Sec. 9).
pub const EPI_RECTIFY: Shader = Shader {
    name: "epi_rectify.wgsl",
    source: concat!(include_str!("shaders/epi_common.wgsl"), include_str!("shaders/epi_rectify.wgsl")),
};
/// Epipolar: rectified shadow map, depth modes and light modulation per (slice, γ bin) (Secs. 6–7).
pub const EPI_PREFILTER: Shader = Shader {
    name: "epi_prefilter.wgsl",
    source: concat!(include_str!("shaders/epi_common.wgsl"), include_str!("shaders/epi_prefilter.wgsl")),
};
/// Epipolar: per-lane scale and integer leaves of each slice's integrand (Sec. 6).
pub const EPI_QUANTISE: Shader = Shader {
    name: "epi_quantise.wgsl",
    source: concat!(include_str!("shaders/epi_common.wgsl"), include_str!("shaders/epi_quantise.wgsl")),
};
/// Epipolar: in-scatter per view ray from the partial sums of the visible leaves (Secs. 4–7).
pub const EPI_INTEGRATE: Shader = Shader {
    name: "epi_integrate.wgsl",
    source: concat!(include_str!("shaders/epi_common.wgsl"), include_str!("shaders/epi_integrate.wgsl")),
};
/// Epipolar: unrectification, transmittance and the ray-marched ring (Secs. 3, 6).
pub const EPI_UNRECTIFY: Shader = Shader {
    name: "epi_unrectify.wgsl",
    source: concat!(include_str!("shaders/epi_common.wgsl"), include_str!("shaders/epi_unrectify.wgsl")),
};

/// Every shader, for validation.
pub const ALL: &[Shader] = &[
    POP_STEP,
    POP_ENERGY,
    POP_ACCUMULATE,
    FOG_INTEGRALS,
    FOG_DOWNSAMPLE,
    FOG_FETCH,
    FOG_COMPOSE,
    EPI_COMMON,
    EPI_RECTIFY,
    EPI_PREFILTER,
    EPI_QUANTISE,
    EPI_INTEGRATE,
    EPI_UNRECTIFY,
];

impl Shader {
    /// Parses and validates the source with naga.
    ///
    /// # Errors
    /// The rendered diagnostic (`file:line:column` and the offending source line).
    pub fn validate(&self) -> Result<naga::valid::ModuleInfo, String> {
        let path = format!("src/gpu/shaders/{}", self.name);
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

    #[test]
    fn every_shader_file_is_listed_and_validates() {
        // A file under src/gpu/shaders that ALL forgets would never be validated.
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("src/gpu/shaders");
        let mut files: Vec<String> = std::fs::read_dir(&dir)
            .expect("shader folder")
            .filter_map(|e| e.ok().map(|e| e.file_name().to_string_lossy().into_owned()))
            .filter(|n| n.ends_with(".wgsl"))
            .collect();
        files.sort();
        let mut listed: Vec<String> = ALL.iter().map(|s| s.name.to_string()).collect();
        listed.sort();
        assert_eq!(files, listed);
        for s in ALL {
            if let Err(e) = s.validate() {
                panic!("{e}");
            }
        }
    }

    #[test]
    fn a_broken_shader_is_reported_with_its_file_and_line() {
        let broken = Shader {
            name: "broken.wgsl",
            source: "@compute @workgroup_size(64)\nfn main() {\n  let x: f32 = 1u;\n}\n",
        };
        let e = broken.validate().unwrap_err();
        assert!(e.contains("src/gpu/shaders/broken.wgsl:3:"), "{e}");
    }
}
