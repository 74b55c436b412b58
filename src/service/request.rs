//! Checking a request before anything acts on it: the key names one known
//! instance, the payload is small, protobuf and well-formed, and every field
//! is in range for that instance. Pure (no zenoh, no I/O) so that it can be
//! fuzzed by the million; the daemon answers every [`Refusal`] with an
//! `Error` reply carrying its code and message.

use prost::Message;

use super::keys;
use crate::estimate::Method;
use crate::names;
use crate::plan::InstancePlan;
use crate::plan::Level;
use crate::proto::{v1, WireLevel};
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
        names::parse::<Method>(&req.method).map_err(|e| {
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
