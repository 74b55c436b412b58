//! Longer studies built on the core: stability sweeps, and the level-of-detail
//! experiments (Table 1, Pareto front, LOD planning, switch continuity). These
//! measure wall-clock time, which the pure modules never do.

pub mod lod;
mod stability;

pub use stability::*;
