//! # voltab — a table compiler for rendering participating media
//!
//! Tech artists declare tables in RON pipeline files; voltab compiles them into versioned,
//! compressed, checksummed `.vtab` tables that rendering stages consume. It is shaped like a
//! compiler (read ARCHITECTURE.md first):
//!
//! ```text
//! pipelines/*.ron ──pipeline──▶ ValidatedPipeline ──compile──▶ tables::* generators
//!     (front end: parse,           (IR: resolved defs,           │ arrays + stats
//!      includes, presets,           content keys)                ▼
//!      validation)                                     container (.vtab: chunked, zstd, CRC)
//!                                                                │  cache (content-addressed,
//!                                                                ▼   atomic, locked)
//!                                                     stages::* consumers (load only the
//!                                                      slices they need)
//! ```
//!
//! Module map:
//! - [`pipeline`]: RON language, diagnostics, includes/presets/overrides, validation, schema; generic
//!   over the stage kinds ([`pipeline::StageKinds`]), so it imports no stage.
//! - [`registry`]: the front end bound to the stage kinds ([`registry::ValidatedPipeline`],
//!   [`registry::load_and_validate`], the schema pages) and every kind's stability rows.
//! - [`tables`]: one module per table kind (`phase_hg`, `zh_response`, `ms_lobes`, `pop_preset`), each
//!   implementing [`tables::TableKind`] with its error estimates.
//! - [`container`]: the `.vtab` format: header, chunks, transforms, zstd, checksums, reader, diff.
//! - [`cache`]: content keys, atomic writes, the locked output folder.
//! - [`compile`]: parallel, incremental compilation with progress and sidecars.
//! - [`plan`]: (pipeline, scenes) → the tables and slices the scenes need.
//! - [`shard`]: scale-out: a compile split into work units and a lightmap bake into texel tiles over
//!   N shards (Slurm job arrays), and the merges that write the bytes one machine writes.
//! - [`stages`]: consumers of tables, one folder per technique (`bake`, `god_rays`, `image_fog`,
//!   `pop`, `translucent`, plus `plot_phase`): the stage ([`stages::Stage`]), its algorithm, its GPU
//!   twin and shaders.
//! - [`render`]: the floor under the techniques: images, camera, G-buffer, luminance, optics, GPU context.
//! - [`scene`]: glTF/USD import into one scene model, checks, BVH ray queries.
//! - [`image_io`]: EXR and PNG output.
//! - [`physics`]: phase functions, counter-based random streams, spherical harmonics, the homogeneous
//!   medium and the ZH and lobe transport generators (one home per concept).
//! - [`reference`](mod@reference): independent high-precision references the tables are judged against.
//! - [`report`]: error-against-run-time reports and plots.
//! - [`validation`]: `voltab validate`, every stage against Mitsuba 3 (the independent reference).
//! - [`bench`](mod@bench): timings measured side by side, printed as ratios.
//! - [`stability`]: the extreme-input matrix every formula must survive.
//!
//! Papers: dubouchet2019 (ZH tables, bake), wang2018 (lobe tables, translucent), elek2014 (POP),
//! baran2010 (god rays), iser2018 (image fog) — see
//! `../shared/papers/` and each module's header for the equations it implements.

pub mod bench;
pub mod cache;
pub mod compile;
pub mod container;
pub mod image_io;
pub mod physics;
pub mod pipeline;
pub mod plan;
pub mod reference;
pub mod registry;
pub mod render;
pub mod report;
pub mod scene;
pub mod shard;
pub mod stability;
pub mod stages;
pub mod tables;
pub mod validation;
