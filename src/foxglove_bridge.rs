//! The daemon's instances as Foxglove channels: `lodcloth foxglove` serves
//! them on the Foxglove WebSocket protocol, `lodcloth record --mcap` writes
//! the same channels to an MCAP file.
//!
//! Per instance:
//! - `/lodcloth/<instance>/mesh`: `foxglove.SceneUpdate`, one entity with
//!   the level's triangle mesh coloured per vertex (blue→red) by its error
//!   against the shadow reference (or by strain without one), and, with a
//!   shadow reference, a second translucent entity `<instance>/reference`;
//! - `/lodcloth/<instance>/metrics`: `lodcloth.v1.Metrics` as published,
//!   schema = the wire contract's file descriptor set;
//! - `/lodcloth/<instance>/inputs`: `lodcloth.v1.InputEvent`, every input
//!   that took effect (an MCAP recording replays with
//!   `lodcloth simulate --inputs`).
//!
//! Meshes are built only while a sink (a subscribed Foxglove client, an
//! MCAP file) wants them, and at most `max_hz` times a second per instance.

use std::collections::{HashMap, HashSet};
use std::future::Future;
use std::sync::Arc;
use std::time::{Duration, Instant};

use foxglove::messages::{
    Color, KeyValuePair, Point3, Pose, Quaternion, SceneEntity, SceneUpdate, Timestamp, TriangleListPrimitive, Vector3,
};
use foxglove::{Channel, ChannelBuilder, Context, PartialMetadata, RawChannel, Schema};
use prost::Message;

use crate::plan::Level;
use crate::proto::{schema, unpack_positions, v1, WireLevel};
use crate::service::client::Client;

/// The wire contract's file descriptor set (the schema of raw channels).
pub const DESCRIPTORS: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/lodcloth.fds"));

/// Topic of an instance's mesh.
pub fn mesh_topic(instance: &str) -> String {
    format!("/lodcloth/{instance}/mesh")
}

/// Topic of an instance's metrics.
pub fn metrics_topic(instance: &str) -> String {
    format!("/lodcloth/{instance}/metrics")
}

/// Topic of an instance's inputs.
pub fn inputs_topic(instance: &str) -> String {
    format!("/lodcloth/{instance}/inputs")
}

/// What the vertex colours show.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Colouring {
    /// |x − x_ref| / O_max per vertex.
    Error,
    /// Largest |l / l_rest − 1| over the vertex's triangle edges.
    Strain,
}

/// A blue→cyan→green→yellow→red map of `v` in [0, 1] (the paper's error maps).
pub fn jet(v: f64) -> [f64; 3] {
    let v = if v.is_finite() { v.clamp(0.0, 1.0) } else { 1.0 };
    let ramp = |x: f64| (1.5 - (4.0 * v - x).abs()).clamp(0.0, 1.0);
    [ramp(3.0), ramp(2.0), ramp(1.0)]
}

/// Per-vertex strain: the largest |l / l_rest − 1| over the edges of the
/// triangles around each vertex (0 for a vertex on no triangle).
pub fn vertex_strain(pos: &[[f64; 3]], rest: &[[f64; 3]], triangles: &[u32]) -> Vec<f64> {
    let mut strain = vec![0.0f64; pos.len()];
    let len = |p: &[[f64; 3]], a: usize, b: usize| {
        ((p[a][0] - p[b][0]).powi(2) + (p[a][1] - p[b][1]).powi(2) + (p[a][2] - p[b][2]).powi(2)).sqrt()
    };
    for t in triangles.chunks_exact(3) {
        for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
            let (a, b) = (a as usize, b as usize);
            if a >= pos.len() || b >= pos.len() || a >= rest.len() || b >= rest.len() {
                continue;
            }
            let l0 = len(rest, a, b);
            if l0 > 0.0 {
                let e = (len(pos, a, b) / l0 - 1.0).abs();
                strain[a] = strain[a].max(e);
                strain[b] = strain[b].max(e);
            }
        }
    }
    strain
}

