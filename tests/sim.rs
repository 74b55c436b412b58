//! Tests of the root package that need no bus: the LOD experiments, the
//! point-sampled surfaces through the engine's transfer, and the parsing of
//! every file and config the daemon reads. One test binary, so the release
//! build links (thin LTO) the library once rather than once per file. The
//! core's own tests are in `crates/lodcloth-core/tests/`.
//!
//! `cargo test --release --test sim` (one file: `--test sim points::`).

mod engine;
mod lod;
mod parse_fuzz;
mod points;
mod prepare;
