//! `switch`: a level (or the cheapest meeting an error bound) prepared and
//! taken over by the running instance, one at a time per instance with a
//! bounded queue.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::Instant;

use prost::Message;
use zenoh::query::Query;

use super::{decode, refuse, reply_error, reply_ok, target};
use crate::engine::SwitchOutcome;
use crate::estimate::Method;
use crate::plan::{Level, PrepareError, Prepared};
use crate::proto::v1::error::Code;
use crate::proto::{self, schema, v1, WireLevel};
use crate::service::prepare::{
    apply_in_place, estimate_in_place, on_client_thread, prepare, prepare_first, switch_at_once, switch_to,
    Interruption, Ready, SwitchFailed, Unprepared, Waiting,
};
use crate::service::request::{self, SwitchTarget};
use crate::service::{keys, Context, Instance, MAX_PENDING_SWITCHES};

/// Holds one of an instance's bounded switch slots (see
/// [`MAX_PENDING_SWITCHES`]); frees it when dropped.
struct SwitchSlot<'a>(&'a AtomicUsize);

impl<'a> SwitchSlot<'a> {
    fn take(pending: &'a AtomicUsize) -> Option<SwitchSlot<'a>> {
        pending
            .fetch_update(Ordering::AcqRel, Ordering::Acquire, |n| {
                (n < MAX_PENDING_SWITCHES).then_some(n + 1)
            })
            .ok()
            .map(|_| SwitchSlot(pending))
    }
}

impl Drop for SwitchSlot<'_> {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::AcqRel);
    }
}

pub(in crate::service) async fn answer_switch(ctx: Arc<Context>, q: Query) {
    let arrived = Instant::now();
    let checked = target(&ctx, &q, "switch").and_then(|inst| {
        let req: v1::SwitchRequest = decode(&q, schema::SWITCH_REQUEST)?;
        Ok((inst, request::switch_plan(inst.preparer.plan(), &req)?))
    });
    let (inst, plan) = match checked {
        Ok(c) => c,
        Err(r) => return refuse(&ctx, &q, r).await,
    };
    // A bounded queue per instance: a flood of switches is refused here,
    // cheaply, instead of piling up behind the one being applied.
    let Some(_slot) = SwitchSlot::take(&inst.pending_switches) else {
        return reply_error(
            &ctx,
            &q,
            Code::Busy,
            format!(
                "{MAX_PENDING_SWITCHES} switches of '{}' are already in progress or waiting; retry when one completes",
                inst.handle.name
            ),
        )
        .await;
    };
    let config = inst.preparer.plan().clone();
    let method = plan.method;
    let level = match plan.target {
        SwitchTarget::Level(level) => level,
        SwitchTarget::MaxError(bound) => match cheapest_meeting(inst, method, bound, touched(inst)).await {
            Ok(level) => level,
            Err(message) => return reply_error(&ctx, &q, Code::NoLevelMeetsError, message).await,
        },
    };
    if *ctx.closing.borrow() {
        return reply_error(&ctx, &q, Code::Unavailable, "the daemon is shutting down").await;
    }
    let was_ready = inst.preparer.get(level, method).is_some();
    let _guard = inst.switching.lock().await;
    if plan.at_once && !was_ready {
        match switch_at_once(&inst.handle, inst.preparer.clone(), level).await {
            Ok(o) => {
                tokio::spawn(refine(
                    ctx.clone(),
                    config.name.clone(),
                    level,
                    method,
                    o.coefficient_version,
                    None,
                ));
                return reply_switched(&ctx, &q, inst, &o, arrived, false, true).await;
            }
            Err(e) => return refuse_switch(&ctx, &q, e).await,
        }
    }
    // A level whose estimate is slow to make (`fit`) goes live with the
    // quick methods' best, the estimate following in place if better. That
    // is waited for `switch_budget` at most: past it (a reference still to
    // record on a busy machine) the level goes live with the scene's own
    // coefficients, and what the switch waited for follows in place.
    // A level prepared already is only built, and always waited for.
    let mut first = tokio::spawn(prepare_first(inst.preparer.clone(), level, method));
    let waited = match was_ready {
        true => Ok((&mut first).await),
        false => tokio::time::timeout(ctx.switch_budget, &mut first).await,
    };
    let first = match waited {
        Ok(joined) => joined,
        Err(_) => {
            tracing::info!(
                instance = %config.name,
                %level,
                %method,
                budget_s = ctx.switch_budget.as_secs_f64(),
                "the estimate is not ready within the switch budget; live with the scene's coefficients first"
            );
            return match switch_at_once(&inst.handle, inst.preparer.clone(), level).await {
                Ok(o) => {
                    tokio::spawn(follow(
                        ctx.clone(),
                        config.name.clone(),
                        level,
                        method,
                        o.coefficient_version,
                        first,
                    ));
                    reply_switched(&ctx, &q, inst, &o, arrived, false, true).await
                }
                Err(e) => refuse_switch(&ctx, &q, e).await,
            };
        }
    };
    let (ready, provisional) = match first.map_err(|e| joined_error(level, method, e)).and_then(|r| r) {
        Ok(p) => p,
        Err(e) => return refuse_switch(&ctx, &q, e.into()).await,
    };
    let cached = !provisional && (was_ready || ready.prepared.cached);
    let live_error = ready.prepared.predicted_error;
    let live = ready.prepared.clone();
    match switch_to(&inst.handle, ready, inst.preparer.plan().switch_settle).await {
        Ok(o) => {
            inst.predict_under_input(&live);
            if provisional {
                tokio::spawn(refine(
                    ctx.clone(),
                    config.name.clone(),
                    level,
                    method,
                    o.coefficient_version,
                    Some(live_error),
                ));
            }
            reply_switched(&ctx, &q, inst, &o, arrived, cached, provisional).await
        }
        Err(e) => refuse_switch(&ctx, &q, e.into()).await,
    }
}

