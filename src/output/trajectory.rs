//! The binary trajectory (`.lct`): written frame by frame while a run steps
//! and read back frame by frame.
//!
//! # Trajectory format (`.lct`, version 1, all little-endian)
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 8 | magic `LCTRAJ01` |
//! | 8 | 4 | u32 version = 1 |
//! | 12 | 4 | u32 flags: bit 0 = values are f64 (else f32); bit 1 = velocities stored |
//! | 16 | 4 | u32 nx (0 when the cloth is not a grid) |
//! | 20 | 4 | u32 ny |
//! | 24 | 8 | u64 number of nodes n |
//! | 32 | 8 | f64 dt (s) |
//! | 40 | 4 | u32 steps between frames |
//! | 44 | 4 | u32 reserved (0) |
//! | 48 | 8 | u64 number of frames, written when the file is finished; 0 if the writer stopped early (readers then count whole frames by size) |
//!
//! Then frames of `8 + 8 + 3n·s (+ 3n·s)` bytes: u64 step, f64 time, the
//! positions node by node (x, y, z), and with bit 1 the velocities likewise;
//! `s` is 4 or 8 bytes per value.

use std::fs::File;
use std::io::{BufReader, BufWriter, Read, Seek, SeekFrom, Write};
use std::path::Path;

use super::{io_err, OutputError};
use crate::sim::State;

/// File magic of trajectory files.
pub const TRAJECTORY_MAGIC: &[u8; 8] = b"LCTRAJ01";
const HEADER_LEN: u64 = 56;

/// Value precision in a trajectory file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Precision {
    F32,
    F64,
}

/// Header of a trajectory file.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrajectoryHeader {
    pub precision: Precision,
    pub velocities: bool,
    pub nx: u32,
    pub ny: u32,
    pub n_nodes: u64,
    pub dt: f64,
    pub frame_every: u32,
    /// Frames in the file (counted from its size when the writer stopped early).
    pub n_frames: u64,
}

impl TrajectoryHeader {
    fn value_size(&self) -> u64 {
        match self.precision {
            Precision::F32 => 4,
            Precision::F64 => 8,
        }
    }

    /// Bytes per frame.
    pub fn frame_len(&self) -> u64 {
        let per = 3 * self.n_nodes * self.value_size();
        16 + per * if self.velocities { 2 } else { 1 }
    }
}

/// Streams frames to a trajectory file.
pub struct TrajectoryWriter {
    out: BufWriter<File>,
    header: TrajectoryHeader,
    path: String,
    buf: Vec<u8>,
}

impl TrajectoryWriter {
    /// Create `path` for a cloth of `n_nodes` nodes (`grid` = (nx, ny) when a grid).
    pub fn create(
        path: &Path,
        n_nodes: usize,
        grid: Option<(usize, usize)>,
        dt: f64,
        frame_every: u32,
        precision: Precision,
        velocities: bool,
    ) -> Result<TrajectoryWriter, OutputError> {
        let file = File::create(path).map_err(io_err(path))?;
        let (nx, ny) = grid.unwrap_or((0, 0));
        let header = TrajectoryHeader {
            precision,
            velocities,
            nx: nx as u32,
            ny: ny as u32,
            n_nodes: n_nodes as u64,
            dt,
            frame_every,
            n_frames: 0,
        };
        let mut w = TrajectoryWriter {
            out: BufWriter::new(file),
            header,
            path: path.display().to_string(),
            buf: Vec::with_capacity(header.frame_len() as usize),
        };
        let mut h = Vec::with_capacity(HEADER_LEN as usize);
        h.extend_from_slice(TRAJECTORY_MAGIC);
        h.extend_from_slice(&1u32.to_le_bytes());
        let flags = u32::from(precision == Precision::F64) | (u32::from(velocities) << 1);
        h.extend_from_slice(&flags.to_le_bytes());
        h.extend_from_slice(&header.nx.to_le_bytes());
        h.extend_from_slice(&header.ny.to_le_bytes());
        h.extend_from_slice(&header.n_nodes.to_le_bytes());
        h.extend_from_slice(&dt.to_le_bytes());
        h.extend_from_slice(&frame_every.to_le_bytes());
        h.extend_from_slice(&0u32.to_le_bytes());
        h.extend_from_slice(&0u64.to_le_bytes());
        debug_assert_eq!(h.len() as u64, HEADER_LEN);
        w.out.write_all(&h).map_err(|source| OutputError::Io {
            path: w.path.clone(),
            source,
        })?;
        Ok(w)
    }

    /// Append the state as a frame.
    pub fn write(&mut self, state: &State) -> Result<(), OutputError> {
        let n = state.n_nodes();
        self.buf.clear();
        self.buf.extend_from_slice(&state.step.to_le_bytes());
        self.buf.extend_from_slice(&state.time.to_le_bytes());
        let mut put = |v: &[f64]| {
            for k in 0..n {
                for c in 0..3 {
                    let x = v[c * n + k];
                    match self.header.precision {
                        Precision::F32 => self.buf.extend_from_slice(&(x as f32).to_le_bytes()),
                        Precision::F64 => self.buf.extend_from_slice(&x.to_le_bytes()),
                    }
                }
            }
        };
        put(&state.pos);
        if self.header.velocities {
            put(&state.vel);
        }
        self.out.write_all(&self.buf).map_err(|source| OutputError::Io {
            path: self.path.clone(),
            source,
        })?;
        self.header.n_frames += 1;
        Ok(())
    }

