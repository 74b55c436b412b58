//! The binary trajectory (`.lct`): written frame by frame while a run steps
//! and read back frame by frame.
//!
//! # Trajectory format (`.lct`, version 1, all little-endian)
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 8 | magic `LCTRAJ01` |
//! | 8 | 4 | u32 version = 1 |
//! | 12 | 4 | u32 flags: bit 0 = values are f64 (else f32); bit 1 = velocities stored; bit 2 = an input log follows the frames |
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
//!
//! With flag bit 2 (set, with the frame count, when the writer finished),
//! the inputs that acted on the cloth while it was recorded follow the
//! last frame: magic `LCINPUT1`, u64 count, then per input a u32 length
//! and a `lodcloth.v1.InputEvent` (protobuf, as published on
//! `<prefix>/<instance>/inputs`). `lodcloth simulate --inputs` replays them.

use std::fs::File;
use std::io::{BufReader, BufWriter, Read, Seek, SeekFrom, Write};
use std::path::Path;

use prost::Message;

use super::{io_err, OutputError};
use crate::proto::v1;
use crate::sim::State;

/// File magic of trajectory files.
pub const TRAJECTORY_MAGIC: &[u8; 8] = b"LCTRAJ01";
const HEADER_LEN: u64 = 56;
/// Magic of the input log after the frames.
pub const INPUT_LOG_MAGIC: &[u8; 8] = b"LCINPUT1";
/// Flag bit: an input log follows the frames.
const FLAG_INPUTS: u32 = 4;

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
    /// An input log follows the frames.
    pub inputs: bool,
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
            inputs: false,
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
    pub fn finish(self) -> Result<TrajectoryHeader, OutputError> {
        self.finish_with_inputs(None)
    }

    /// Append the inputs that acted on the cloth as the input log, then
    /// finish: a replayable recording (`lodcloth simulate --inputs`).
    pub fn finish_with_inputs(self, inputs: Option<&[v1::InputEvent]>) -> Result<TrajectoryHeader, OutputError> {
        let mut header = self.header;
        let path = self.path.clone();
        let e = |source| OutputError::Io {
            path: path.clone(),
            source,
        };
        let mut out = self.out;
        if let Some(inputs) = inputs {
            out.write_all(INPUT_LOG_MAGIC).map_err(e)?;
            out.write_all(&(inputs.len() as u64).to_le_bytes()).map_err(e)?;
            for event in inputs {
                let bytes = event.encode_to_vec();
                out.write_all(&(bytes.len() as u32).to_le_bytes()).map_err(e)?;
                out.write_all(&bytes).map_err(e)?;
            }
            header.inputs = true;
        }
        out.flush().map_err(e)?;
        let mut file = out.into_inner().map_err(|e2| e(e2.into_error()))?;
        // The flag and the count last: a file cut short before here reads
        // as frames only.
        let flags = u32::from(header.precision == Precision::F64)
            | (u32::from(header.velocities) << 1)
            | if header.inputs { FLAG_INPUTS } else { 0 };
        file.seek(SeekFrom::Start(12)).map_err(e)?;
        file.write_all(&flags.to_le_bytes()).map_err(e)?;
        file.seek(SeekFrom::Start(48)).map_err(e)?;
        file.write_all(&header.n_frames.to_le_bytes()).map_err(e)?;
        file.sync_all().map_err(e)?;
        Ok(header)
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
    size: u64,
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
        if flags & !7 != 0 {
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
            inputs: flags & FLAG_INPUTS != 0,
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
        if header.inputs && header.n_frames == 0 {
            return Err(bad("an input log is flagged but the frame count is 0".into()));
        }
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
            size,
        })
    }

    /// The input log (empty when the file has none); the frame reading
    /// starts over afterwards.
    pub fn inputs(&mut self) -> Result<Vec<v1::InputEvent>, OutputError> {
        if !self.header.inputs {
            return Ok(Vec::new());
        }
        let path = self.path.clone();
        let io = |source| OutputError::Io {
            path: path.clone(),
            source,
        };
        let bad = |reason: String| OutputError::Inputs {
            path: path.clone(),
            reason,
        };
        let start = HEADER_LEN + self.header.n_frames * self.header.frame_len();
        self.input.seek(SeekFrom::Start(start)).map_err(io)?;
        let mut left = self.size.saturating_sub(start);
        let mut head = [0u8; 16];
        if left < 16 {
            return Err(bad(format!("the input log at byte {start} is cut short")));
        }
        self.input.read_exact(&mut head).map_err(io)?;
        left -= 16;
        if &head[0..8] != INPUT_LOG_MAGIC {
            return Err(bad(format!("no input log at byte {start} (wrong magic)")));
        }
        let count = u64::from_le_bytes(head[8..16].try_into().expect("8 bytes"));
        if count > left / 4 {
            return Err(bad(format!("the input log claims {count} inputs in {left} bytes")));
        }
        let mut events = Vec::with_capacity(count as usize);
        for i in 0..count {
            let mut len = [0u8; 4];
            if left < 4 {
                return Err(bad(format!("input {i} of {count} is cut short")));
            }
            self.input.read_exact(&mut len).map_err(io)?;
            let len = u64::from(u32::from_le_bytes(len));
            left -= 4;
            if len > left {
                return Err(bad(format!("input {i} of {count} claims {len} bytes, {left} are left")));
            }
            let mut buf = vec![0u8; len as usize];
            self.input.read_exact(&mut buf).map_err(io)?;
            left -= len;
            let event = v1::InputEvent::decode(buf.as_slice())
                .map_err(|e| bad(format!("input {i} of {count} is not an InputEvent: {e}")))?;
            events.push(event);
        }
        self.input.seek(SeekFrom::Start(HEADER_LEN)).map_err(io)?;
        self.next = 0;
        Ok(events)
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::touch::{Input, Patch};

    fn state(step: u64, n: usize) -> State {
        let pos: Vec<f64> = (0..3 * n).map(|i| i as f64 * 0.25 + step as f64).collect();
        State {
            vel: pos.iter().map(|x| -x).collect(),
            pos,
            time: step as f64 * 0.01,
            step,
        }
    }

    fn event(frame: u64, input: Input) -> v1::InputEvent {
        v1::InputEvent {
            instance: "a".into(),
            frame,
            time: frame as f64 * 0.01,
            episode: 2,
            level: Some(v1::Level {
                nx: 2,
                ny: 2,
                ..Default::default()
            }),
            input: Some(crate::proto::input_request(&input)),
            idle: frame == 9,
            seq: frame,
        }
    }

    fn write(path: &Path, inputs: Option<&[v1::InputEvent]>) {
        let mut w = TrajectoryWriter::create(path, 4, Some((2, 2)), 0.01, 1, Precision::F64, true).unwrap();
        for step in 0..5 {
            w.write(&state(step, 4)).unwrap();
        }
        w.finish_with_inputs(inputs).unwrap();
    }

    #[test]
    fn frames_and_the_input_log_read_back_as_written() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.lct");
        let inputs = vec![
            event(
                3,
                Input::Grab {
                    id: 1,
                    at: Patch {
                        u: 0.5,
                        v: 0.5,
                        radius: 0.0,
                    },
                    target: None,
                    stiffness: 5.0,
                    damping: 0.1,
                },
            ),
            event(9, Input::ReleaseAll),
        ];
        write(&path, Some(&inputs));
        let mut r = TrajectoryReader::open(&path).unwrap();
        assert!(r.header().inputs);
        assert_eq!(r.header().n_frames, 5);
        assert_eq!(r.inputs().unwrap(), inputs);
        // Frames read from the start after the log, every value exact (f64).
        for step in 0..5 {
            let f = r.next_frame().unwrap().unwrap();
            let s = state(step, 4);
            assert_eq!(f.step, step);
            assert_eq!(f.positions[3], [s.pos[3], s.pos[7], s.pos[11]]);
            assert_eq!(f.velocities.unwrap()[1], [s.vel[1], s.vel[5], s.vel[9]]);
        }
        assert!(r.next_frame().unwrap().is_none());

        // Without inputs: no flag, an empty log.
        write(&path, None);
        let mut r = TrajectoryReader::open(&path).unwrap();
        assert!(!r.header().inputs);
        assert!(r.inputs().unwrap().is_empty());
    }

    #[test]
    fn a_damaged_input_log_is_refused_by_what_is_wrong() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.lct");
        let inputs = vec![event(3, Input::ReleaseAll); 3];
        write(&path, Some(&inputs));
        let whole = std::fs::read(&path).unwrap();
        let frames_end = (HEADER_LEN + 5 * TrajectoryReader::open(&path).unwrap().header().frame_len()) as usize;
        let check = |bytes: &[u8], expect: &str| {
            std::fs::write(&path, bytes).unwrap();
            let e = TrajectoryReader::open(&path).and_then(|mut r| r.inputs()).unwrap_err();
            assert!(e.to_string().contains(expect), "{e}");
        };
        // Cut inside the last input, inside the count, and a wrong magic.
        check(&whole[..whole.len() - 2], "input 2 of 3 claims");
        check(&whole[..frames_end + 10], "cut short");
        let mut wrong = whole.clone();
        wrong[frames_end] = b'X';
        check(&wrong, "wrong magic");
        let mut huge = whole.clone();
        huge[frames_end + 8..frames_end + 16].copy_from_slice(&u64::MAX.to_le_bytes());
        check(&huge, "claims 18446744073709551615 inputs");
    }
}
