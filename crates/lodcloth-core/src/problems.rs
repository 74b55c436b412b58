//! One way to validate input: every problem found in one pass, each a line
//! `<field path>: <what is wrong>, got <value>`, in the order the fields are
//! checked. Scenes, surface scenes and the daemon's config all report
//! through it, so a user reads one phrasing everywhere.
//!
//! Checks record a problem and carry on with the value as given, so one
//! mistake never hides another.

use std::fmt::Display;

/// Problems found so far, each starting with its field path.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Problems(Vec<String>);

impl Problems {
    /// No problems yet.
    pub fn new() -> Problems {
        Problems::default()
    }

    /// Record a problem worded `<path>: <what is wrong>`.
    pub fn push(&mut self, line: String) {
        self.0.push(line);
    }

    /// `x` must be a finite number.
    pub fn finite(&mut self, path: &str, x: f64) {
        if !x.is_finite() {
            self.push(format!("{path}: must be a finite number, got {x}"));
        }
    }

    /// `x` must be finite and > 0.
    pub fn positive(&mut self, path: &str, x: f64) {
        if !(x.is_finite() && x > 0.0) {
            self.push(format!("{path}: must be positive and finite, got {x}"));
        }
    }

    /// `x` must be finite and ≥ 0.
    pub fn non_negative(&mut self, path: &str, x: f64) {
        if !(x.is_finite() && x >= 0.0) {
            self.push(format!("{path}: must be finite and ≥ 0, got {x}"));
        }
    }

    /// `n` must be at least `min`.
    pub fn at_least<T: PartialOrd + Display>(&mut self, path: &str, n: T, min: T) {
        if n < min {
            self.push(format!("{path}: must be at least {min}, got {n}"));
        }
    }

    /// `x` must lie in `(low, high]` (`low` excluded, for rates and
    /// durations that must be positive); `unit` follows the bounds.
    pub fn in_open_closed(&mut self, path: &str, x: f64, low: f64, high: f64, unit: &str) {
        if !(x > low && x <= high) {
            self.push(format!("{path}: must be in ({low}, {high}] {unit}, got {x}"));
        }
    }

    /// `x` must lie in `[low, high]`; `unit` follows the bounds.
    pub fn in_closed(&mut self, path: &str, x: f64, low: f64, high: f64, unit: &str) {
        if !(x >= low && x <= high) {
            self.push(format!("{path}: must be in [{low}, {high}] {unit}, got {x}"));
        }
    }

    /// A finite `[low, high]` with low ≤ high.
    pub fn interval(&mut self, path: &str, r: [f64; 2]) {
        if !(r[0].is_finite() && r[1].is_finite() && r[0] <= r[1]) {
            self.push(format!("{path}: must be [low, high] with low ≤ high, got {r:?}"));
        }
    }

    /// Whether nothing was found.
    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }

    /// The problems, in the order they were found.
    pub fn into_lines(self) -> Vec<String> {
        self.0
    }

    /// `Ok(())` when nothing was found, else the problems.
    pub fn finish(self) -> Result<(), Vec<String>> {
        if self.0.is_empty() {
            Ok(())
        } else {
            Err(self.0)
        }
    }
}

impl Extend<String> for Problems {
    fn extend<I: IntoIterator<Item = String>>(&mut self, lines: I) {
        self.0.extend(lines);
    }
}
