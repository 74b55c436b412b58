//! Live input from the page: the WebSocket ops `grab`, `move`, `release`
//! and `release_all` checked and turned into `InputRequest`s, the queue
//! that sends one input at a time per page (a waiting move replaced by a
//! newer one of the same grab), and the replies the page shows.

use std::collections::{BTreeSet, VecDeque};

use crate::proto::v1;
use crate::service::client::ClientError;
use crate::touch::{Input, Patch};

use super::level_text;

/// Spring constant of a grab from the page that names none (N/m), as
/// `lodcloth input grab`.
pub const DEFAULT_STIFFNESS: f64 = 20.0;

/// Damping of a grab from the page that names none (N·s/m), as `lodcloth
/// input grab`.
pub const DEFAULT_DAMPING: f64 = 0.2;

/// The fields of a command besides `op`.
pub type Fields = serde_json::Map<String, serde_json::Value>;

/// `op.name`, as an error names it.
fn field_name(op: &str, name: &str) -> String {
    format!("{op}.{name}")
}

/// A number field; `None` when absent (null is not absent: it is refused).
fn number(op: &str, fields: &Fields, name: &str) -> Result<Option<f64>, String> {
    match fields.get(name) {
        None => Ok(None),
        Some(x) => x
            .as_f64()
            .map(Some)
            .ok_or_else(|| format!("{}: expected a number, got {x}", field_name(op, name))),
    }
}

fn required(op: &str, fields: &Fields, name: &str) -> Result<f64, String> {
    number(op, fields, name)?.ok_or_else(|| format!("{}: missing (a number)", field_name(op, name)))
}

fn grab_id(op: &str, fields: &Fields) -> Result<u32, String> {
    let x = fields
        .get("id")
        .ok_or_else(|| format!("{}: missing (the grab's id, a whole number)", field_name(op, "id")))?;
    x.as_u64().and_then(|n| u32::try_from(n).ok()).ok_or_else(|| {
        format!(
            "{}: expected a whole number within [0, {}], got {x}",
            field_name(op, "id"),
            u32::MAX
        )
    })
}

/// A point `[x, y, z]` (m); `None` when absent.
fn point(op: &str, fields: &Fields, name: &str) -> Result<Option<[f64; 3]>, String> {
    let Some(x) = fields.get(name) else {
        return Ok(None);
    };
    let bad = || format!("{}: expected [x, y, z] in metres, got {x}", field_name(op, name));
    let a = x.as_array().filter(|a| a.len() == 3).ok_or_else(bad)?;
    let mut p = [0.0; 3];
    for (slot, v) in p.iter_mut().zip(a) {
        *slot = v.as_f64().ok_or_else(bad)?;
    }
    Ok(Some(p))
}

/// The input request a page's input op (`grab`, `move`, `release`,
/// `release_all`) asks for, or why it cannot be sent: an unknown or
/// missing field, a value of the wrong type, or one out of range (the
/// daemon's own check, [`Input::check`], so the reason reads as the
/// daemon's would). Defaults: [`DEFAULT_STIFFNESS`], [`DEFAULT_DAMPING`].
pub fn input_request(op: &str, fields: &Fields) -> Result<v1::InputRequest, String> {
    let known: &[&str] = match op {
        "grab" => &["id", "u", "v", "radius", "target", "stiffness", "damping"],
        "move" => &["id", "target"],
        "release" => &["id"],
        "release_all" => &[],
        _ => return Err(format!("'{op}' is not an input op (grab, move, release, release_all)")),
    };
    if let Some(unknown) = fields.keys().find(|k| !known.contains(&k.as_str())) {
        return Err(format!("{op}: unknown field '{unknown}' (known: {})", known.join(", ")));
    }
    let input = match op {
        "grab" => Input::Grab {
            id: grab_id(op, fields)?,
            at: Patch {
                u: required(op, fields, "u")?,
                v: required(op, fields, "v")?,
                radius: required(op, fields, "radius")?,
            },
            target: point(op, fields, "target")?,
            stiffness: number(op, fields, "stiffness")?.unwrap_or(DEFAULT_STIFFNESS),
            damping: number(op, fields, "damping")?.unwrap_or(DEFAULT_DAMPING),
        },
        "move" => Input::Move {
            id: grab_id(op, fields)?,
            target: point(op, fields, "target")?
                .ok_or_else(|| format!("{}: missing ([x, y, z] in metres)", field_name(op, "target")))?,
        },
        "release" => Input::Release {
            id: grab_id(op, fields)?,
        },
        _ => Input::ReleaseAll,
    };
    input.check().map_err(|e| e.to_string())?;
    Ok(crate::proto::input_request(&input))
}