/// Refuse a switch that did not go live, with its wire code.
async fn refuse_switch(ctx: &Context, q: &Query, e: SwitchFailed) {
    reply_error(ctx, q, switch_code(&e), e.to_string()).await
}

/// The wire code of a switch that did not go live. A level the engine did
/// not take over is unavailable, except in an at-once switch, which reports
/// it as the level's preparation failing.
fn switch_code(e: &SwitchFailed) -> Code {
    match e {
        SwitchFailed::Unprepared(Unprepared::Level(PrepareError::Unstable { .. })) => Code::Unstable,
        SwitchFailed::Unprepared(Unprepared::Level(PrepareError::NotAllowed { .. })) => Code::LevelNotAllowed,
        SwitchFailed::Unprepared(_) | SwitchFailed::AtOnce { .. } => Code::EstimationFailed,
        SwitchFailed::Handover(_) => Code::Unavailable,
    }
}

/// Count the switch and answer it.
async fn reply_switched(
    ctx: &Context,
    q: &Query,
    inst: &Instance,
    o: &SwitchOutcome,
    arrived: Instant,
    cached: bool,
    refining: bool,
) {
    let name = inst.handle.name.as_str();
    let under_input = o
        .predicted_error
        .and_then(|_| inst.preparer.touched_prediction(o.level, o.method).map(|t| t.error));
    tracing::info!(instance = %name, from = %o.previous, to = %o.level, method = %o.method, refining, "switched");
    let reply = v1::SwitchReply {
        instance: name.to_string(),
        previous: Some(o.previous.to_wire()),
        level: Some(o.level.to_wire()),
        method: o.method.to_string(),
        coefficients: Some(proto::coefficients(&o.material)),
        predicted_error: o.predicted_error,
        dt: o.dt,
        seconds: arrived.elapsed().as_secs_f64(),
        cached,
        coefficient_version: o.coefficient_version,
        frame: o.frame,
        refining,
        predicted_error_under_input: under_input,
    };
    if let Some(c) = ctx.telemetry.instance(name) {
        c.switches.fetch_add(1, Ordering::Relaxed);
    }
    reply_ok(
        q,
        keys::switch(&ctx.prefix, name),
        schema::SWITCH_REPLY,
        reply.encode_to_vec(),
    )
    .await;
}

/// After an at-once or provisional switch: the requested method's
/// estimate, live in place unless the instance is switched again first or
/// (provisional) its predicted error is not below `live_error`'s.
async fn refine(ctx: Arc<Context>, name: String, level: Level, method: Method, version: u32, live_error: Option<f64>) {
    if let Some(inst) = ctx.instances.get(&name) {
        // Not counted as a switch: the client's was.
        estimate_in_place(inst, level, method, version, live_error).await;
    }
}

