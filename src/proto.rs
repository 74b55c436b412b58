//! The wire contract (`proto/lodcloth/v1/lodcloth.proto`, compiled by
//! `build.rs`) and every conversion between wire and domain types.

#![allow(missing_docs, clippy::doc_lazy_continuation, clippy::large_enum_variant)]

/// Generated message types of package `lodcloth.v1`.
pub mod v1 {
    include!(concat!(env!("OUT_DIR"), "/lodcloth.v1.rs"));
}

use std::time::UNIX_EPOCH;

use crate::engine::{AppliedInput, MetricsFrame, StateFrame};
use crate::plan::Level;
use crate::sim::{Collider, Material, Shape, SpringCoeffs};
use crate::touch::{Input, Patch};

/// Schema names sent with every put and reply (`application/protobuf;<schema>`).
pub mod schema {
    pub const STATE: &str = "lodcloth.v1.State";
    pub const METRICS: &str = "lodcloth.v1.Metrics";
    pub const INSTANCE_INFO: &str = "lodcloth.v1.InstanceInfo";
    pub const INSTANCE_LIST: &str = "lodcloth.v1.InstanceList";
    pub const SWITCH_REQUEST: &str = "lodcloth.v1.SwitchRequest";
    pub const SWITCH_REPLY: &str = "lodcloth.v1.SwitchReply";
    pub const CONTROL_REQUEST: &str = "lodcloth.v1.ControlRequest";
    pub const CONTROL_REPLY: &str = "lodcloth.v1.ControlReply";
    pub const INPUT_REQUEST: &str = "lodcloth.v1.InputRequest";
    pub const INPUT_REPLY: &str = "lodcloth.v1.InputReply";
    pub const INPUT_EVENT: &str = "lodcloth.v1.InputEvent";
    pub const EPISODE_INPUTS: &str = "lodcloth.v1.EpisodeInputs";
    pub const ERROR: &str = "lodcloth.v1.Error";
}

/// A [`Level`] on the wire: `nx`/`ny` for a grid, `points` for a surface.
pub trait WireLevel: Sized {
    /// The wire message of this level.
    fn to_wire(self) -> v1::Level;
    /// The level a wire message names; an error when it sets both a grid
    /// and a point count.
    fn from_wire(l: &v1::Level) -> Result<Self, String>;
}

impl WireLevel for Level {
    fn to_wire(self) -> v1::Level {
        match self {
            Level::Grid { nx, ny } => v1::Level {
                nx: nx as u32,
                ny: ny as u32,
                ..Default::default()
            },
            Level::Points(n) => v1::Level {
                points: n as u32,
                ..Default::default()
            },
            Level::Vertices(n) => v1::Level {
                vertices: n as u32,
                ..Default::default()
            },
        }
    }

    fn from_wire(l: &v1::Level) -> Result<Level, String> {
        match (l.points, l.vertices, l.nx, l.ny) {
            (0, 0, nx, ny) => Ok(Level::new(nx as usize, ny as usize)),
            (n, 0, 0, 0) => Ok(Level::Points(n as usize)),
            (0, n, 0, 0) => Ok(Level::Vertices(n as usize)),
            (p, v, nx, ny) => {
                let mut set = Vec::new();
                if nx != 0 || ny != 0 {
                    set.push(format!("a grid ({nx}x{ny})"));
                }
                if p != 0 {
                    set.push(format!("a point count ({p})"));
                }
                if v != 0 {
                    set.push(format!("a vertex count ({v})"));
                }
                let last = set.pop().unwrap_or_default();
                let both = if set.len() == 1 { "both " } else { "all of " };
                Err(format!("level sets {both}{} and {last}; set one", set.join(", ")))
            }
        }
    }
}

