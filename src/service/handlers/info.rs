//! `info` and `instances`: what each instance runs, its levels and how
//! ready they are.

use prost::Message;
use zenoh::query::Query;

use super::{addressed, reply_error, reply_ok, unknown_instance};
use crate::proto::v1::error::Code;
use crate::proto::{self, schema, v1, WireLevel};
use crate::service::{keys, Context, Instance};

pub(in crate::service) async fn answer_info(ctx: &Context, q: Query) {
    answer_each(ctx, q, "info", keys::info, schema::INSTANCE_INFO, |inst| {
        instance_info(inst).encode_to_vec()
    })
    .await;
}

/// The inputs of each addressed instance's latest episode so far.
pub(in crate::service) async fn answer_episode_inputs(ctx: &Context, q: Query) {
    answer_each(
        ctx,
        q,
        "episode_inputs",
        keys::episode_inputs,
        schema::EPISODE_INPUTS,
        |inst| inst.episode_inputs().encode_to_vec(),
    )
    .await;
}

/// A read-only query on `<prefix>/<instance>/<leaf>`: one reply per
/// instance the key addresses (a wildcard may address several), and an
/// error naming the unknown instance when it addresses none (every query
/// gets an answer, a wildcard matching nothing too).
async fn answer_each(
    ctx: &Context,
    q: Query,
    leaf: &str,
    key_of: fn(&str, &str) -> String,
    schema: &'static str,
    reply: impl Fn(&Instance) -> Vec<u8>,
) {
    let matched = addressed(ctx, &q, key_of);
    if matched.is_empty() {
        let key = q.key_expr().as_str();
        let message = match keys::instance_of(&ctx.prefix, leaf, key) {
            Some(name) => unknown_instance(ctx, name),
            None => format!(
                "key '{key}' matches none of {}",
                ctx.instances.keys().cloned().collect::<Vec<_>>().join(", ")
            ),
        };
        return reply_error(ctx, &q, Code::UnknownInstance, message).await;
    }
    for inst in matched {
        reply_ok(&q, key_of(&ctx.prefix, &inst.handle.name), schema, reply(inst)).await;
    }
}

fn instance_info(inst: &Instance) -> v1::InstanceInfo {
    let s = inst.handle.status();
    let c = inst.preparer.plan();
    let levels = c
        .levels
        .iter()
        .map(|&l| {
            let p = inst.preparer.get(l, c.method);
            v1::LevelInfo {
                level: Some(l.to_wire()),
                predicted_error: p.as_ref().map(|p| p.predicted_error),
                dt: p.as_ref().map_or(0.0, |p| p.dt),
                ready: p.is_some(),
                predicted_error_under_input: inst.preparer.touched_prediction(l, c.method).map(|t| t.error),
            }
        })
        .collect();
    v1::InstanceInfo {
        instance: c.name.clone(),
        scene: c.scene_name().to_string(),
        description: c.description().to_string(),
        level: Some(s.level.to_wire()),
        reference: Some(c.reference().to_wire()),
        levels,
        method: s.method.to_string(),
        integrator: c.integrator.name().to_string(),
        dt: s.dt,
        coefficients: Some(proto::coefficients(&s.material)),
        coefficient_version: s.coefficient_version,
        triangles: s.topology.triangles.iter().flatten().copied().collect(),
        pinned: s.pinned.clone(),
        publish_hz: c.publish_hz,
        o_max: s.o_max.unwrap_or(0.0),
        shadow_reference: c.shadow_reference,
        paused: s.paused,
        kind: c.kind_name().to_string(),
        simulation_points: s.simulation_points.as_deref().cloned().unwrap_or_default(),
        cloud_points: s.cloud_points as u32,
        halted: s.halted.as_deref().unwrap_or_default().to_string(),
        colliders: c.colliders().iter().map(proto::collider).collect(),
        material_uv: s
            .topology
            .material_uv()
            .map(|uv| proto::pack_positions(&uv.iter().flatten().map(|&c| c as f32).collect::<Vec<f32>>()))
            .unwrap_or_default(),
        rest_positions: proto::pack_positions(
            &s.topology
                .rest_positions
                .iter()
                .flatten()
                .map(|&c| c as f32)
                .collect::<Vec<f32>>(),
        ),
    }
}

pub(in crate::service) async fn answer_list(ctx: &Context, q: Query) {
    let list = v1::InstanceList {
        daemon: ctx.daemon.clone(),
        instances: ctx
            .instances
            .values()
            .map(|inst| {
                let s = inst.handle.status();
                let c = inst.preparer.plan();
                v1::InstanceSummary {
                    instance: c.name.clone(),
                    scene: c.scene_name().to_string(),
                    level: Some(s.level.to_wire()),
                    method: s.method.to_string(),
                    publish_hz: c.publish_hz,
                }
            })
            .collect(),
    };
    reply_ok(
        &q,
        keys::instances(&ctx.prefix),
        schema::INSTANCE_LIST,
        list.encode_to_vec(),
    )
    .await;
}