/// One input of a connection, to send.
#[derive(Debug, Clone, PartialEq)]
pub struct Queued {
    pub instance: String,
    /// The page's op (`grab`, `move`, …) and grab id, echoed in the reply.
    pub op: String,
    pub id: Option<u32>,
    pub request: v1::InputRequest,
    /// Earlier moves of the same grab this one replaced before they were
    /// sent.
    pub replaced: u64,
}

impl Queued {
    fn is_move_of(&self, instance: &str, id: Option<u32>) -> bool {
        self.op == "move" && self.instance == instance && self.id == id
    }
}

/// The inputs of one connection, sent one at a time in arrival order (the
/// daemon applies them in the order they arrive, and a move must not
/// overtake its grab). Grabs and releases are never dropped; a move waiting
/// behind the one in flight is replaced by a newer move of the same grab
/// (latest wins), as states are for a slow page, so a slow bus never builds
/// a backlog of stale targets.
#[derive(Debug, Default)]
pub struct InputQueue {
    waiting: VecDeque<Queued>,
    in_flight: bool,
    /// Moves replaced before they were sent (since the connection opened).
    pub replaced: u64,
}

impl InputQueue {
    /// Queue an input (a move may replace the move waiting last).
    pub fn push(&mut self, mut q: Queued) {
        if q.op == "move" {
            if let Some(last) = self.waiting.back_mut().filter(|l| l.is_move_of(&q.instance, q.id)) {
                q.replaced = last.replaced + 1;
                self.replaced += 1;
                *last = q;
                return;
            }
        }
        self.waiting.push_back(q);
    }

    /// The next input to send, when none is in flight (it is then).
    pub fn take_next(&mut self) -> Option<Queued> {
        if self.in_flight {
            return None;
        }
        let q = self.waiting.pop_front()?;
        self.in_flight = true;
        Some(q)
    }

    /// The input in flight was answered.
    pub fn done(&mut self) {
        self.in_flight = false;
    }

    /// Inputs waiting (not the one in flight).
    pub fn waiting(&self) -> usize {
        self.waiting.len()
    }
}

/// The grabs a connection holds, by instance and id, as far as its inputs
/// go: released when the connection closes.
pub(super) fn track_hold(held: &mut BTreeSet<(String, u32)>, q: &Queued) {
    match (q.op.as_str(), q.id) {
        ("grab", Some(id)) => {
            held.insert((q.instance.clone(), id));
        }
        ("release", Some(id)) => {
            held.remove(&(q.instance.clone(), id));
        }
        ("release_all", _) => held.retain(|(i, _)| *i != q.instance),
        _ => {}
    }
}

/// The reply to an input, as the page shows it. An error is (code,
/// message): the daemon's code (`CODE_UNSTABLE`, …) or
/// `CODE_BAD_REQUEST` for an op the viewer could not read.
pub fn input_reply(
    op: &str,
    id: Option<u32>,
    replaced: u64,
    result: Result<v1::InputReply, (String, String)>,
) -> serde_json::Value {
    match result {
        Ok(r) => {
            let level = level_text(&r.level);
            let what = id.map_or_else(|| op.replace('_', " "), |id| format!("{op} {id}"));
            serde_json::json!({
                "type": "input", "op": op, "id": id, "ok": true, "frame": r.frame, "time": r.time,
                "grabs": r.grabs, "level": level, "replaced": replaced,
                "message": format!(
                    "{what} applied after step {} (t = {:.3} s) at {level}; grabs held: {:?}",
                    r.frame, r.time, r.grabs
                ),
            })
        }
        Err((code, message)) => serde_json::json!({
            "type": "input", "op": op, "id": id, "ok": false, "code": code, "message": message,
            "replaced": replaced,
        }),
    }
}