/// After a switch that went live past its budget with the scene's own
/// coefficients (at `version`): what it waited for (`first`, the
/// preparation [`prepare_first`] started) goes live in place, then, if
/// that was provisional, the requested method's estimate as [`refine`]
/// does. Nothing goes live once the instance is switched again.
async fn follow(
    ctx: Arc<Context>,
    name: String,
    level: Level,
    method: Method,
    version: u32,
    first: tokio::task::JoinHandle<Result<(Ready, bool), Unprepared>>,
) {
    let Some(inst) = ctx.instances.get(&name) else {
        return;
    };
    let (ready, provisional) = match first.await.map_err(|e| joined_error(level, method, e)).and_then(|r| r) {
        Ok(p) => p,
        Err(e) => {
            tracing::error!(instance = %name, %level, %method, "preparing the level a switch went live at: {e}");
            return;
        }
    };
    let live_error = ready.prepared.predicted_error;
    // The live coefficients have no prediction: whatever was prepared is
    // better known than they are.
    let applied = apply_in_place(inst, level, method, version, None, Ok(ready)).await;
    if let (Some(version), true) = (applied, provisional) {
        estimate_in_place(inst, level, method, version, Some(live_error)).await;
    }
}

/// A preparation's task that panicked or was cancelled, as its error.
fn joined_error(level: Level, method: Method, e: tokio::task::JoinError) -> Unprepared {
    Unprepared::Interrupted {
        level,
        method,
        source: Interruption::Joined(e),
    }
}

/// A client's input acts on the instance now (its latest metrics say so).
fn touched(inst: &Instance) -> bool {
    inst.handle.metrics.borrow().as_ref().is_some_and(|m| m.touched)
}

/// The coarsest allowed level whose predicted error is at most `bound`:
/// every level's prediction is needed, so they are prepared cheapest first
/// until one meets it. `under_input` (a client touches the cloth): by the
/// levels' predictions under input, made where missing (a reference run per
/// standard drag, once per instance, then a run per drag per level). Err:
/// why none does (the best one's error).
async fn cheapest_meeting(inst: &Instance, method: Method, bound: f64, under_input: bool) -> Result<Level, String> {
    let config = inst.preparer.plan();
    let mut levels = config.levels.clone();
    levels.sort_by_key(|l| l.nodes());
    let mut best: Option<(Level, f64)> = None;
    for l in levels {
        let predicted = match prepare(Waiting::Client, inst.preparer.clone(), l, method).await {
            Ok(Ready { prepared: p, .. }) if under_input => predict_under_input(inst, p).await,
            Ok(Ready { prepared: p, .. }) => Ok(p.predicted_error),
            Err(err) => Err(err.to_string()),
        };
        match predicted {
            Ok(error) => {
                if error <= bound {
                    return Ok(l);
                }
                if best.is_none_or(|(_, b)| error < b) {
                    best = Some((l, error));
                }
            }
            Err(err) => tracing::warn!(instance = %config.name, %l, "skipped for max_error: {err}"),
        }
    }
    let best = best.map_or("no level could be prepared".to_string(), |(l, b)| {
        format!("the best is {l} at {:.2} %", 100.0 * b)
    });
    let which = if under_input {
        "prediction under input (a client touches it)"
    } else {
        "predicted error"
    };
    Err(format!(
        "no allowed level of '{}' has a {which} ≤ {:.2} %; {best}",
        config.name,
        100.0 * bound
    ))
}

/// `prepared`'s prediction under input, made now if need be, on a thread in
/// the class of work a client waits for.
async fn predict_under_input(inst: &Instance, prepared: Arc<Prepared>) -> Result<f64, String> {
    let preparer = inst.preparer.clone();
    match on_client_thread(move || preparer.predict_touched(&prepared, &|| false)).await {
        Ok(Ok(Some(t))) => Ok(t.error),
        Ok(Ok(None)) => Err("a surface takes no input".into()),
        Ok(Err(e)) => Err(e.to_string()),
        Err(e) => Err(format!("the prediction: {e}")),
    }
}
