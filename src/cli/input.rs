//! `lodcloth input`: touch a running cloth (grab, move, release, move a
//! pin, set the wind, strike it). Each call sends one `InputRequest` and
//! prints the daemon's answer: the step after which it took effect and the
//! grabs held, or the refusal naming the field.

use anyhow::Result;
use clap::{Args, Subcommand};

use lodcloth::proto::v1;
use v1::input_request::{self as ir, Action};

use crate::serve::{self, Connect};

/// `input` options.
#[derive(Args)]
pub struct InputArgs {
    /// The instance to touch.
    pub instance: String,
    #[command(subcommand)]
    pub action: InputAction,
}

/// A point or vector `x,y,z` (m, m/s or N·s).
fn vec3(text: &str) -> Result<[f64; 3], String> {
    let parts: Vec<&str> = text.split(',').collect();
    let [x, y, z] = parts.as_slice() else {
        return Err(format!("'{text}' is not x,y,z"));
    };
    let num = |s: &str| s.trim().parse::<f64>().map_err(|e| format!("'{s}' in '{text}': {e}"));
    Ok([num(x)?, num(y)?, num(z)?])
}

/// Where on the cloth: material coordinates and a radius.
#[derive(Args, Clone, Copy)]
pub struct PatchArgs {
    /// Across the width, 0 (left edge) to 1 (right edge).
    #[arg(long)]
    pub u: f64,
    /// Down the height, 0 (top row) to 1 (bottom row).
    #[arg(long)]
    pub v: f64,
    /// Half-side of the square patch (m); 0 is a point.
    #[arg(long, default_value_t = 0.02)]
    pub radius: f64,
}

impl PatchArgs {
    fn wire(self) -> Option<v1::Patch> {
        Some(v1::Patch {
            u: self.u,
            v: self.v,
            radius: self.radius,
        })
    }
}

/// What to do.
#[derive(Subcommand)]
pub enum InputAction {
    /// Take hold of a patch with a spring to a target point.
    Grab {
        /// The grab's id (a later grab with the same id replaces it).
        #[arg(long, default_value_t = 1)]
        id: u32,
        #[command(flatten)]
        at: PatchArgs,
        /// Target point x,y,z (m); without it, where the patch is now (then
        /// `move` drags it).
        #[arg(long, value_parser = vec3, allow_hyphen_values = true)]
        target: Option<[f64; 3]>,
        /// Spring constant (N/m).
        #[arg(long, default_value_t = 20.0)]
        stiffness: f64,
        /// Damping (N·s/m).
        #[arg(long, default_value_t = 0.2)]
        damping: f64,
    },
    /// Move a grab's target.
    Move {
        #[arg(long, default_value_t = 1)]
        id: u32,
        /// New target x,y,z (m).
        #[arg(long, value_parser = vec3, allow_hyphen_values = true)]
        target: [f64; 3],
    },
    /// Let go of a grab (every grab with --all).
    Release {
        #[arg(long, default_value_t = 1, conflicts_with = "all")]
        id: u32,
        #[arg(long)]
        all: bool,
    },
    /// Move one of the scene's pin sets off its scripted path.
    MovePin {
        /// Index of the set in the scene's [[pins]].
        #[arg(long, default_value_t = 0)]
        pin: u32,
        /// Offset x,y,z from the scripted position (m).
        #[arg(long, value_parser = vec3, allow_hyphen_values = true)]
        offset: [f64; 3],
        /// Over this much simulated time (s).
        #[arg(long, default_value_t = 1.0)]
        seconds: f64,
    },
    /// Replace the scene's wind (--scene: back to the scene's own).
    Wind {
        /// Air velocity x,y,z (m/s).
        #[arg(long, value_parser = vec3, allow_hyphen_values = true, required_unless_present = "scene")]
        velocity: Option<[f64; 3]>,
        /// Gusts: the velocity scaled by 1 + gust·sin(2π·gust_hz·t).
        #[arg(long, default_value_t = 0.0)]
        gust: f64,
        #[arg(long, default_value_t = 0.0)]
        gust_hz: f64,
        /// Back to the scene's own wind.
        #[arg(long, conflicts_with = "velocity")]
        scene: bool,
    },
    /// Give a patch momentum at once.
    Impulse {
        #[command(flatten)]
        at: PatchArgs,
        /// Impulse x,y,z (N·s).
        #[arg(long, value_parser = vec3, allow_hyphen_values = true)]
        impulse: [f64; 3],
    },
}

fn wire3(p: [f64; 3]) -> Option<v1::Vec3> {
    Some(v1::Vec3 {
        x: p[0],
        y: p[1],
        z: p[2],
    })
}

/// The request an action sends.
pub fn request(action: &InputAction) -> v1::InputRequest {
    let action = match *action {
        InputAction::Grab {
            id,
            at,
            target,
            stiffness,
            damping,
        } => Action::Grab(ir::Grab {
            id,
            at: at.wire(),
            target: target.and_then(wire3),
            stiffness,
            damping,
        }),
        InputAction::Move { id, target } => Action::Move(ir::Move {
            id,
            target: wire3(target),
        }),
        InputAction::Release { all: true, .. } => Action::ReleaseAll(ir::ReleaseAll {}),
        InputAction::Release { id, all: false } => Action::Release(ir::Release { id }),
        InputAction::MovePin { pin, offset, seconds } => Action::MovePin(ir::MovePin {
            pin,
            offset: wire3(offset),
            seconds,
        }),
        InputAction::Wind { scene: true, .. } => Action::SceneWind(ir::SceneWind {}),
        InputAction::Wind {
            velocity,
            gust,
            gust_hz,
            ..
        } => Action::Wind(ir::Wind {
            velocity: wire3(velocity.unwrap_or_default()),
            gust,
            gust_hz,
        }),
        InputAction::Impulse { at, impulse } => Action::Impulse(ir::Impulse {
            at: at.wire(),
            impulse: wire3(impulse),
        }),
    };
    v1::InputRequest { action: Some(action) }
}

pub fn run(c: Connect, args: InputArgs) -> Result<()> {
    let request = request(&args.action);
    serve::runtime()?.block_on(async {
        let client = serve::connect(&c).await?;
        let r = client.input(&args.instance, &request).await?;
        println!(
            "{}: applied after step {} (t = {:.3} s) at {}; grabs held: {:?}",
            r.instance,
            r.frame,
            r.time,
            r.level.map_or_else(|| "?".into(), |l| format!("{}x{}", l.nx, l.ny)),
            r.grabs
        );
        let _ = client.session.close().await;
        Ok(())
    })
}
