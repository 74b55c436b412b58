//! Levels of detail: a grid of `nx × ny` nodes, a surface simulated on `n`
//! of its cloud's points, or a mesh cloth simplified to `n` vertices; how
//! they are written and read in files. Below scenes and plans, so a scene
//! can be built at any level.

use std::fmt;
use std::str::FromStr;

/// A level of detail: a grid cloth of `nx × ny` nodes, written `NXxNY`
/// (e.g. `32x32`); a point-sampled surface simulated on `n` points of its
/// cloud, written `N` or `Npts` (e.g. `300pts`; configs also accept a bare
/// integer for a point count); or a mesh cloth simplified to about `n`
/// vertices, written `Nv` (e.g. `1200v`).
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
    /// A mesh cloth simplified to about this many vertices (within
    /// [`crate::mesh::VERTEX_TOLERANCE`]); the mesh's own count is its reference.
    Vertices(usize),
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
            Level::Points(n) | Level::Vertices(n) => n,
        }
    }

    /// `(nx, ny)` of a grid level.
    pub fn grid(self) -> Option<(usize, usize)> {
        match self {
            Level::Grid { nx, ny } => Some((nx, ny)),
            Level::Points(_) | Level::Vertices(_) => None,
        }
    }
}

impl From<(usize, usize)> for Level {
    /// A grid level `(nx, ny)`.
    fn from((nx, ny): (usize, usize)) -> Level {
        Level::new(nx, ny)
    }
}

impl fmt::Display for Level {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Level::Grid { nx, ny } => write!(f, "{nx}x{ny}"),
            Level::Points(n) => write!(f, "{n}pts"),
            Level::Vertices(n) => write!(f, "{n}v"),
        }
    }
}

impl FromStr for Level {
    type Err = String;

    fn from_str(s: &str) -> Result<Level, String> {
        let bad = || {
            format!(
                "'{s}' is not a level; write NXxNY for a cloth (e.g. 32x32), N for a surface's point count \
                 (e.g. 300) or Nv for a mesh's vertex count (e.g. 1200v)"
            )
        };
        let t = s.trim();
        if let Some((a, b)) = t.split_once(['x', 'X']) {
            let nx = a.trim().parse::<usize>().map_err(|_| bad())?;
            let ny = b.trim().parse::<usize>().map_err(|_| bad())?;
            return Ok(Level::new(nx, ny));
        }
        if let Some(n) = t.strip_suffix("vertices").or_else(|| t.strip_suffix('v')) {
            return n.trim().parse::<usize>().map(Level::Vertices).map_err(|_| bad());
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

/// A level named for any scene, as the experiments take it. On a grid
/// cloth: `N` is N nodes along the cloth's longer side and as many along the
/// other as keep its cells closest to square (so a chain of `N`s keeps the
/// cloth's aspect ratio); `NXxNY` is exactly that grid. On a mesh cloth:
/// `Nv` is N vertices, `P%` is P % of the mesh's vertices.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum GridLevel {
    /// N nodes along the longer side, the cloth's aspect ratio kept.
    Long(usize),
    /// Exactly `nx × ny` nodes.
    Exact {
        /// Nodes along the cloth's width.
        nx: usize,
        /// Nodes along the cloth's height.
        ny: usize,
    },
    /// A mesh cloth simplified to about this many vertices.
    Vertices(usize),
    /// A mesh cloth simplified to this percentage of its vertices (1 to 100).
    Percent(u32),
}

impl GridLevel {
    /// `(nx, ny)` for a cloth of `width × height` (m). For `Long(n)` on a
    /// cloth wider than tall, nx = n and ny = round((n − 1)·height/width) + 1
    /// (at least 2), which makes the cells as square as a grid of n columns
    /// allows; the other way round for a cloth taller than wide.
    ///
    /// # Panics
    /// For a mesh level ([`GridLevel::Vertices`], [`GridLevel::Percent`]);
    /// [`GridLevel::on`] resolves any level on any scene.
    pub fn resolve(self, width: f64, height: f64) -> (usize, usize) {
        match self {
            GridLevel::Exact { nx, ny } => (nx, ny),
            GridLevel::Vertices(_) | GridLevel::Percent(_) => panic!("{self} is a mesh level, not a grid"),
            GridLevel::Long(n) => {
                let other = |long: f64, short: f64| (((n - 1) as f64 * short / long).round() as usize + 1).max(2);
                if width >= height {
                    (n, other(width, height))
                } else {
                    (other(height, width), n)
                }
            }
        }
    }

    /// N of a square level (`N`, or `NxN`): how the paper names its levels.
    pub fn square(self) -> Option<usize> {
        match self {
            GridLevel::Long(n) => Some(n),
            GridLevel::Exact { nx, ny } if nx == ny => Some(nx),
            _ => None,
        }
    }

    /// The level this names on a cloth: a grid of `width × height` m, or
    /// (`mesh_vertices`) a mesh of that many vertices. A grid level on a
    /// mesh, or a mesh level on a grid, is an error naming the right form.
    pub fn on(self, width: f64, height: f64, mesh_vertices: Option<usize>) -> Result<Level, String> {
        match (self, mesh_vertices) {
            (GridLevel::Long(_) | GridLevel::Exact { .. }, None) => Ok(Level::from(self.resolve(width, height))),
            (GridLevel::Vertices(n), Some(_)) => Ok(Level::Vertices(n)),
            (GridLevel::Percent(p), Some(all)) => Ok(Level::Vertices(
                ((all as f64) * f64::from(p) / 100.0).round().max(3.0) as usize,
            )),
            (_, Some(all)) => Err(format!(
                "level {self}: a mesh cloth ({all} vertices) takes Nv (vertices) or P% (of its vertices)"
            )),
            (_, None) => Err(format!(
                "level {self}: a grid cloth takes N (along its longer side) or NXxNY"
            )),
        }
    }
}

impl fmt::Display for GridLevel {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            GridLevel::Long(n) => write!(f, "{n}"),
            GridLevel::Exact { nx, ny } => write!(f, "{nx}x{ny}"),
            GridLevel::Vertices(n) => write!(f, "{n}v"),
            GridLevel::Percent(p) => write!(f, "{p}%"),
        }
    }
}

