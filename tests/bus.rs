//! The daemon on a real zenoh bus (loopback): one test binary for every test
//! that links zenoh, so the release build links (thin LTO) it once. The tests
//! take [`daemon::serial`] and run one at a time: several measure rates and
//! latencies that a browser or a fuzzer beside them would disturb.
//!
//! `cargo test --release --test bus` (one file: `--test bus robustness::`).

mod browser;
#[path = "../crates/lodcloth-core/tests/common/mod.rs"]
mod common;
mod daemon;
mod fuzz;

mod clients;
mod colliders;
mod input;
mod live_error;
mod meshes;
mod operations;
mod robustness;
mod security;
mod service;
mod snapshots;
mod under_input;