fn points(packed: &[u8]) -> Option<Vec<[f64; 3]>> {
    let soa = unpack_positions(packed)?;
    let n = soa.len() / 3;
    Some((0..n).map(|k| [soa[k], soa[n + k], soa[2 * n + k]]).collect())
}

/// The scene update of one state: the mesh (cloth nodes, or a surface's
/// simulated points) coloured by error when the state carries the reference,
/// else by strain. Errors name what does not fit `info` (a state of another
/// level than the info describes, say).
pub fn scene_update(state: &v1::State, info: &v1::InstanceInfo) -> Result<(SceneUpdate, Colouring), String> {
    let surface = info.kind == "surface";
    let vertices = points(if surface {
        &state.simulation_positions
    } else {
        &state.positions
    })
    .ok_or("positions are not a whole number of f32 triples")?;
    let n = vertices.len();
    if let Some(&bad) = info.triangles.iter().find(|&&i| i as usize >= n) {
        return Err(format!("triangle index {bad} beyond the {n} vertices of the state"));
    }
    let reference = points(&state.reference_positions).unwrap_or_default();
    // The reference at each vertex: the same node, or a surface point's
    // place in the cloud.
    let reference: Vec<[f64; 3]> = if reference.is_empty() || !(info.o_max > 0.0) {
        Vec::new()
    } else if surface {
        info.simulation_points
            .iter()
            .map(|&i| reference.get(i as usize).copied())
            .collect::<Option<Vec<_>>>()
            .filter(|r| r.len() == n)
            .ok_or("reference positions do not cover the simulated points")?
    } else if reference.len() == n {
        reference
    } else {
        return Err(format!("{} reference positions for {n} nodes", reference.len()));
    };
    let (values, colouring) = if reference.is_empty() {
        let rest = points(&info.rest_positions).unwrap_or_default();
        (vertex_strain(&vertices, &rest, &info.triangles), Colouring::Strain)
    } else {
        let e = vertices
            .iter()
            .zip(&reference)
            .map(|(p, r)| ((p[0] - r[0]).powi(2) + (p[1] - r[1]).powi(2) + (p[2] - r[2]).powi(2)).sqrt() / info.o_max)
            .collect();
        (e, Colouring::Error)
    };
    let scale = values.iter().copied().fold(0.0f64, f64::max).max(1e-9);
    let stamp = Timestamp::new(
        (state.stepped_unix_nanos / 1_000_000_000) as u32,
        (state.stepped_unix_nanos % 1_000_000_000) as u32,
    );
    let pose = Pose {
        position: Some(Vector3 { x: 0.0, y: 0.0, z: 0.0 }),
        orientation: Some(Quaternion {
            x: 0.0,
            y: 0.0,
            z: 0.0,
            w: 1.0,
        }),
    };
    let to_points = |v: &[[f64; 3]]| {
        v.iter()
            .map(|p| Point3 {
                x: p[0],
                y: p[1],
                z: p[2],
            })
            .collect::<Vec<_>>()
    };
    let level = state
        .level
        .as_ref()
        .and_then(|l| Level::from_wire(l).ok())
        .map_or("?".into(), |l| l.to_string());
    let kv = |key: &str, value: String| KeyValuePair { key: key.into(), value };
    let mesh = SceneEntity {
        timestamp: Some(stamp),
        frame_id: "world".into(),
        id: state.instance.clone(),
        metadata: vec![
            kv("level", level),
            kv("frame", state.frame.to_string()),
            kv("coefficient_version", state.coefficient_version.to_string()),
            kv(
                "colour",
                match colouring {
                    Colouring::Error => "error (fraction of O_max)".into(),
                    Colouring::Strain => "strain".into(),
                },
            ),
            kv("colour_max", format!("{scale:.6}")),
        ],
        triangles: vec![TriangleListPrimitive {
            pose: Some(pose),
            points: to_points(&vertices),
            color: None,
            colors: values
                .iter()
                .map(|v| {
                    let [r, g, b] = jet(v / scale);
                    Color { r, g, b, a: 1.0 }
                })
                .collect(),
            indices: info.triangles.clone(),
        }],
        ..Default::default()
    };
    let mut entities = vec![mesh];
    if !reference.is_empty() {
        entities.push(SceneEntity {
            timestamp: Some(stamp),
            frame_id: "world".into(),
            id: format!("{}/reference", state.instance),
            triangles: vec![TriangleListPrimitive {
                pose: Some(pose),
                points: to_points(&reference),
                color: Some(Color {
                    r: 0.8,
                    g: 0.8,
                    b: 0.8,
                    a: 0.3,
                }),
                colors: Vec::new(),
                indices: info.triangles.clone(),
            }],
            ..Default::default()
        });
    }
    // The scene's bodies, each where the state says it is at its time.
    let centres = points(&state.collider_positions).unwrap_or_default();
    for (i, body) in info.colliders.iter().enumerate() {
        let at = centres
            .get(i)
            .copied()
            .or_else(|| body.position.as_ref().map(|p| [p.x, p.y, p.z]));
        let Some(at) = at else { continue };
        let triangles = points(&body.triangles).ok_or("a collider's triangles are not f32 triples")?;
        entities.push(SceneEntity {
            timestamp: Some(stamp),
            frame_id: "world".into(),
            id: format!("{}/collider/{i}", state.instance),
            metadata: vec![
                kv("shape", body.shape.clone()),
                kv("friction", body.friction.to_string()),
            ],
            triangles: vec![TriangleListPrimitive {
                pose: Some(Pose {
                    position: Some(Vector3 {
                        x: at[0],
                        y: at[1],
                        z: at[2],
                    }),
                    ..pose
                }),
                points: to_points(&triangles),
                color: Some(Color {
                    r: 0.55,
                    g: 0.45,
                    b: 0.35,
                    a: 1.0,
                }),
                colors: Vec::new(),
                indices: Vec::new(),
            }],
            ..Default::default()
        });
    }
    Ok((
        SceneUpdate {
            deletions: Vec::new(),
            entities,
        },
        colouring,
    ))
}

