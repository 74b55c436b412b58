//! Checking a request before anything acts on it: the key names one known
//! instance, the payload is small, protobuf and well-formed, and every field
//! is in range for that instance. Pure (no zenoh, no I/O) so that it can be
//! fuzzed by the million; the daemon answers every [`Refusal`] with an
//! `Error` reply carrying its code and message.

use prost::Message;

use super::keys;
use crate::estimate::{Method, Served};
use crate::names;
use crate::plan::InstancePlan;
use crate::plan::Level;
use crate::proto::{v1, WireLevel};
use crate::touch::{Input, Patch};
use v1::error::Code;

/// Largest request payload accepted (bytes). A `SwitchRequest` or
/// `ControlRequest` is under 40 bytes; anything near this is not one.
pub const MAX_REQUEST_BYTES: usize = 64 * 1024;

/// Why a request is refused: the reply's code and a message naming the
/// problem.
#[derive(Debug, Clone, PartialEq)]
pub struct Refusal {
    pub code: Code,
    pub message: String,
}

impl Refusal {
    pub fn new(code: Code, message: impl Into<String>) -> Refusal {
        Refusal {
            code,
            message: message.into(),
        }
    }

    fn bad(message: impl Into<String>) -> Refusal {
        Refusal::new(Code::BadRequest, message)
    }
}

/// Where a switch goes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SwitchTarget {
    /// This allowed level.
    Level(Level),
    /// The cheapest allowed level with a predicted error at most this.
    MaxError(f64),
}

/// A checked switch request.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SwitchPlan {
    pub target: SwitchTarget,
    pub method: Method,
    /// Go live at once with the scene's coefficients when the level is not
    /// prepared (level targets only).
    pub at_once: bool,
}

/// The one instance `key` (`<prefix>/<instance>/<leaf>`) names, if `known`.
/// `names` lists the instances for the message when it is not.
pub fn instance_name<'k>(
    prefix: &str,
    leaf: &str,
    key: &'k str,
    known: impl Fn(&str) -> bool,
    names: impl Fn() -> String,
) -> Result<&'k str, Refusal> {
    let Some(name) = keys::instance_of(prefix, leaf, key) else {
        return Err(Refusal::bad(format!(
            "key '{key}' names no single instance; send to {prefix}/<instance>/{leaf}"
        )));
    };
    if known(name) {
        Ok(name)
    } else {
        Err(Refusal::new(
            Code::UnknownInstance,
            format!("no instance '{name}' on this daemon; it runs {}", names()),
        ))
    }
}

/// Decode a `schema` payload, or say exactly what is wrong with it:
/// missing, too large, another encoding, or malformed.
pub fn decode<M: Message + Default>(
    schema: &str,
    encoding: Option<&str>,
    payload: Option<&[u8]>,
) -> Result<M, Refusal> {
    let Some(payload) = payload else {
        return Err(Refusal::bad(format!("empty request: no payload; send a {schema}")));
    };
    if payload.len() > MAX_REQUEST_BYTES {
        return Err(Refusal::bad(format!(
            "payload of {} bytes exceeds the {MAX_REQUEST_BYTES}-byte limit of a {schema}",
            payload.len()
        )));
    }
    if let Some(enc) = encoding {
        let base = enc.split(';').next().unwrap_or_default();
        if base != "application/protobuf" && base != "zenoh/bytes" {
            return Err(Refusal::bad(format!(
                "payload encoding is '{enc}'; expected application/protobuf ({schema})"
            )));
        }
    }
    M::decode(payload).map_err(|e| Refusal::bad(format!("malformed {schema} payload: {e}")))
}

/// Check a switch request against `config`: a method it knows, exactly one
/// target, an allowed level or a positive finite error bound.
pub fn switch_plan(config: &InstancePlan, req: &v1::SwitchRequest) -> Result<SwitchPlan, Refusal> {
    let method = if req.method.is_empty() {
        config.method
    } else {
        // The name comes from the network: escaped before it is echoed.
        Served::parse(&req.method).map_err(|e| {
            let given = e.given.escape_debug().to_string();
            Refusal::bad(format!("method {}", names::UnknownName { given, ..e }))
        })?
    };
    let target = match &req.target {
        None => return Err(Refusal::bad("no target: set either level or max_error")),
        Some(v1::switch_request::Target::Level(l)) => {
            let level = Level::from_wire(l).map_err(|e| Refusal::bad(format!("level: {e}")))?;
            if !config.levels.contains(&level) {
                return Err(Refusal::new(
                    Code::LevelNotAllowed,
                    format!(
                        "level {level} is not allowed for '{}'; allowed: {}",
                        config.name,
                        crate::plan::allowed(&config.levels)
                    ),
                ));
            }
            SwitchTarget::Level(level)
        }
        Some(v1::switch_request::Target::MaxError(e)) => {
            if !(*e > 0.0 && e.is_finite()) {
                return Err(Refusal::bad(format!(
                    "max_error {e} must be a positive finite fraction (0.05 = 5 %)"
                )));
            }
            SwitchTarget::MaxError(*e)
        }
    };
    let at_once = req.at_once && matches!(target, SwitchTarget::Level(_));
    Ok(SwitchPlan {
        target,
        method,
        at_once,
    })
}

/// Check a control request: one of the known actions.
pub fn control_action(req: &v1::ControlRequest) -> Result<v1::control_request::Action, Refusal> {
    use v1::control_request::Action;
    match Action::try_from(req.action) {
        Ok(a @ (Action::Pause | Action::Resume | Action::Reset)) => Ok(a),
        _ => Err(Refusal::bad(format!(
            "action {} is not one of PAUSE, RESUME, RESET",
            req.action
        ))),
    }
}

