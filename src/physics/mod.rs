//! Physics shared by every table kind and stage: phase functions, random streams, spherical
//! harmonics, the homogeneous medium.
//! One home per concept: no table kind carries its own copy of a phase function.

pub mod hg;
pub mod lobe_transport;
pub mod medium;
pub mod rng;
pub mod sh;
pub mod zh_transport;
