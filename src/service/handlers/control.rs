//! `control`: pause, resume and reset.

use std::sync::Arc;
use std::time::Duration;

use prost::Message;
use tokio::sync::oneshot;
use zenoh::query::Query;

use super::{decode, refuse, reply_error, reply_ok, target};
use crate::engine::Command;
use crate::proto::v1::error::Code;
use crate::proto::{schema, v1};
use crate::service::request;
use crate::service::{keys, Context};

pub(in crate::service) async fn answer_control(ctx: Arc<Context>, q: Query) {
    let checked = target(&ctx, &q, "control").and_then(|inst| {
        let req: v1::ControlRequest = decode(&q, schema::CONTROL_REQUEST)?;
        Ok((inst, request::control_action(&req)?))
    });
    let (inst, action) = match checked {
        Ok(c) => c,
        Err(r) => return refuse(&ctx, &q, r).await,
    };
    use v1::control_request::Action;
    let (tx, rx) = oneshot::channel();
    let command = match action {
        Action::Pause => Command::Pause {
            paused: true,
            reply: tx,
        },
        Action::Resume => Command::Pause {
            paused: false,
            reply: tx,
        },
        Action::Reset | Action::Unspecified => Command::Reset { reply: tx },
    };
    if let Err(e) = inst.handle.send(command) {
        return reply_error(&ctx, &q, Code::Unavailable, e.to_string()).await;
    }
    match tokio::time::timeout(Duration::from_secs(5), rx).await {
        Ok(Ok(o)) => {
            let reply = v1::ControlReply {
                instance: inst.handle.name.clone(),
                paused: o.paused,
                frame: o.frame,
            };
            reply_ok(
                &q,
                keys::control(&ctx.prefix, &inst.handle.name),
                schema::CONTROL_REPLY,
                reply.encode_to_vec(),
            )
            .await;
        }
        _ => reply_error(&ctx, &q, Code::Unavailable, "the engine did not apply the command").await,
    }
}
