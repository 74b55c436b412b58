//! The lab's tests: the studies' harnesses measure what they say they
//! measure (a drag replayed on every level, the generalisation suite and
//! its chaos floor, a switch mid-run, a recorded session scored by the
//! `lodcloth-lab` binary), and the bending stencil rules the scenes do not
//! use against a plate's energy.
//!
//! `cargo test --release -p lodcloth-lab`.

mod drag;
mod generalise;
// The core's bent-plate fixtures, shared rather than copied.
#[path = "../../lodcloth-core/tests/common/plate.rs"]
mod plate;
mod stencils;
mod switch;
mod touched;
