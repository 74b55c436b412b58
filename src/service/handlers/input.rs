//! `input`: a client's touch on a cloth (grab, move, release, pin moves,
//! wind, impulses).
//!
//! Inputs must reach the engine in the order they arrive (a grab before its
//! moves), so the answering loop checks and queues each one itself
//! ([`submit_input`]: rate limit, decode, range checks, then the engine's
//! command channel, which is FIFO) and only the wait for the engine's
//! answer runs as a task ([`finish_input`]).

use std::sync::Arc;
use std::time::{Duration, Instant};

use prost::Message;
use tokio::sync::oneshot;
use zenoh::query::Query;

use super::{decode, reply_error, reply_ok, target};
use crate::engine::{Command, InputOutcome};
use crate::proto::v1::error::Code;
use crate::proto::{schema, v1, WireLevel};
use crate::service::request::{self, Refusal};
use crate::service::{keys, Context, Instance};
use crate::touch::TouchError;

/// An input queued to its instance's engine.
pub(in crate::service) struct Submitted {
    instance: Arc<Instance>,
    reply: oneshot::Receiver<Result<InputOutcome, TouchError>>,
}

/// Check `q` and queue its input to the engine, or say why not.
pub(in crate::service) fn submit_input(ctx: &Context, q: &Query) -> Result<Submitted, Refusal> {
    let inst = target(ctx, q, "input")?;
    if !inst.input_allowed(Instant::now()) {
        return Err(Refusal::new(
            Code::Busy,
            format!(
                "more than {} inputs/s (burst {}) to '{}'; send fewer (input.rate)",
                ctx.input.rate, ctx.input.burst, inst.handle.name
            ),
        ));
    }
    let req: v1::InputRequest = decode(q, schema::INPUT_REQUEST)?;
    let input = request::input(&req)?;
    let (tx, rx) = oneshot::channel();
    inst.handle
        .send(Command::Input { input, reply: tx })
        .map_err(|e| Refusal::new(Code::Unavailable, e.to_string()))?;
    Ok(Submitted {
        instance: inst.clone(),
        reply: rx,
    })
}

/// Answer a queued input with what the engine did.
pub(in crate::service) async fn finish_input(ctx: Arc<Context>, q: Query, submitted: Submitted) {
    let name = submitted.instance.handle.name.clone();
    match tokio::time::timeout(Duration::from_secs(5), submitted.reply).await {
        Ok(Ok(Ok(o))) => {
            let reply = v1::InputReply {
                instance: name.clone(),
                frame: o.frame,
                time: o.time,
                grabs: o.grabs,
                level: Some(o.level.to_wire()),
            };
            reply_ok(
                &q,
                keys::input(&ctx.prefix, &name),
                schema::INPUT_REPLY,
                reply.encode_to_vec(),
            )
            .await;
        }
        Ok(Ok(Err(e))) => {
            let code = match e {
                TouchError::Unstable { .. } => Code::Unstable,
                _ => Code::BadRequest,
            };
            reply_error(&ctx, &q, code, e.to_string()).await
        }
        _ => reply_error(&ctx, &q, Code::Unavailable, "the engine did not apply the input").await,
    }
}
