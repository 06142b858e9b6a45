//! Independent reference evaluations that tables and stages are judged against: different
//! arithmetic (double-double) and different formulas (closed forms, quadrature) from the
//! production code in `physics`.

pub mod hg_hp;
