//! The `lodcloth-lab` commands: one module per study family.

pub mod experiment;
pub mod points_accuracy;
pub mod stability;
