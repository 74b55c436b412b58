//! Generated requests for the daemon's queryables: valid ones, ones with
//! every field out of range, mutated and random bytes, wrong encodings,
//! oversized payloads, unknown and wildcard instances. Deterministic from a
//! seed (the tests' SplitMix64 [`Rng`]), for `tests/robustness.rs` (in
//! process and over the bus).
#![allow(dead_code)]

use prost::Message;

use crate::common::Rng;
use lodcloth::proto::v1;

/// Which queryable a request goes to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Leaf {
    Switch,
    Control,
    Input,
    Info,
}

impl Leaf {
    pub fn name(self) -> &'static str {
        match self {
            Leaf::Switch => "switch",
            Leaf::Control => "control",
            Leaf::Input => "input",
            Leaf::Info => "info",
        }
    }
}

/// One generated request.
#[derive(Debug, Clone)]
pub struct Request {
    pub leaf: Leaf,
    /// The instance segment of the key.
    pub instance: String,
    pub encoding: Option<String>,
    pub payload: Option<Vec<u8>>,
}

impl Request {
    pub fn key(&self, prefix: &str) -> String {
        format!("{prefix}/{}/{}", self.instance, self.leaf.name())
    }
}

const NUMBERS: [u32; 9] = [0, 1, 7, 8, 12, 16, 24, 100_000, u32::MAX];
const ERRORS: [f64; 12] = [
    f64::NAN,
    f64::INFINITY,
    f64::NEG_INFINITY,
    -1.0,
    0.0,
    -0.0,
    f64::MIN_POSITIVE,
    1e-300,
    0.05,
    0.5,
    1e300,
    f64::MAX,
];

fn method(rng: &mut Rng) -> String {
    match rng.below(10) {
        0..=3 => String::new(),
        4 => rng.pick(&["same", "bcd", "gkd", "lsq", "fit"]).to_string(),
        5 => rng.pick(&["SAME", "Fit", "bcd ", "gkd\0", "lsq;drop"]).to_string(),
        6 => "é∑😀".repeat(rng.below(50)),
        7 => "x".repeat(rng.below(5000)),
        _ => String::from_utf8_lossy(&rng.bytes(0, 16)).into_owned(),
    }
}

fn number(rng: &mut Rng) -> u32 {
    if rng.chance(3) {
        rng.next_u64() as u32
    } else {
        *rng.pick(&NUMBERS)
    }
}

/// A `SwitchRequest` whose fields are anything their types allow.
pub fn switch_request(rng: &mut Rng) -> v1::SwitchRequest {
    use v1::switch_request::Target;
    let target = match rng.below(4) {
        0 => None,
        1 => Some(Target::MaxError(if rng.chance(3) {
            f64::from_bits(rng.next_u64())
        } else {
            *rng.pick(&ERRORS)
        })),
        _ => Some(Target::Level(v1::Level {
            nx: number(rng),
            ny: number(rng),
            points: if rng.chance(3) { number(rng) } else { 0 },
            vertices: if rng.chance(3) { number(rng) } else { 0 },
        })),
    };
    v1::SwitchRequest {
        at_once: false,
        target,
        method: method(rng),
    }
}

/// A float that is anything its type allows, often a special value.
fn real(rng: &mut Rng) -> f64 {
    match rng.below(4) {
        0 => f64::from_bits(rng.next_u64()),
        1 => *rng.pick(&ERRORS),
        _ => (rng.below(2001) as f64 - 1000.0) / 500.0,
    }
}

fn vec3(rng: &mut Rng) -> Option<v1::Vec3> {
    (!rng.chance(8)).then(|| v1::Vec3 {
        x: real(rng),
        y: real(rng),
        z: real(rng),
    })
}

fn patch(rng: &mut Rng) -> Option<v1::Patch> {
    (!rng.chance(8)).then(|| v1::Patch {
        u: real(rng),
        v: real(rng),
        radius: real(rng),
    })
}

