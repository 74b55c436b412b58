//! The per-instance publishers: every state and metrics frame the engine
//! hands out, encoded once and put on the bus (states are skipped while
//! nobody listens, never the two states of a switch).

use std::sync::Arc;

use prost::Message;
use tokio::sync::watch;

use crate::engine::{InstanceHandle, StateFrame};
use crate::proto;

pub(super) async fn publish_states(
    handle: InstanceHandle,
    publisher: zenoh::pubsub::Publisher<'static>,
    closing: watch::Receiver<bool>,
) {
    let mut states = handle.states.clone();
    let mut transitions = handle.transitions.lock().await;
    let mut closing = closing;
    let mut buf = Vec::new();
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
        if !frame.transition && !publisher.matching_status().await.map(|m| m.matching()).unwrap_or(true) {
            continue;
        }
        buf.clear();
        proto::state_message(&handle.name, &frame)
            .encode(&mut buf)
            .expect("Vec grows");
        if let Err(e) = publisher.put(buf.clone()).await {
            tracing::warn!(instance = %handle.name, "publishing a state: {e}");
        }
    }
}

pub(super) async fn publish_metrics(
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
                let bytes = proto::metrics_message(&handle.name, &m).encode_to_vec();
                if let Err(e) = publisher.put(bytes).await {
                    tracing::warn!(instance = %handle.name, "publishing metrics: {e}");
                }
            }
        }
    }
}
