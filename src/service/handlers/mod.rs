//! The queryables' answers: one file per request kind, and what they
//! share (replies, refusals, which instance a key addresses).

mod control;
mod info;
mod input;
mod switch;

use std::sync::Arc;

use prost::Message;
use zenoh::query::Query;

use super::request::{self, Refusal};
use super::{encoding, Context, Instance, MAX_REQUESTS_IN_FLIGHT};
use crate::proto::v1::error::Code;
use crate::proto::{self, schema};

pub(super) use control::answer_control;
pub(super) use info::{answer_episode_inputs, answer_info, answer_list};
pub(super) use input::{finish_input, submit_input};
pub(super) use switch::answer_switch;

pub(super) async fn reply_error(ctx: &Context, q: &Query, code: Code, message: impl Into<String>) {
    let message = message.into();
    ctx.telemetry.refused(code);
    tracing::info!(key = %q.key_expr(), ?code, "refused: {message}");
    let e = proto::error(code, message);
    if let Err(err) = q.reply_err(e.encode_to_vec()).encoding(encoding(schema::ERROR)).await {
        tracing::warn!("sending an error reply: {err}");
    }
}

pub(super) async fn reply_ok(q: &Query, key: String, schema: &'static str, bytes: Vec<u8>) {
    if let Err(err) = q.reply(key, bytes).encoding(encoding(schema)).await {
        tracing::warn!("sending a reply: {err}");
    }
}

pub(super) fn unknown_instance(ctx: &Context, name: &str) -> String {
    format!(
        "no instance '{name}' on this daemon; it runs {}",
        ctx.instances.keys().cloned().collect::<Vec<_>>().join(", ")
    )
}

/// Which instances a query's key expression names.
pub(super) fn addressed<'a>(ctx: &'a Context, q: &Query, key_of: fn(&str, &str) -> String) -> Vec<&'a Arc<Instance>> {
    ctx.instances
        .iter()
        .filter(|(name, _)| {
            zenoh::key_expr::KeyExpr::new(key_of(&ctx.prefix, name)).is_ok_and(|k| k.intersects(q.key_expr()))
        })
        .map(|(_, i)| i)
        .collect()
}

/// Decode a request's payload (see [`request::decode`]).
pub(super) fn decode<M: Message + Default>(q: &Query, schema: &str) -> Result<M, Refusal> {
    let encoding = q.encoding().map(|e| e.to_string());
    let payload = q.payload().map(|p| p.to_bytes());
    request::decode(schema, encoding.as_deref(), payload.as_deref())
}

/// The instance a request for `<prefix>/<instance>/<leaf>` addresses.
pub(super) fn target<'a>(ctx: &'a Context, q: &Query, leaf: &str) -> Result<&'a Arc<Instance>, Refusal> {
    let name = request::instance_name(
        &ctx.prefix,
        leaf,
        q.key_expr().as_str(),
        |n| ctx.instances.contains_key(n),
        || ctx.instances.keys().cloned().collect::<Vec<_>>().join(", "),
    )?;
    Ok(&ctx.instances[name])
}

/// Refuse a request because too many are being handled.
pub(in crate::service) async fn busy(ctx: &Context, q: Query) {
    let message = format!("the daemon is handling {MAX_REQUESTS_IN_FLIGHT} requests; retry shortly");
    reply_error(ctx, &q, Code::Busy, message).await
}

/// Answer a refusal.
pub(super) async fn refuse(ctx: &Context, q: &Query, r: Refusal) {
    reply_error(ctx, q, r.code, r.message).await
}