struct InstanceChannels {
    mesh: Channel<SceneUpdate>,
    metrics: Arc<RawChannel>,
    inputs: Arc<RawChannel>,
    info: Option<v1::InstanceInfo>,
    last_mesh: Option<Instant>,
    /// `seq` of every input logged, so one that is both in the episode log
    /// and on the subscription is logged once.
    inputs_logged: HashSet<u64>,
    /// The episode log was asked for (at the instance's first state).
    asked_log: bool,
}

impl InstanceChannels {
    /// Log an input event (encoded) unless its `seq` was logged already.
    fn log_input(&mut self, bytes: &[u8], seq: u64) -> bool {
        if !self.inputs_logged.insert(seq) {
            return false;
        }
        self.inputs.log(bytes);
        true
    }
}

/// Instances' channels opened in a context ahead of [`relay`]. Open them
/// before a WebSocket server starts on the context: the foxglove SDK
/// (0.30) sends a client the advertisement of a channel added while the
/// client is connected *before* it records the channel as advertised to
/// that client, so a client that subscribes at once is told "unknown
/// channel" and never gets its data. Channels that exist when a client
/// connects are advertised before its messages are read. (Instances that
/// appear later are still opened as they come.)
pub struct RelayChannels(HashMap<String, InstanceChannels>);

impl RelayChannels {
    /// The channels of each of `names` in `ctx`.
    pub fn open(ctx: &Arc<Context>, names: &[String]) -> anyhow::Result<RelayChannels> {
        let mut channels = HashMap::new();
        for name in names {
            if !channels.contains_key(name) {
                channels.insert(name.clone(), open_instance(ctx, name)?);
            }
        }
        Ok(RelayChannels(channels))
    }
}