impl FromStr for GridLevel {
    type Err = String;

    fn from_str(s: &str) -> Result<GridLevel, String> {
        let bad = || {
            format!(
                "'{s}' is not a level; write N (N nodes along the longer side, aspect ratio kept, e.g. 40) or NXxNY (e.g. 40x24), each side at least 2; on a mesh cloth Nv (e.g. 1200v) or P% (e.g. 40%)"
            )
        };
        let side = |t: &str| t.trim().parse::<usize>().ok().filter(|&n| n >= 2);
        let t = s.trim();
        if let Some(p) = t.strip_suffix('%') {
            return p
                .trim()
                .parse::<u32>()
                .ok()
                .filter(|p| (1..=100).contains(p))
                .map(GridLevel::Percent)
                .ok_or_else(|| format!("'{s}' is not a share of a mesh's vertices; write P% with P from 1 to 100"));
        }
        if let Some(n) = t.strip_suffix('v') {
            return n
                .trim()
                .parse::<usize>()
                .ok()
                .filter(|&n| n >= 3)
                .map(GridLevel::Vertices)
                .ok_or_else(|| format!("'{s}' is not a mesh level; write Nv with N ≥ 3 vertices"));
        }
        match t.split_once(['x', 'X']) {
            Some((a, b)) => Ok(GridLevel::Exact {
                nx: side(a).ok_or_else(bad)?,
                ny: side(b).ok_or_else(bad)?,
            }),
            None => side(t).map(GridLevel::Long).ok_or_else(bad),
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
        assert_eq!("1200v".parse::<Level>(), Ok(Level::Vertices(1200)));
        assert_eq!("1200 vertices".parse::<Level>(), Ok(Level::Vertices(1200)));
        assert_eq!(
            Level::Vertices(96).to_string().parse::<Level>(),
            Ok(Level::Vertices(96))
        );
        assert!("v".parse::<Level>().is_err());
    }

    #[test]
    fn grid_levels_parse_print_and_keep_the_aspect_ratio() {
        assert_eq!("40".parse::<GridLevel>(), Ok(GridLevel::Long(40)));
        assert_eq!(" 40X24 ".parse::<GridLevel>(), Ok(GridLevel::Exact { nx: 40, ny: 24 }));
        assert_eq!("1200v".parse::<GridLevel>(), Ok(GridLevel::Vertices(1200)));
        assert_eq!("40%".parse::<GridLevel>(), Ok(GridLevel::Percent(40)));
        assert_eq!(
            GridLevel::Percent(40).on(1.0, 1.0, Some(1000)),
            Ok(Level::Vertices(400))
        );
        assert!(GridLevel::Long(40).on(1.0, 1.0, Some(1000)).is_err());
        assert!(GridLevel::Percent(40).on(1.0, 1.0, None).is_err());
        for bad in ["1", "0x4", "x", "40x", "-3", "4.5", "0%", "101%", "2v"] {
            assert!(bad.parse::<GridLevel>().is_err(), "{bad} parsed");
        }
        for l in [GridLevel::Long(17), GridLevel::Exact { nx: 30, ny: 18 }] {
            assert_eq!(l.to_string().parse::<GridLevel>(), Ok(l));
        }
        // A square cloth: N×N. A 5:3 cloth: 48 columns of 47 cells of 5/47 m,
        // rows of 3/(28) m: the nearest to square; and the transposed cloth.
        assert_eq!(GridLevel::Long(40).resolve(1.0, 1.0), (40, 40));
        assert_eq!(GridLevel::Long(48).resolve(5.0, 3.0), (48, 29));
        assert_eq!(GridLevel::Long(48).resolve(3.0, 5.0), (29, 48));
        assert_eq!(GridLevel::Long(2).resolve(10.0, 1.0), (2, 2));
        assert_eq!(GridLevel::Exact { nx: 40, ny: 24 }.resolve(1.0, 1.0), (40, 24));
        // The cells of Long(n) are within one row of square for any aspect.
        for n in [8, 16, 33, 64] {
            for aspect in [1.0, 1.3, 2.0, 3.0, 5.0 / 3.0] {
                let (nx, ny) = GridLevel::Long(n).resolve(aspect, 1.0);
                let (hx, hy) = (aspect / (nx - 1) as f64, 1.0 / (ny - 1) as f64);
                let rows = 1.0 / hx;
                assert!(
                    ((ny - 1) as f64 - rows).abs() <= 0.5 + 1e-9,
                    "{n} at {aspect}: {nx}x{ny}, cells {hx}×{hy}"
                );
            }
        }
    }
}
