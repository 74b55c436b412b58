//! The lab's tests: the studies' harnesses measure what they say they
//! measure (a drag replayed on every level, the generalisation suite and
//! its chaos floor, a switch mid-run, a recorded session scored by the
//! `lodcloth-lab` binary).
//!
//! `cargo test --release -p lodcloth-lab`.

mod drag;
mod generalise;
mod switch;
mod touched;