    /// Flush and record the frame count in the header.
    pub fn finish(mut self) -> Result<TrajectoryHeader, OutputError> {
        let path = self.path.clone();
        let e = |source| OutputError::Io {
            path: path.clone(),
            source,
        };
        self.out.flush().map_err(e)?;
        let mut file = self.out.into_inner().map_err(|e2| e(e2.into_error()))?;
        file.seek(SeekFrom::Start(48)).map_err(e)?;
        file.write_all(&self.header.n_frames.to_le_bytes()).map_err(e)?;
        file.sync_all().map_err(e)?;
        Ok(self.header)
    }
}

/// One frame read back: step, time, positions (and velocities) as `[x, y, z]` per node.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    pub step: u64,
    pub time: f64,
    pub positions: Vec<[f64; 3]>,
    pub velocities: Option<Vec<[f64; 3]>>,
}

/// Reads a trajectory file frame by frame.
pub struct TrajectoryReader {
    input: BufReader<File>,
    header: TrajectoryHeader,
    next: u64,
    path: String,
}

impl TrajectoryReader {
    /// Open and check a trajectory file.
    pub fn open(path: &Path) -> Result<TrajectoryReader, OutputError> {
        let file = File::open(path).map_err(io_err(path))?;
        let size = file.metadata().map_err(io_err(path))?.len();
        let mut input = BufReader::new(file);
        let bad = |reason: String| OutputError::Format {
            path: path.display().to_string(),
            reason,
        };
        if size < HEADER_LEN {
            return Err(bad(format!(
                "{size} bytes is shorter than the {HEADER_LEN}-byte header"
            )));
        }
        let mut h = [0u8; HEADER_LEN as usize];
        input.read_exact(&mut h).map_err(io_err(path))?;
        if &h[0..8] != TRAJECTORY_MAGIC {
            return Err(bad("wrong magic bytes".into()));
        }
        let u32_at = |o: usize| u32::from_le_bytes(h[o..o + 4].try_into().expect("4 bytes"));
        let u64_at = |o: usize| u64::from_le_bytes(h[o..o + 8].try_into().expect("8 bytes"));
        let version = u32_at(8);
        if version != 1 {
            return Err(bad(format!("version {version} is not supported (expected 1)")));
        }
        let flags = u32_at(12);
        if flags & !3 != 0 {
            return Err(bad(format!("unknown flags {flags:#x}")));
        }
        let mut header = TrajectoryHeader {
            precision: if flags & 1 != 0 { Precision::F64 } else { Precision::F32 },
            velocities: flags & 2 != 0,
            nx: u32_at(16),
            ny: u32_at(20),
            n_nodes: u64_at(24),
            dt: f64::from_le_bytes(h[32..40].try_into().expect("8 bytes")),
            frame_every: u32_at(40),
            n_frames: u64_at(48),
        };
        if header.n_nodes == 0 || header.n_nodes > 1 << 32 {
            return Err(bad(format!("implausible node count {}", header.n_nodes)));
        }
        if header.nx != 0 && u64::from(header.nx) * u64::from(header.ny) != header.n_nodes {
            return Err(bad(format!(
                "grid {}×{} does not have {} nodes",
                header.nx, header.ny, header.n_nodes
            )));
        }
        let whole = (size - HEADER_LEN) / header.frame_len();
        if header.n_frames == 0 {
            header.n_frames = whole; // the writer stopped early: keep every complete frame
        } else if header.n_frames > whole {
            return Err(bad(format!(
                "header says {} frames, the file holds {whole}",
                header.n_frames
            )));
        }
        Ok(TrajectoryReader {
            input,
            header,
            next: 0,
            path: path.display().to_string(),
        })
    }

    /// The header.
    pub fn header(&self) -> &TrajectoryHeader {
        &self.header
    }

    /// Next frame, or `None` after the last.
    pub fn next_frame(&mut self) -> Result<Option<Frame>, OutputError> {
        if self.next >= self.header.n_frames {
            return Ok(None);
        }
        let mut buf = vec![0u8; self.header.frame_len() as usize];
        self.input.read_exact(&mut buf).map_err(|source| OutputError::Io {
            path: self.path.clone(),
            source,
        })?;
        self.next += 1;
        let n = self.header.n_nodes as usize;
        let s = self.header.value_size() as usize;
        let value = |o: usize| match self.header.precision {
            Precision::F32 => f64::from(f32::from_le_bytes(buf[o..o + 4].try_into().expect("4 bytes"))),
            Precision::F64 => f64::from_le_bytes(buf[o..o + 8].try_into().expect("8 bytes")),
        };
        let block = |start: usize| -> Vec<[f64; 3]> {
            (0..n)
                .map(|k| {
                    let o = start + 3 * k * s;
                    [value(o), value(o + s), value(o + 2 * s)]
                })
                .collect()
        };
        Ok(Some(Frame {
            step: u64::from_le_bytes(buf[0..8].try_into().expect("8 bytes")),
            time: f64::from_le_bytes(buf[8..16].try_into().expect("8 bytes")),
            positions: block(16),
            velocities: self.header.velocities.then(|| block(16 + 3 * n * s)),
        }))
    }
}