/// One instance's mesh and metrics channels in `ctx`.
fn open_instance(ctx: &Arc<Context>, name: &str) -> anyhow::Result<InstanceChannels> {
    let metrics = ChannelBuilder::new(metrics_topic(name))
        .context(ctx)
        .message_encoding("protobuf")
        .schema(Schema::new(schema::METRICS, "protobuf", DESCRIPTORS))
        .build_raw()
        .map_err(|e| anyhow::anyhow!("metrics channel of {name}: {e}"))?;
    let inputs = ChannelBuilder::new(inputs_topic(name))
        .context(ctx)
        .message_encoding("protobuf")
        .schema(Schema::new(schema::INPUT_EVENT, "protobuf", DESCRIPTORS))
        .build_raw()
        .map_err(|e| anyhow::anyhow!("inputs channel of {name}: {e}"))?;
    Ok(InstanceChannels {
        inputs,
        mesh: ChannelBuilder::new(mesh_topic(name))
            .context(ctx)
            .build::<SceneUpdate>(),
        metrics,
        info: None,
        last_mesh: None,
        inputs_logged: HashSet::new(),
        asked_log: false,
    })
}

/// Log the inputs of `name`'s `episode` that the daemon applied before the
/// relay subscribed (its `episode_inputs` log, when it is of that episode);
/// how many were new.
async fn log_earlier_inputs(client: &Client, name: &str, episode: u64, ch: &mut InstanceChannels) -> u64 {
    match client.episode_inputs(name).await {
        Ok(log) if log.episode != episode => 0,
        Ok(log) => {
            if !log.complete {
                tracing::warn!(
                    instance = name,
                    kept = log.events.len(),
                    "the daemon kept only the latest inputs of this episode; a replay misses the first"
                );
            }
            let mut new = 0;
            for e in &log.events {
                if ch.log_input(&e.encode_to_vec(), e.seq) {
                    new += 1;
                }
            }
            new
        }
        Err(e) => {
            tracing::warn!(instance = name, error = %e, "no episode log: inputs from before the relay started are unknown");
            0
        }
    }
}

/// What a relay did.
#[derive(Debug, Default, Clone)]
pub struct RelayCounts {
    pub states: u64,
    pub meshes: u64,
    pub metrics: u64,
    /// Inputs that took effect.
    pub inputs: u64,
    /// States that could not be turned into a mesh (each also logged).
    pub rejected: u64,
}

/// Options of [`relay`].
#[derive(Debug, Clone)]
pub struct RelayOptions {
    /// One instance, or every instance under the prefix.
    pub instance: Option<String>,
    /// Meshes per second per instance, at most.
    pub max_hz: f64,
}