/// An [`Input`] as a client sends it (`service::request::input` is the
/// inverse, with the checks).
pub fn input_request(input: &Input) -> v1::InputRequest {
    use v1::input_request::{self as ir, Action};
    let vec = |v: [f64; 3]| {
        Some(v1::Vec3 {
            x: v[0],
            y: v[1],
            z: v[2],
        })
    };
    let patch = |p: Patch| {
        Some(v1::Patch {
            u: p.u,
            v: p.v,
            radius: p.radius,
        })
    };
    let action = match *input {
        Input::Grab {
            id,
            at,
            target,
            stiffness,
            damping,
        } => Action::Grab(ir::Grab {
            id,
            at: patch(at),
            target: target.and_then(vec),
            stiffness,
            damping,
        }),
        Input::Move { id, target } => Action::Move(ir::Move {
            id,
            target: vec(target),
        }),
        Input::Release { id } => Action::Release(ir::Release { id }),
        Input::ReleaseAll => Action::ReleaseAll(ir::ReleaseAll {}),
        Input::MovePin { pin, offset, seconds } => Action::MovePin(ir::MovePin {
            pin,
            offset: vec(offset),
            seconds,
        }),
        Input::Wind {
            velocity,
            gust,
            gust_hz,
        } => Action::Wind(ir::Wind {
            velocity: vec(velocity),
            gust,
            gust_hz,
        }),
        Input::SceneWind => Action::SceneWind(ir::SceneWind {}),
        Input::Impulse { at, impulse } => Action::Impulse(ir::Impulse {
            at: patch(at),
            impulse: vec(impulse),
        }),
    };
    v1::InputRequest { action: Some(action) }
}

/// `InputEvent` on the wire.
pub fn input_event(instance: &str, a: &AppliedInput) -> v1::InputEvent {
    v1::InputEvent {
        instance: instance.to_string(),
        frame: a.frame,
        time: a.time,
        episode: a.episode,
        level: Some(a.level.to_wire()),
        input: Some(input_request(&a.input)),
        idle: a.idle,
        seq: a.seq,
    }
}

/// `State` on the wire.
pub fn state_message(instance: &str, f: &StateFrame) -> v1::State {
    v1::State {
        instance: instance.to_string(),
        frame: f.frame,
        time: f.time,
        level: Some(f.level.to_wire()),
        coefficient_version: f.coefficient_version,
        positions: pack_positions(&f.positions),
        episode: f.episode,
        stepped_unix_nanos: f.stepped.duration_since(UNIX_EPOCH).map_or(0, |d| d.as_nanos() as u64),
        transition: f.transition,
        simulation_positions: pack_positions(&f.simulation_positions),
        normals: pack_positions(&f.normals),
        reference_positions: pack_positions(&f.reference_positions),
        collider_positions: pack_positions(&f.collider_positions),
    }
}

/// A scene's rigid body on the wire, with the triangles clients draw.
pub fn collider(body: &Collider) -> v1::Collider {
    let vec3 = |v: [f64; 3]| v1::Vec3 {
        x: v[0],
        y: v[1],
        z: v[2],
    };
    let (shape, axis, radius, half_extents) = match body.shape {
        Shape::Plane { normal } => ("plane", Some(vec3(normal)), 0.0, None),
        Shape::Sphere { radius } => ("sphere", None, radius, None),
        Shape::Capsule { half_axis, radius } => ("capsule", Some(vec3(half_axis)), radius, None),
        Shape::Cuboid { half_extents } => ("box", None, 0.0, Some(vec3(half_extents))),
        Shape::Cylinder { radius, half_height } => (
            "cylinder",
            Some(vec3([0.0, half_height, 0.0])),
            radius,
            Some(vec3([radius, half_height, radius])),
        ),
    };
    let triangles: Vec<f32> = body
        .shape
        .triangles(COLLIDER_PLANE_SIZE)
        .iter()
        .flat_map(|v| v.map(|c| c as f32))
        .collect();
    v1::Collider {
        shape: shape.to_string(),
        position: Some(vec3(body.position)),
        axis,
        radius,
        half_extents,
        friction: body.friction,
        clearance: body.clearance,
        triangles: pack_positions(&triangles),
    }
}

