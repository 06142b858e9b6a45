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
//! - [`pipeline`]: RON language, diagnostics, includes/presets/overrides, validation, schema.
//! - [`tables`]: one module per table kind (`phase_hg`), each with its error estimates.
//! - [`container`]: the `.vtab` format: header, chunks, transforms, zstd, checksums, reader, diff.
//! - [`cache`]: content keys, atomic writes, the locked output folder.
//! - [`compile`]: parallel, incremental compilation with progress and sidecars.
//! - [`stages`]: consumers of tables (`plot_phase`).
//! - [`physics`]: phase functions and counter-based random streams (one home per concept).
//! - [`reference`](mod@reference): independent high-precision references the tables are judged against.
//! - [`report`]: error-against-run-time reports and plots.
//! - [`bench`](mod@bench): timings measured side by side, printed as ratios.
//! - [`stability`]: the extreme-input matrix every formula must survive.
//!
//! Papers: elek2014 (POP; F_hg cumulative), dubouchet2019 (ZH convention) — see
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
pub mod render;
pub mod report;
pub mod scene;
pub mod stability;
pub mod stages;
pub mod tables;
