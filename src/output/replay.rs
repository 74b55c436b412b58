//! The inputs a recording holds — the input log of an `.lct` file or the
//! `/lodcloth/<instance>/inputs` channel of an MCAP file — as a script that
//! replays the session on any level of the scene.

use std::path::Path;

use prost::Message;

use super::{OutputError, TrajectoryReader, TRAJECTORY_MAGIC};
use crate::plan::Level;
use crate::proto::{schema, v1, WireLevel};
use crate::touch::Script;

/// MCAP's file magic.
const MCAP_MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";

/// Every input event a recording holds, in the order recorded: an `.lct`
/// trajectory's input log, or every `lodcloth.v1.InputEvent` message of
/// an MCAP file (uncompressed chunks, as `lodcloth record --mcap` writes).
pub fn recorded_inputs(path: &Path) -> Result<Vec<v1::InputEvent>, OutputError> {
    let p = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|source| OutputError::Io {
        path: p.clone(),
        source,
    })?;
    let bad = |reason: String| OutputError::Inputs {
        path: p.clone(),
        reason,
    };
    if bytes.starts_with(TRAJECTORY_MAGIC) {
        let mut r = TrajectoryReader::open(path)?;
        if !r.header().inputs {
            return Err(bad(
                "the trajectory has no input log (written by `lodcloth simulate`, or by `lodcloth record` \
                 before inputs were recorded)"
                    .into(),
            ));
        }
        return r.inputs();
    }
    if !bytes.starts_with(MCAP_MAGIC) {
        return Err(bad("neither a trajectory (.lct) nor an MCAP file".into()));
    }
    let mut events = Vec::new();
    let stream = mcap::MessageStream::new(&bytes).map_err(|e| bad(format!("MCAP: {e}")))?;
    for m in stream {
        let m = m.map_err(|e| bad(format!("MCAP: {e}")))?;
        if m.channel.schema.as_ref().is_none_or(|s| s.name != schema::INPUT_EVENT) {
            continue;
        }
        let e = v1::InputEvent::decode(m.data.as_ref())
            .map_err(|e| bad(format!("a message on {} is not an InputEvent: {e}", m.channel.topic)))?;
        events.push(e);
    }
    Ok(events)
}

/// One episode's inputs, ready to replay.
#[derive(Debug, Clone)]
pub struct Replay {
    /// The inputs at their simulated times.
    pub script: Script,
    /// The instance they were sent to.
    pub instance: String,
    /// The episode replayed.
    pub episode: u64,
    /// Every episode the recording has inputs of.
    pub episodes: Vec<u64>,
    /// The level the first input was applied at.
    pub level: Option<Level>,
    /// Inputs the daemon applied itself (the idle rule).
    pub idle: usize,
}

impl Replay {
    /// The inputs of `episode` (default: the first recorded) of one
    /// instance; every input checked like a request on the bus, a bad one
    /// refused naming its index and field.
    pub fn of(events: &[v1::InputEvent], episode: Option<u64>, path: &Path) -> Result<Replay, OutputError> {
        let bad = |reason: String| OutputError::Inputs {
            path: path.display().to_string(),
            reason,
        };
        let first = events
            .first()
            .ok_or_else(|| bad("the recording holds no input".into()))?;
        let mut episodes: Vec<u64> = events.iter().map(|e| e.episode).collect();
        episodes.sort_unstable();
        episodes.dedup();
        let episode = episode.unwrap_or(first.episode);
        if !episodes.contains(&episode) {
            return Err(bad(format!(
                "no input of episode {episode}; the recording has {episodes:?}"
            )));
        }
        let instance = first.instance.clone();
        let mut timed = Vec::new();
        let mut level = None;
        let mut idle = 0;
        for (i, e) in events.iter().enumerate() {
            if e.instance != instance {
                return Err(bad(format!(
                    "input {i} is of instance '{}', the first of '{instance}'; record one instance",
                    e.instance
                )));
            }
            if e.episode != episode {
                continue;
            }
            let request = e.input.as_ref().ok_or_else(|| bad(format!("input {i}: no input")))?;
            let input =
                crate::service::request::input(request).map_err(|r| bad(format!("input {i}: {}", r.message)))?;
            if level.is_none() {
                level = e
                    .level
                    .as_ref()
                    .map(Level::from_wire)
                    .transpose()
                    .map_err(|m| bad(format!("input {i}: {m}")))?;
            }
            idle += usize::from(e.idle);
            timed.push((e.time, input));
        }
        let script = Script::new(timed).map_err(|e| bad(e.to_string()))?;
        Ok(Replay {
            script,
            instance,
            episode,
            episodes,
            level,
            idle,
        })
    }
}