/// Relay the daemon's states, metrics and inputs into `ctx`'s channels (`opened`
/// ahead, the others as their instances appear) until `until` completes;
/// `progress` sees the counts after every state.
pub async fn relay(
    client: &Client,
    ctx: &Arc<Context>,
    options: &RelayOptions,
    opened: RelayChannels,
    until: impl Future<Output = ()>,
    mut progress: impl FnMut(&RelayCounts),
) -> anyhow::Result<RelayCounts> {
    let which = options.instance.as_deref().unwrap_or("*");
    let prefix = client.prefix.clone();
    let zerr = |e: zenoh::Error| anyhow::anyhow!("subscribing: {e}");
    // Inputs first: once states arrive, no input that acts on them is missed.
    let inputs = client
        .session
        .declare_subscriber(format!("{prefix}/{which}/inputs"))
        .await
        .map_err(zerr)?;
    let states = client
        .session
        .declare_subscriber(format!("{prefix}/{which}/state"))
        .await
        .map_err(zerr)?;
    let metrics = client
        .session
        .declare_subscriber(format!("{prefix}/{which}/metrics"))
        .await
        .map_err(zerr)?;
    let min_interval = Duration::from_secs_f64(1.0 / options.max_hz.max(1e-3));
    let mut channels = opened.0;
    let mut counts = RelayCounts::default();
    tokio::pin!(until);
    loop {
        tokio::select! {
            () = &mut until => break,
            sample = metrics.recv_async() => {
                let Ok(sample) = sample else { break };
                let Some(name) = crate::service::keys::instance_of(&prefix, "metrics", sample.key_expr().as_str()) else {
                    continue;
                };
                if !channels.contains_key(name) {
                    channels.insert(name.to_string(), open_instance(ctx, name)?);
                }
                let bytes = sample.payload().to_bytes();
                channels[name].metrics.log(&bytes);
                counts.metrics += 1;
            }
            sample = inputs.recv_async() => {
                let Ok(sample) = sample else { break };
                let Some(name) = crate::service::keys::instance_of(&prefix, "inputs", sample.key_expr().as_str()) else {
                    continue;
                };
                if !channels.contains_key(name) {
                    channels.insert(name.to_string(), open_instance(ctx, name)?);
                }
                let bytes = sample.payload().to_bytes();
                let seq = v1::InputEvent::decode(bytes.as_ref()).map_or(0, |e| e.seq);
                let ch = channels.get_mut(name).expect("inserted above");
                if ch.log_input(&bytes, seq) {
                    counts.inputs += 1;
                }
            }
            sample = states.recv_async() => {
                let Ok(sample) = sample else { break };
                let Some(name) = crate::service::keys::instance_of(&prefix, "state", sample.key_expr().as_str()) else {
                    continue;
                };
                counts.states += 1;
                if !channels.contains_key(name) {
                    channels.insert(name.to_string(), open_instance(ctx, name)?);
                }
                let ch = channels.get_mut(name).expect("inserted above");
                if !ch.asked_log {
                    // States arrive, so the inputs subscription (declared
                    // first) does too: the inputs of this episode from
                    // before it are in the daemon's episode log.
                    ch.asked_log = true;
                    let episode = v1::State::decode(sample.payload().to_bytes().as_ref()).map(|s| s.episode);
                    if let Ok(episode) = episode {
                        counts.inputs += log_earlier_inputs(client, name, episode, ch).await;
                    }
                }
                let due = ch.last_mesh.is_none_or(|t| t.elapsed() >= min_interval);
                if !due || !ch.mesh.has_sinks() {
                    continue;
                }
                let state = match v1::State::decode(sample.payload().to_bytes().as_ref()) {
                    Ok(s) => s,
                    Err(e) => {
                        counts.rejected += 1;
                        tracing::warn!(instance = name, error = %e, "undecodable state");
                        continue;
                    }
                };
                // The mesh topology comes with the info: fetch it again when
                // the level or coefficients moved on.
                let stale = ch.info.as_ref().is_none_or(|i| {
                    i.level != state.level || i.coefficient_version != state.coefficient_version
                });
                if stale {
                    match client.info(name).await {
                        Ok(info) => ch.info = Some(info),
                        Err(e) => tracing::warn!(instance = name, error = %e, "no info; keeping the last"),
                    }
                }
                let Some(info) = ch.info.as_ref() else { continue };
                match scene_update(&state, info) {
                    Ok((update, _)) => {
                        ch.mesh.log_with_meta(&update, PartialMetadata { log_time: Some(state.stepped_unix_nanos) });
                        ch.last_mesh = Some(Instant::now());
                        counts.meshes += 1;
                    }
                    Err(e) => {
                        counts.rejected += 1;
                        tracing::debug!(instance = name, error = %e, "state does not fit the info yet");
                    }
                }
                progress(&counts);
            }
        }
    }
    Ok(counts)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::proto::pack_positions;

    fn packed(p: &[[f32; 3]]) -> Vec<u8> {
        pack_positions(&p.iter().flatten().copied().collect::<Vec<f32>>())
    }

    #[test]
    fn jet_runs_blue_to_red() {
        assert_eq!(jet(0.0), [0.0, 0.0, 0.5]);
        assert_eq!(jet(1.0), [0.5, 0.0, 0.0]);
        assert_eq!(jet(0.5), [0.5, 1.0, 0.5]);
        assert_eq!(jet(f64::NAN), jet(1.0));
    }

    #[test]
    fn strain_is_the_largest_relative_stretch_of_a_vertex_edges() {
        let rest = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        // Stretch the x edge by 10 %: vertices 0 and 1 see it; the hypotenuse
        // goes from √2 to √2.21.
        let pos = [[0.0, 0.0, 0.0], [1.1, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let s = vertex_strain(&pos, &rest, &[0, 1, 2]);
        let hyp = (2.21f64).sqrt() / 2f64.sqrt() - 1.0;
        assert!((s[0] - 0.1).abs() < 1e-12 && (s[1] - 0.1).abs() < 1e-12);
        assert!((s[2] - hyp).abs() < 1e-12);
    }

    #[test]
    fn a_mesh_is_coloured_by_its_distance_from_the_reference() {
        let info = v1::InstanceInfo {
            instance: "c".into(),
            kind: "cloth".into(),
            triangles: vec![0, 1, 2],
            o_max: 2.0,
            ..Default::default()
        };
        let state = v1::State {
            instance: "c".into(),
            positions: packed(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]),
            reference_positions: packed(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.5], [0.0, 1.0, 1.0]]),
            stepped_unix_nanos: 1_700_000_000_250_000_000,
            ..Default::default()
        };
        let (u, colouring) = scene_update(&state, &info).unwrap();
        assert_eq!(colouring, Colouring::Error);
        assert_eq!(u.entities.len(), 2, "the mesh and the reference");
        let t = &u.entities[0].triangles[0];
        assert_eq!(t.indices, vec![0, 1, 2]);
        // Errors 0, 0.25, 0.5 of O_max: the scale is the largest.
        let expect = [jet(0.0), jet(0.5), jet(1.0)];
        for (c, e) in t.colors.iter().zip(expect) {
            assert_eq!([c.r, c.g, c.b], e);
        }
        let stamp = u.entities[0].timestamp.unwrap();
        assert_eq!((stamp.sec(), stamp.nsec()), (1_700_000_000, 250_000_000));
        assert_eq!(u.entities[1].triangles[0].points[2].z, 1.0);
    }

    /// A moving body is drawn where the state says it is, with the
    /// triangles the daemon gave for it.
    #[test]
    fn each_collider_is_drawn_at_the_position_the_state_gives() {
        let body = crate::sim::Collider {
            shape: crate::sim::Shape::Sphere { radius: 0.2 },
            position: [0.5, -0.3, 0.5],
            path: crate::sim::PinPath::Fixed,
            friction: 0.4,
            clearance: 0.005,
        };
        let info = v1::InstanceInfo {
            instance: "c".into(),
            kind: "cloth".into(),
            triangles: vec![0, 1, 2],
            colliders: vec![crate::proto::collider(&body)],
            ..Default::default()
        };
        let state = v1::State {
            instance: "c".into(),
            positions: packed(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]),
            collider_positions: packed(&[[0.5, -0.1, 0.7]]),
            ..Default::default()
        };
        let (u, _) = scene_update(&state, &info).unwrap();
        assert_eq!(u.entities.len(), 2, "the mesh and the sphere");
        let sphere = &u.entities[1];
        assert_eq!(sphere.id, "c/collider/0");
        let t = &sphere.triangles[0];
        let at = t.pose.unwrap().position.unwrap();
        assert_eq!([at.x, at.y, at.z], [0.5, -0.1, 0.7].map(|c: f64| c as f32 as f64));
        assert_eq!(t.points.len(), body.shape.triangles(4.0).len());
        for p in &t.points {
            let r = (p.x * p.x + p.y * p.y + p.z * p.z).sqrt();
            assert!(
                (r - 0.2).abs() < 1e-6,
                "a vertex {r} m from the centre of a 0.2 m sphere"
            );
        }
    }

    #[test]
    fn states_that_do_not_fit_the_info_are_refused_by_name() {
        let info = v1::InstanceInfo {
            kind: "cloth".into(),
            triangles: vec![0, 1, 5],
            ..Default::default()
        };
        let state = v1::State {
            positions: packed(&[[0.0; 3]; 3]),
            ..Default::default()
        };
        let e = scene_update(&state, &info).unwrap_err();
        assert!(e.contains("index 5"), "{e}");
        let state = v1::State {
            positions: vec![0; 7],
            ..Default::default()
        };
        assert!(scene_update(&state, &info).unwrap_err().contains("f32"));
    }
}