/// Turn an input request into an [`Input`] whose fields are all in range
/// ([`Input::check`]); a missing part is refused naming it. Whether the
/// input fits the instance (its grab ids, pin sets, stability at its dt)
/// is the engine's to check, between two steps.
pub fn input(req: &v1::InputRequest) -> Result<Input, Refusal> {
    use v1::input_request::Action;
    let vec = |v: &Option<v1::Vec3>, name: &str| -> Result<[f64; 3], Refusal> {
        v.as_ref()
            .map(|v| [v.x, v.y, v.z])
            .ok_or_else(|| Refusal::bad(format!("{name}: missing")))
    };
    let patch = |p: &Option<v1::Patch>, name: &str| -> Result<Patch, Refusal> {
        p.as_ref()
            .map(|p| Patch {
                u: p.u,
                v: p.v,
                radius: p.radius,
            })
            .ok_or_else(|| Refusal::bad(format!("{name}: missing")))
    };
    let input = match &req.action {
        None => {
            return Err(Refusal::bad(
                "no action: set one of grab, move, release, release_all, move_pin, wind, scene_wind, impulse",
            ))
        }
        Some(Action::Grab(g)) => Input::Grab {
            id: g.id,
            at: patch(&g.at, "grab.at")?,
            target: g.target.as_ref().map(|v| [v.x, v.y, v.z]),
            stiffness: g.stiffness,
            damping: g.damping,
        },
        Some(Action::Move(m)) => Input::Move {
            id: m.id,
            target: vec(&m.target, "move.target")?,
        },
        Some(Action::Release(r)) => Input::Release { id: r.id },
        Some(Action::ReleaseAll(_)) => Input::ReleaseAll,
        Some(Action::MovePin(m)) => Input::MovePin {
            pin: m.pin,
            offset: vec(&m.offset, "move_pin.offset")?,
            seconds: m.seconds,
        },
        Some(Action::Wind(w)) => Input::Wind {
            velocity: vec(&w.velocity, "wind.velocity")?,
            gust: w.gust,
            gust_hz: w.gust_hz,
        },
        Some(Action::SceneWind(_)) => Input::SceneWind,
        Some(Action::Impulse(i)) => Input::Impulse {
            at: patch(&i.at, "impulse.at")?,
            impulse: vec(&i.impulse, "impulse.impulse")?,
        },
    };
    input.check().map_err(|e| Refusal::bad(e.to_string()))?;
    Ok(input)
}

/// A token bucket: `rate` tokens a second up to `burst`; each accepted
/// input takes one. Pure (the caller passes the time) so it can be tested
/// without a clock.
#[derive(Debug, Clone)]
pub struct TokenBucket {
    rate: f64,
    burst: f64,
    tokens: f64,
    last: std::time::Instant,
}

impl TokenBucket {
    /// A full bucket at `now`.
    pub fn new(rate: f64, burst: u32, now: std::time::Instant) -> TokenBucket {
        TokenBucket {
            rate,
            burst: f64::from(burst),
            tokens: f64::from(burst),
            last: now,
        }
    }

    /// Take a token at `now`; false when none is left.
    pub fn take(&mut self, now: std::time::Instant) -> bool {
        let elapsed = now.saturating_duration_since(self.last).as_secs_f64();
        self.last = self.last.max(now);
        self.tokens = (self.tokens + elapsed * self.rate).min(self.burst);
        if self.tokens >= 1.0 {
            self.tokens -= 1.0;
            true
        } else {
            false
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::{Duration, Instant};

    #[test]
    fn a_token_bucket_passes_its_burst_then_its_rate() {
        let t0 = Instant::now();
        let mut b = TokenBucket::new(100.0, 10, t0);
        assert_eq!((0..20).filter(|_| b.take(t0)).count(), 10, "the burst at once");
        // One second later: 100 more (capped at the burst of 10 at a time).
        let mut passed = 0;
        for ms in 1..=1000 {
            if b.take(t0 + Duration::from_millis(ms)) {
                passed += 1;
            }
        }
        assert!((99..=101).contains(&passed), "{passed} in a second at 100/s");
        // A long pause refills only to the burst.
        let later = t0 + Duration::from_secs(60);
        assert_eq!((0..50).filter(|_| b.take(later)).count(), 10);
    }

    #[test]
    fn input_requests_become_checked_inputs_or_refusals_naming_the_field() {
        let grab = |u: f64| v1::InputRequest {
            action: Some(v1::input_request::Action::Grab(v1::input_request::Grab {
                id: 2,
                at: Some(v1::Patch { u, v: 0.5, radius: 0.0 }),
                target: Some(v1::Vec3 { x: 0.0, y: 1.0, z: 0.0 }),
                stiffness: 3.0,
                damping: 0.1,
            })),
        };
        match input(&grab(0.25)) {
            Ok(Input::Grab { id: 2, at, target, .. }) => {
                assert_eq!((at.u, at.v, target), (0.25, 0.5, Some([0.0, 1.0, 0.0])));
            }
            other => panic!("{other:?}"),
        }
        let r = input(&grab(1.25)).unwrap_err();
        assert_eq!(r.code, Code::BadRequest);
        assert!(r.message.starts_with("grab.at.u = 1.25"), "{}", r.message);
        let r = input(&v1::InputRequest { action: None }).unwrap_err();
        assert!(r.message.contains("no action"), "{}", r.message);
        let no_target = v1::InputRequest {
            action: Some(v1::input_request::Action::Move(v1::input_request::Move {
                id: 1,
                target: None,
            })),
        };
        assert!(input(&no_target)
            .unwrap_err()
            .message
            .starts_with("move.target: missing"));
    }
}