/// A client error as an input reply's (code, message).
pub(super) fn input_error(e: ClientError) -> (String, String) {
    match e {
        ClientError::Refused { code, message } => (code, message),
        other => ("CODE_UNAVAILABLE".into(), other.to_string()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plan::Level;
    use crate::proto::WireLevel;
    use crate::view::tests::request;

    #[test]
    fn page_inputs_become_input_requests_with_the_cli_defaults() {
        use v1::input_request::Action;
        let r = request(r#"{"op":"grab","id":7,"u":0.5,"v":0.8,"radius":0.05}"#).unwrap();
        let Some(Action::Grab(g)) = r.action else {
            panic!("a grab")
        };
        assert_eq!((g.id, g.stiffness, g.damping), (7, DEFAULT_STIFFNESS, DEFAULT_DAMPING));
        let at = g.at.unwrap();
        assert_eq!((at.u, at.v, at.radius), (0.5, 0.8, 0.05));
        assert_eq!(g.target, None, "no target: where the patch is now");
        let r =
            request(r#"{"op":"grab","id":1,"u":0,"v":1,"radius":0,"target":[1,-2,3.5],"stiffness":50,"damping":0}"#)
                .unwrap();
        let Some(Action::Grab(g)) = r.action else {
            panic!("a grab")
        };
        let t = g.target.unwrap();
        assert_eq!(([t.x, t.y, t.z], g.stiffness, g.damping), ([1.0, -2.0, 3.5], 50.0, 0.0));
        let r = request(r#"{"op":"move","id":7,"target":[0.1,0.2,0.3]}"#).unwrap();
        assert!(matches!(r.action, Some(Action::Move(m)) if m.id == 7 && m.target.unwrap().z == 0.3));
        let r = request(r#"{"op":"release","id":7}"#).unwrap();
        assert!(matches!(r.action, Some(Action::Release(m)) if m.id == 7));
        let r = request(r#"{"op":"release_all"}"#).unwrap();
        assert!(matches!(r.action, Some(Action::ReleaseAll(_))));
    }

    #[test]
    fn a_bad_page_input_is_refused_naming_the_field() {
        for (text, needle) in [
            (r#"{"op":"grab","id":7,"v":0.8,"radius":0.05}"#, "grab.u: missing"),
            (
                r#"{"op":"grab","id":7,"u":"left","v":0.8,"radius":0.05}"#,
                "grab.u: expected a number",
            ),
            (
                r#"{"op":"grab","id":7,"u":0.5,"v":0.8,"radius":null}"#,
                "grab.radius: expected a number, got null",
            ),
            (r#"{"op":"grab","u":0.5,"v":0.8,"radius":0.05}"#, "grab.id: missing"),
            (
                r#"{"op":"grab","id":-1,"u":0.5,"v":0.8,"radius":0.05}"#,
                "grab.id: expected a whole number",
            ),
            (
                r#"{"op":"grab","id":4294967296,"u":0.5,"v":0.8,"radius":0.05}"#,
                "grab.id",
            ),
            (
                r#"{"op":"grab","id":7,"u":1.5,"v":0.8,"radius":0.05}"#,
                "grab.at.u = 1.5",
            ),
            (
                r#"{"op":"grab","id":7,"u":0.5,"v":0.8,"radius":0.05,"stiffness":0}"#,
                "grab.stiffness",
            ),
            (
                r#"{"op":"grab","id":7,"u":0.5,"v":0.8,"radius":0.05,"damping":-1}"#,
                "grab.damping",
            ),
            (
                r#"{"op":"grab","id":7,"u":0.5,"v":0.8,"radius":0.05,"stifness":5}"#,
                "unknown field 'stifness'",
            ),
            (
                r#"{"op":"grab","id":7,"u":0.5,"v":0.8,"radius":0.05,"target":[1,2]}"#,
                "grab.target: expected [x, y, z]",
            ),
            (r#"{"op":"move","id":7}"#, "move.target: missing"),
            (
                r#"{"op":"move","id":7,"target":[0,"a",0]}"#,
                "move.target: expected [x, y, z]",
            ),
            (r#"{"op":"move","id":7,"target":[0,1e9,0]}"#, "move.target.y"),
            (r#"{"op":"release"}"#, "release.id: missing"),
            (r#"{"op":"release_all","id":3}"#, "unknown field 'id'"),
        ] {
            let e = request(text).unwrap_err();
            assert!(e.contains(needle), "{text}: '{e}' does not name {needle}");
        }
        assert!(input_request("poke", &Fields::new()).is_err());
    }

    fn queued(op: &str, id: Option<u32>) -> Queued {
        Queued {
            instance: "a".into(),
            op: op.into(),
            id,
            request: v1::InputRequest::default(),
            replaced: 0,
        }
    }

    #[test]
    fn one_input_is_in_flight_and_a_waiting_move_is_replaced_by_the_latest() {
        let mut q = InputQueue::default();
        q.push(queued("grab", Some(7)));
        let first = q.take_next().expect("the grab goes at once");
        assert_eq!(first.op, "grab");
        // While the grab is in flight the moves wait, and only the latest
        // is kept.
        for _ in 0..5 {
            q.push(queued("move", Some(7)));
        }
        assert_eq!(q.take_next(), None, "one input in flight at a time");
        assert_eq!((q.waiting(), q.replaced), (1, 4));
        q.done();
        let m = q.take_next().expect("the move");
        assert_eq!((m.op.as_str(), m.replaced), ("move", 4));
        // A release is never dropped, and a move after it is not merged
        // into a move before it.
        q.push(queued("move", Some(7)));
        q.push(queued("release", Some(7)));
        q.push(queued("move", Some(7)));
        assert_eq!(q.waiting(), 3);
        q.done();
        let order: Vec<String> = std::iter::from_fn(|| {
            let n = q.take_next();
            q.done();
            n.map(|n| n.op)
        })
        .collect();
        assert_eq!(order, ["move", "release", "move"]);
        // Moves of different grabs are both kept.
        q.push(queued("move", Some(1)));
        q.push(queued("move", Some(2)));
        assert_eq!(q.waiting(), 2);
    }

    #[test]
    fn held_grabs_follow_the_inputs_sent() {
        let mut held = BTreeSet::new();
        track_hold(&mut held, &queued("grab", Some(7)));
        track_hold(&mut held, &queued("grab", Some(8)));
        track_hold(&mut held, &queued("move", Some(7)));
        track_hold(&mut held, &queued("release", Some(7)));
        assert_eq!(held.iter().map(|(_, id)| *id).collect::<Vec<_>>(), [8]);
        track_hold(&mut held, &queued("release_all", None));
        assert!(held.is_empty());
    }

    #[test]
    fn an_input_reply_carries_the_frame_and_grabs_or_the_code_and_reason() {
        let ok = input_reply(
            "grab",
            Some(7),
            0,
            Ok(v1::InputReply {
                instance: "a".into(),
                frame: 1234,
                time: 2.5,
                grabs: vec![7],
                level: Some(Level::new(16, 16).to_wire()),
            }),
        );
        assert_eq!(
            (ok["ok"].clone(), ok["frame"].clone()),
            (serde_json::json!(true), serde_json::json!(1234))
        );
        assert_eq!(ok["grabs"], serde_json::json!([7]));
        assert_eq!(ok["level"], "16x16");
        assert!(ok["message"].as_str().unwrap().contains("grab 7"));
        let refused = input_reply(
            "grab",
            Some(7),
            0,
            Err(input_error(ClientError::Refused {
                code: "CODE_UNSTABLE".into(),
                message: "stiffness = 1e9 N/m: unstable; stable up to 312 N/m".into(),
            })),
        );
        assert_eq!(refused["ok"], false);
        assert_eq!(refused["code"], "CODE_UNSTABLE");
        assert!(refused["message"].as_str().unwrap().contains("stable up to"));
        let lost = input_reply(
            "move",
            Some(7),
            2,
            Err(input_error(ClientError::Zenoh("closed".into()))),
        );
        assert_eq!(
            (lost["code"].clone(), lost["replaced"].clone()),
            ("CODE_UNAVAILABLE".into(), 2.into())
        );
    }
}
