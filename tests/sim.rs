//! Simulation, estimation, point-sampled surfaces and parsing: one test
//! binary, so the release build links (thin LTO) the library once rather
//! than once per file.
//!
//! `cargo test --release --test sim` (one file: `--test sim energy::`).

mod common;

mod cache;
mod conservation;
mod convergence;
mod energy;
mod equilibrium;
mod estimation;
mod kernel;
mod lod;
mod oscillator;
mod parse_fuzz;
mod points;
mod scenes;
mod stability;
mod strain_control;
mod symmetry_determinism;
