//! Independent reference evaluations that tables and stages are judged against: different
//! arithmetic (double-double) and different formulas (closed forms, quadrature) from the
//! production code in `physics`, and an analog random walk (`walk`) that shares no code with any
//! table generator.

pub mod beam_adjoint;
pub mod frame;
pub mod grid_mc;
pub mod hg_hp;
pub mod mitsuba;
pub mod quadrature;
pub mod translucent;
/// Brute-force volumetric path tracer: surface irradiance with volume-to-surface transport.
pub mod volpath;
pub mod walk;
