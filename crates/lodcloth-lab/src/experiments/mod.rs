//! Longer studies built on the core: stability sweeps, the level-of-detail
//! experiments (Table 1, Pareto front, LOD planning, switch continuity) and
//! the generalisation suite. These measure wall-clock time, which the pure
//! modules never do.

pub mod drag;
pub mod generalise;
pub mod lod;
mod stability;

pub use stability::*;