/// How wide a plane is drawn (m): it is infinite.
pub const COLLIDER_PLANE_SIZE: f64 = 4.0;

/// `Metrics` on the wire.
pub fn metrics_message(instance: &str, m: &MetricsFrame) -> v1::Metrics {
    v1::Metrics {
        instance: instance.to_string(),
        frame: m.frame,
        time: m.time,
        level: Some(m.level.to_wire()),
        method: m.method.to_string(),
        predicted_error: m.predicted_error,
        live_error: m.live_error,
        live_error_time: m.live_error_time,
        step_cost_us: m.step_cost_us,
        real_time_factor: m.real_time_factor,
        overruns: m.overruns,
        kinetic_energy: m.kinetic_energy,
        potential_energy: m.potential_energy,
        max_strain: m.max_strain,
        coefficient_version: m.coefficient_version,
        paused: m.paused,
        dt: m.dt,
        steps: m.frame,
        lag_resets: m.lag_resets,
        divergences: m.divergences,
        rollbacks: m.rollbacks,
        halted: m.halted.as_deref().unwrap_or_default().to_string(),
        inputs: m.inputs,
        touched: m.touched,
        // The service knows it (the preparer's), not the engine.
        predicted_error_under_input: None,
    }
}

/// Coefficients on the wire.
pub fn coefficients(m: &Material) -> v1::Coefficients {
    let [s, sv, h, b, bv] = m.springs;
    v1::Coefficients {
        structural_k: s.k,
        structural_c: s.c,
        shear_k: h.k,
        shear_c: h.c,
        bend_k: b.k,
        bend_c: b.c,
        structural_v_k: Some(sv.k),
        structural_v_c: Some(sv.c),
        bend_v_k: Some(bv.k),
        bend_v_c: Some(bv.c),
    }
}

/// Coefficients from the wire (absent `_v` fields: the same as along u).
pub fn material(c: &v1::Coefficients) -> Material {
    let su = SpringCoeffs {
        k: c.structural_k,
        c: c.structural_c,
    };
    let bu = SpringCoeffs {
        k: c.bend_k,
        c: c.bend_c,
    };
    Material {
        springs: [
            su,
            SpringCoeffs {
                k: c.structural_v_k.unwrap_or(su.k),
                c: c.structural_v_c.unwrap_or(su.c),
            },
            SpringCoeffs {
                k: c.shear_k,
                c: c.shear_c,
            },
            bu,
            SpringCoeffs {
                k: c.bend_v_k.unwrap_or(bu.k),
                c: c.bend_v_c.unwrap_or(bu.c),
            },
        ],
    }
}

/// Pack interleaved positions `x0 y0 z0 x1 …` (as the engine snapshots
/// them) into the wire's little-endian f32 bytes.
pub fn pack_positions(interleaved: &[f32]) -> Vec<u8> {
    interleaved.iter().flat_map(|v| v.to_le_bytes()).collect()
}

/// Unpack interleaved f32 positions into SoA f64 (x…, y…, z…). None when the
/// byte count is not a multiple of 12.
pub fn unpack_positions(bytes: &[u8]) -> Option<Vec<f64>> {
    if !bytes.len().is_multiple_of(12) {
        return None;
    }
    let n = bytes.len() / 12;
    let mut soa = vec![0.0; 3 * n];
    for (i, chunk) in bytes.chunks_exact(4).enumerate() {
        let v = f32::from_le_bytes([chunk[0], chunk[1], chunk[2], chunk[3]]);
        soa[(i % 3) * n + i / 3] = f64::from(v);
    }
    Some(soa)
}

