//! The per-instance publishers: every state and metrics frame the engine
//! hands out, encoded once and put on the bus (states are skipped while
//! nobody listens, never the two states of a switch).

use std::sync::atomic::Ordering;
use std::sync::Arc;

use prost::Message;
use tokio::sync::watch;

use super::Context;
use crate::engine::{InstanceHandle, StateFrame};
use crate::proto;

pub(super) async fn publish_states(
    ctx: Arc<Context>,
    handle: InstanceHandle,
    publisher: zenoh::pubsub::Publisher<'static>,
    closing: watch::Receiver<bool>,
) {
    let mut states = handle.states.clone();
    let mut transitions = handle.transitions.lock().await;
    let mut closing = closing;
    let mut buf = Vec::new();
    let counters = ctx.telemetry.instance(&handle.name);
    loop {
        let frame: Arc<StateFrame> = tokio::select! {
            biased;
            _ = closing.changed() => break,
            Some(f) = transitions.recv() => f,
            changed = states.changed() => {
                if changed.is_err() {
                    break;
                }
                let Some(f) = states.borrow_and_update().clone() else { continue };
                // Transition frames go out through `transitions`, in order.
                if f.transition {
                    continue;
                }
                f
            }
        };
        // Skip the encoding when nobody listens.
        let matching = publisher.matching_status().await.map(|m| m.matching()).unwrap_or(true);
        if let Some(c) = counters {
            c.state_subscribed.store(matching, Ordering::Relaxed);
        }
        if !frame.transition && !matching {
            continue;
        }
        buf.clear();
        proto::state_message(&handle.name, &frame)
            .encode(&mut buf)
            .expect("Vec grows");
        match publisher.put(buf.clone()).await {
            Ok(()) => {
                if let Some(c) = counters {
                    c.states_published.fetch_add(1, Ordering::Relaxed);
                }
            }
            Err(e) => tracing::warn!(instance = %handle.name, "publishing a state: {e}"),
        }
    }
}

pub(super) async fn publish_metrics(
    ctx: Arc<Context>,
    handle: InstanceHandle,
    publisher: zenoh::pubsub::Publisher<'static>,
    closing: watch::Receiver<bool>,
) {
    let mut metrics = handle.metrics.clone();
    let mut closing = closing;
    loop {
        tokio::select! {
            _ = closing.changed() => break,
            changed = metrics.changed() => {
                if changed.is_err() {
                    break;
                }
                let Some(m) = metrics.borrow_and_update().clone() else { continue };
                let mut message = proto::metrics_message(&handle.name, &m);
                message.predicted_error_under_input = under_input(&ctx, &handle.name, &m);
                let bytes = message.encode_to_vec();
                match publisher.put(bytes).await {
                    Ok(()) => ctx.telemetry.metrics_published(&handle.name),
                    Err(e) => tracing::warn!(instance = %handle.name, "publishing metrics: {e}"),
                }
            }
        }
    }
}

/// Put every input that took effect on `<prefix>/<instance>/inputs`, in
/// order.
pub(super) async fn publish_inputs(
    inst: Arc<super::Instance>,
    publisher: zenoh::pubsub::Publisher<'static>,
    closing: watch::Receiver<bool>,
) {
    let handle = &inst.handle;
    let mut applied = handle.applied.lock().await;
    let mut closing = closing;
    loop {
        let a = tokio::select! {
            biased;
            _ = closing.changed() => break,
            a = applied.recv() => match a {
                Some(a) => a,
                None => break,
            },
        };
        let event = proto::input_event(&handle.name, &a);
        // Logged before it is published: a recorder that subscribed, then
        // queried the log, finds every input in one or the other.
        inst.episode_log.lock().unwrap_or_else(|e| e.into_inner()).push(&event);
        let bytes = event.encode_to_vec();
        if let Err(e) = publisher.put(bytes).await {
            tracing::warn!(instance = %handle.name, "publishing an input: {e}");
        }
    }
}

/// The live level's prediction under input, while its coefficients are the
/// prepared ones it was made for (they have a predicted error).
fn under_input(ctx: &Context, name: &str, m: &crate::engine::MetricsFrame) -> Option<f64> {
    m.predicted_error?;
    let inst = ctx.instances.get(name)?;
    inst.preparer.touched_prediction(m.level, m.method).map(|t| t.error)
}