/// An `InputRequest` whose fields are anything their types allow.
pub fn input_request(rng: &mut Rng) -> v1::InputRequest {
    use v1::input_request::{self as ir, Action};
    let action = match rng.below(9) {
        0 => None,
        1 => Some(Action::Grab(ir::Grab {
            id: number(rng),
            at: patch(rng),
            target: vec3(rng),
            stiffness: real(rng),
            damping: real(rng),
        })),
        2 => Some(Action::Move(ir::Move {
            id: number(rng),
            target: vec3(rng),
        })),
        3 => Some(Action::Release(ir::Release { id: number(rng) })),
        4 => Some(Action::ReleaseAll(ir::ReleaseAll {})),
        5 => Some(Action::MovePin(ir::MovePin {
            pin: number(rng),
            offset: vec3(rng),
            seconds: real(rng),
        })),
        6 => Some(Action::Wind(ir::Wind {
            velocity: vec3(rng),
            gust: real(rng),
            gust_hz: real(rng),
        })),
        7 => Some(Action::SceneWind(ir::SceneWind {})),
        _ => Some(Action::Impulse(ir::Impulse {
            at: patch(rng),
            impulse: vec3(rng),
        })),
    };
    v1::InputRequest { action }
}

/// Damage an encoding: truncate, flip bits, splice in random bytes.
fn mutate(rng: &mut Rng, mut bytes: Vec<u8>) -> Vec<u8> {
    for _ in 0..1 + rng.below(3) {
        match rng.below(3) {
            0 if !bytes.is_empty() => {
                let n = rng.below(bytes.len());
                bytes.truncate(n)
            }
            1 if !bytes.is_empty() => {
                let i = rng.below(bytes.len());
                bytes[i] ^= 1 << rng.below(8);
            }
            _ => {
                let at = rng.below(bytes.len() + 1);
                let extra = rng.bytes(1, 8);
                bytes.splice(at..at, extra);
            }
        }
    }
    bytes
}

fn payload(rng: &mut Rng, leaf: Leaf) -> Option<Vec<u8>> {
    let valid = || -> fn(&mut Rng) -> Vec<u8> {
        match leaf {
            Leaf::Switch => |rng| switch_request(rng).encode_to_vec(),
            Leaf::Control => |rng| {
                v1::ControlRequest {
                    action: if rng.chance(2) {
                        rng.below(5) as i32 - 1
                    } else {
                        rng.next_u64() as i32
                    },
                }
                .encode_to_vec()
            },
            Leaf::Input => |rng| input_request(rng).encode_to_vec(),
            Leaf::Info => |rng| rng.bytes(0, 4),
        }
    };
    match rng.below(20) {
        0 => None,
        1 => Some(Vec::new()),
        2 if rng.chance(50) => Some(rng.bytes(lodcloth::service::request::MAX_REQUEST_BYTES + 1, 40_000)),
        3..=5 => Some(rng.bytes(0, 64)),
        6..=9 => {
            let bytes = valid()(rng);
            Some(mutate(rng, bytes))
        }
        _ => Some(valid()(rng)),
    }
}

fn encoding(rng: &mut Rng) -> Option<String> {
    match rng.below(12) {
        0 => None,
        1..=5 => Some("application/protobuf;lodcloth.v1.SwitchRequest".into()),
        6 => Some("application/protobuf".into()),
        7 => Some("zenoh/bytes".into()),
        8 => Some("text/plain;charset=utf-8".into()),
        9 => Some("application/json".into()),
        10 => Some("application/protobuf;lodcloth.v1.State".into()),
        _ => Some("zenoh/string".into()),
    }
}

/// One request for a daemon running `instances` (several of which it
/// knows); the key is always a valid key expression.
pub fn request(rng: &mut Rng, instances: &[&str]) -> Request {
    let leaf = match rng.below(13) {
        0..=6 => Leaf::Switch,
        7..=8 => Leaf::Control,
        9..=11 => Leaf::Input,
        _ => Leaf::Info,
    };
    let instance = match rng.below(10) {
        0..=6 => rng.pick(instances).to_string(),
        7 => "ghost".into(),
        8 => rng.pick(&["*", "a$*", "$*b", "x-y_z", "é", "0"]).to_string(),
        _ => format!("unknown{}", rng.next_u64() % 1000),
    };
    Request {
        leaf,
        instance,
        encoding: encoding(rng),
        payload: payload(rng, leaf),
    }
}