/// An error reply.
pub fn error(code: v1::error::Code, message: impl Into<String>) -> v1::Error {
    v1::Error {
        code: code as i32,
        message: message.into(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_input_crosses_the_wire_and_comes_back_the_same() {
        let at = Patch {
            u: 0.25,
            v: 0.75,
            radius: 0.05,
        };
        let inputs = [
            Input::Grab {
                id: 3,
                at,
                target: Some([0.1, -0.2, 0.3]),
                stiffness: 40.0,
                damping: 0.5,
            },
            Input::Grab {
                id: 4,
                at,
                target: None,
                stiffness: 1.0,
                damping: 0.0,
            },
            Input::Move {
                id: 3,
                target: [1.0, 2.0, 3.0],
            },
            Input::Release { id: 3 },
            Input::ReleaseAll,
            Input::MovePin {
                pin: 1,
                offset: [0.0, 0.1, 0.0],
                seconds: 0.5,
            },
            Input::Wind {
                velocity: [2.0, 0.0, 1.0],
                gust: 0.3,
                gust_hz: 0.7,
            },
            Input::SceneWind,
            Input::Impulse {
                at,
                impulse: [0.0, 0.0, 0.02],
            },
        ];
        for input in inputs {
            let wire = input_request(&input);
            let bytes = prost::Message::encode_to_vec(&wire);
            let back: v1::InputRequest = prost::Message::decode(bytes.as_slice()).unwrap();
            assert_eq!(crate::service::request::input(&back).unwrap(), input);
        }
    }

    #[test]
    fn levels_cross_the_wire_and_mixed_levels_are_refused() {
        for l in [Level::new(16, 24), Level::Points(327), Level::Vertices(1200)] {
            assert_eq!(Level::from_wire(&l.to_wire()), Ok(l));
        }
        let mixed = v1::Level {
            nx: 16,
            ny: 16,
            points: 300,
            ..Default::default()
        };
        let e = Level::from_wire(&mixed).unwrap_err();
        assert!(e.contains("16x16") && e.contains("300"), "{e}");
        let both = v1::Level {
            points: 300,
            vertices: 1200,
            ..Default::default()
        };
        let e = Level::from_wire(&both).unwrap_err();
        assert!(e.contains("300") && e.contains("1200"), "{e}");
    }

    #[test]
    fn config_levels_accept_counts_and_strings() {
        #[derive(serde::Deserialize)]
        struct L {
            levels: Vec<Level>,
        }
        let l: L = toml::from_str(r#"levels = [85, "273", "16x16"]"#).unwrap();
        assert_eq!(
            l.levels,
            vec![Level::Points(85), Level::Points(273), Level::new(16, 16)]
        );
        assert!(toml::from_str::<L>("levels = [-3]").is_err());
    }

    #[test]
    fn coefficients_cross_the_wire_per_direction_and_old_messages_mean_v_equals_u() {
        let m = Material {
            springs: [
                SpringCoeffs { k: 400.0, c: 0.04 },
                SpringCoeffs { k: 250.0, c: 0.025 },
                SpringCoeffs { k: 60.0, c: 0.006 },
                SpringCoeffs { k: 8.0, c: 8e-4 },
                SpringCoeffs { k: 5.0, c: 5e-4 },
            ],
        };
        assert_eq!(material(&coefficients(&m)), m);
        // A message from before the `_v` fields: v is u.
        let old = v1::Coefficients {
            structural_v_k: None,
            structural_v_c: None,
            bend_v_k: None,
            bend_v_c: None,
            ..coefficients(&m)
        };
        let [su, _, sh, bu, _] = m.springs;
        assert_eq!(material(&old), Material::isotropic([su, sh, bu]));
    }

    #[test]
    fn positions_round_trip_through_the_packed_layout() {
        // Two nodes, (1, 10, 100) and (2, 20, 200).
        let soa = vec![1.0, 2.0, 10.0, 20.0, 100.0, 200.0];
        let bytes = pack_positions(&[1.0, 10.0, 100.0, 2.0, 20.0, 200.0]);
        assert_eq!(bytes.len(), 24);
        // Node 0 is (1, 10, 100): the first three f32 of the packed layout.
        assert_eq!(f32::from_le_bytes(bytes[4..8].try_into().unwrap()), 10.0);
        assert_eq!(unpack_positions(&bytes), Some(soa));
        assert_eq!(unpack_positions(&bytes[..5]), None);
    }
}
