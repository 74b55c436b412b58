//! Levels of detail: a grid of `nx × ny` nodes or a surface simulated on
//! `n` of its cloud's points; how they are written and read in files.

use std::fmt;
use std::str::FromStr;

/// A level of detail: a grid cloth of `nx × ny` nodes, written `NXxNY`
/// (e.g. `32x32`), or a point-sampled surface simulated on `n` points of
/// its cloud, written `N` or `Npts` (e.g. `300pts`). Configs also accept a
/// bare integer for a point count.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Level {
    /// A grid cloth of `nx × ny` nodes.
    Grid {
        /// Nodes along the cloth's width.
        nx: usize,
        /// Nodes along the cloth's height.
        ny: usize,
    },
    /// A point-sampled surface simulated on this many of its cloud's points.
    Points(usize),
}

impl Level {
    /// A grid level.
    pub fn new(nx: usize, ny: usize) -> Level {
        Level::Grid { nx, ny }
    }

    /// Simulated nodes (grid nodes or surface points): the level's cost.
    pub fn nodes(self) -> usize {
        match self {
            Level::Grid { nx, ny } => nx * ny,
            Level::Points(n) => n,
        }
    }

    /// `(nx, ny)` of a grid level.
    pub fn grid(self) -> Option<(usize, usize)> {
        match self {
            Level::Grid { nx, ny } => Some((nx, ny)),
            Level::Points(_) => None,
        }
    }
}

impl fmt::Display for Level {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Level::Grid { nx, ny } => write!(f, "{nx}x{ny}"),
            Level::Points(n) => write!(f, "{n}pts"),
        }
    }
}

impl FromStr for Level {
    type Err = String;

    fn from_str(s: &str) -> Result<Level, String> {
        let bad = || {
            format!("'{s}' is not a level; write NXxNY for a cloth (e.g. 32x32) or N for a surface's point count (e.g. 300)")
        };
        let t = s.trim();
        if let Some((a, b)) = t.split_once(['x', 'X']) {
            let nx = a.trim().parse::<usize>().map_err(|_| bad())?;
            let ny = b.trim().parse::<usize>().map_err(|_| bad())?;
            return Ok(Level::new(nx, ny));
        }
        let digits = t
            .strip_suffix("points")
            .or_else(|| t.strip_suffix("pts"))
            .unwrap_or(t)
            .trim();
        digits.parse::<usize>().map(Level::Points).map_err(|_| bad())
    }
}

impl serde::Serialize for Level {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

impl<'de> serde::Deserialize<'de> for Level {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Level, D::Error> {
        #[derive(serde::Deserialize)]
        #[serde(untagged)]
        enum Raw {
            Count(u64),
            Text(String),
        }
        match Raw::deserialize(d)? {
            Raw::Count(n) => usize::try_from(n)
                .map(Level::Points)
                .map_err(|_| serde::de::Error::custom(format!("{n} points is too many"))),
            Raw::Text(s) => s.parse().map_err(serde::de::Error::custom),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn levels_parse_and_print() {
        assert_eq!("32x24".parse::<Level>(), Ok(Level::new(32, 24)));
        assert_eq!(" 8X8 ".parse::<Level>(), Ok(Level::new(8, 8)));
        assert!("-3x4".parse::<Level>().is_err());
        assert!("x".parse::<Level>().is_err());
        assert!("pts".parse::<Level>().is_err());
        assert_eq!(Level::new(40, 40).to_string(), "40x40");
        assert_eq!("273".parse::<Level>(), Ok(Level::Points(273)));
        assert_eq!("273pts".parse::<Level>(), Ok(Level::Points(273)));
        assert_eq!(Level::Points(85).to_string().parse::<Level>(), Ok(Level::Points(85)));
    }
}
