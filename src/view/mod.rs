//! `lodcloth view`: a web server that joins the zenoh network and serves a
//! page (embedded in the binary) showing the instances live in WebGL.
//!
//! One zenoh subscription per key feeds every browser: the server keeps only
//! the latest state and metrics of each instance (a `watch` channel) and each
//! WebSocket sends the latest one when it is free, so a slow browser skips
//! frames and never holds back the daemon, the bus or other browsers.
//!
//! WebSocket protocol (`/ws`):
//! - server → page, binary: one tag byte (1 State, 2 Metrics, 3
//!   InstanceInfo) and the protobuf message exactly as on the bus;
//! - server → page, text JSON: `hello`, `instances` (liveliness; a vanished
//!   instance stays listed with `alive: false`), `switch` replies, `error`;
//! - page → server, text JSON: `{"op":"select","instance":…}`,
//!   `{"op":"info"}`, `{"op":"switch","id":…,"level":"16x16"}` or
//!   `{…,"max_error":0.05}` (optional `"method"`), and `{"op":"ack"}` for
//!   every state received;
//! - page → server, live input on the selected instance (issue 22; grids
//!   only, a surface refuses): `{"op":"grab","id":7,"u":0.5,"v":0.8,
//!   "radius":0.05}` with optional `"target":[x,y,z]` (m; absent: where the
//!   patch is now), `"stiffness"` (N/m, default 20) and `"damping"` (N·s/m,
//!   default 0.2); `{"op":"move","id":7,"target":[x,y,z]}`;
//!   `{"op":"release","id":7}`; `{"op":"release_all"}`. Each one sent is
//!   answered by `{"type":"input","op":…,"id":…,"ok":true,"frame":…,
//!   "time":…,"grabs":[…],"level":"16x16","replaced":n,"message":…}` or
//!   `{…,"ok":false,"code":"CODE_UNSTABLE","message":…}` (the daemon's
//!   code and reason; a malformed op is answered `CODE_BAD_REQUEST` naming
//!   the field, without reaching the bus). Grabs a connection still holds
//!   when it closes are released.
//!
//! Flow control: at most [`MAX_IN_FLIGHT`] states are sent and not yet
//! acknowledged; the next one is the latest when an ack comes back. Socket
//! buffers therefore never hold a backlog of old states: a slow page (or a
//! slow network) sees fewer, fresh states, never a growing delay. Inputs
//! go the other way the same way: one at a time per connection, in order
//! ([`InputQueue`]); a grab or release always goes, while a move still
//! waiting is replaced by a newer move of the same grab (`replaced` counts
//! them), so a slow bus delays the drag by one round trip, never a backlog.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::future::Future;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use axum::body::Bytes;
use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::extract::State;
use axum::response::{Html, IntoResponse};
use axum::routing::get;
use axum::{Json, Router};
use prost::Message as _;
use serde::{Deserialize, Serialize};
use tokio::sync::{mpsc, watch};
use zenoh::sample::SampleKind;

mod input;

use crate::plan::Level;
use crate::proto::{v1, WireLevel};
use crate::service::client::{Client, ClientError, ClientOptions};
use crate::service::keys;
use crate::touch::Input;

/// The page, served at `/`.
const INDEX_HTML: &str = include_str!("index.html");

/// Tag bytes of binary WebSocket frames.
pub mod tag {
    pub const STATE: u8 = 1;
    pub const METRICS: u8 = 2;
    pub const INFO: u8 = 3;
}

/// States sent to a page and not yet acknowledged, at most.
pub const MAX_IN_FLIGHT: u32 = 2;

/// How long a switch from the page may take (an unprepared level is
/// estimated first).
const SWITCH_TIMEOUT: Duration = Duration::from_secs(120);

/// What went wrong starting the viewer.
#[derive(Debug, thiserror::Error)]
pub enum ViewError {
    #[error("zenoh: {0}")]
    Zenoh(String),
    #[error("listening on {addr}: {source}")]
    Listen { addr: SocketAddr, source: std::io::Error },
    #[error(transparent)]
    Client(#[from] ClientError),
}

/// One instance seen through liveliness.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Entry {
    pub name: String,
    pub alive: bool,
}

/// The latest message of one kind for one instance and its number.
type Latest = watch::Sender<Option<(u64, Bytes)>>;

struct Feed {
    state: Latest,
    metrics: Latest,
}

/// Shared by every connection: the bus client, the instance list and the
/// latest frames.
struct Hub {
    client: Client,
    connect: Vec<String>,
    instances: watch::Sender<BTreeMap<String, bool>>,
    feeds: Mutex<HashMap<String, Arc<Feed>>>,
    /// Frames a connection skipped because it was still sending (all
    /// connections, since start).
    skipped: AtomicU64,
    sent: AtomicU64,
    shutdown: watch::Receiver<bool>,
}

impl Hub {
    fn feed(&self, instance: &str) -> Arc<Feed> {
        let mut feeds = self.feeds.lock().unwrap_or_else(|e| e.into_inner());
        feeds
            .entry(instance.to_string())
            .or_insert_with(|| {
                Arc::new(Feed {
                    state: watch::channel(None).0,
                    metrics: watch::channel(None).0,
                })
            })
            .clone()
    }

    /// Keep `payload` as the latest message of `instance` (called on
    /// zenoh's threads; a copy and a swap).
    fn put(&self, instance: &str, tag: u8, payload: &[u8]) {
        let mut framed = Vec::with_capacity(payload.len() + 1);
        framed.push(tag);
        framed.extend_from_slice(payload);
        let framed = Bytes::from(framed);
        let feed = self.feed(instance);
        let target = if tag == tag::STATE { &feed.state } else { &feed.metrics };
        // Numbered per feed, so a connection can count what it skipped.
        target.send_modify(|latest| {
            let seq = latest.as_ref().map_or(0, |(s, _)| s + 1);
            *latest = Some((seq, framed));
        });
    }

    fn entries(&self) -> Vec<Entry> {
        self.instances
            .borrow()
            .iter()
            .map(|(name, &alive)| Entry {
                name: name.clone(),
                alive,
            })
            .collect()
    }
}

/// Where the viewer listens and what it joins.
#[derive(Debug, Clone)]
pub struct ViewOptions {
    /// HTTP address of the page.
    pub listen: SocketAddr,
    /// How to join zenoh: endpoints (empty: discover by multicast), mode,
    /// credentials.
    pub zenoh: ClientOptions,
    /// Key prefix of the daemon(s).
    pub prefix: String,
}

/// Serve the page until `shutdown` completes. `ready` receives the bound
/// address (the port may have been 0).
pub async fn run(
    options: ViewOptions,
    ready: impl FnOnce(SocketAddr),
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> Result<(), ViewError> {
    let client = Client::open(&options.zenoh, &options.prefix).await?;
    let prefix = options.prefix.clone();
    let (stop_tx, stop_rx) = watch::channel(false);
    let hub = Arc::new(Hub {
        client,
        connect: options.zenoh.connect.clone(),
        instances: watch::channel(BTreeMap::new()).0,
        feeds: Mutex::new(HashMap::new()),
        skipped: AtomicU64::new(0),
        sent: AtomicU64::new(0),
        shutdown: stop_rx,
    });
    let zerr = |e: zenoh::Error| ViewError::Zenoh(e.to_string());
    let session = hub.client.session.clone();
    let weak = Arc::downgrade(&hub);
    let p = prefix.clone();
    let _alive = session
        .liveliness()
        .declare_subscriber(keys::alive(&prefix, "*"))
        .history(true)
        .callback(move |sample| {
            let (Some(hub), Some(name)) = (weak.upgrade(), keys::alive_instance(&p, sample.key_expr().as_str())) else {
                return;
            };
            let alive = sample.kind() == SampleKind::Put;
            hub.instances
                .send_if_modified(|m| m.insert(name.to_string(), alive) != Some(alive));
        })
        .await
        .map_err(zerr)?;
    let mut subscribers = Vec::new();
    for (leaf, t) in [("state", tag::STATE), ("metrics", tag::METRICS)] {
        let weak = Arc::downgrade(&hub);
        let p = prefix.clone();
        let key = format!("{prefix}/*/{leaf}");
        subscribers.push(
            session
                .declare_subscriber(key)
                .callback(move |sample| {
                    let (Some(hub), Some(name)) =
                        (weak.upgrade(), keys::instance_of(&p, leaf, sample.key_expr().as_str()))
                    else {
                        return;
                    };
                    hub.put(name, t, &sample.payload().to_bytes());
                })
                .await
                .map_err(zerr)?,
        );
    }

    let app = Router::new()
        .route("/", get(|| async { Html(INDEX_HTML) }))
        .route("/ws", get(upgrade))
        .route("/api/instances", get(instances))
        .route("/api/stats", get(stats))
        .with_state(hub.clone());
    let listener = tokio::net::TcpListener::bind(options.listen)
        .await
        .map_err(|source| ViewError::Listen {
            addr: options.listen,
            source,
        })?;
    let addr = listener.local_addr().map_err(|source| ViewError::Listen {
        addr: options.listen,
        source,
    })?;
    tracing::info!(%addr, connect = ?options.zenoh.connect, prefix = %prefix, "serving the viewer on http://{addr}/");
    ready(addr);
    let served = axum::serve(listener, app)
        .with_graceful_shutdown(async move {
            shutdown.await;
            // Upgraded WebSockets are not the server's to wait for: tell them.
            let _ = stop_tx.send(true);
        })
        .await;
    drop(subscribers);
    let _ = hub.client.session.close().await;
    served.map_err(|source| ViewError::Listen {
        addr: options.listen,
        source,
    })
}

async fn instances(State(hub): State<Arc<Hub>>) -> Json<Vec<Entry>> {
    Json(hub.entries())
}

#[derive(Serialize)]
struct Stats {
    /// Frames sent to browsers.
    sent: u64,
    /// Frames replaced by a newer one before a browser was ready for them.
    skipped: u64,
}

async fn stats(State(hub): State<Arc<Hub>>) -> Json<Stats> {
    Json(Stats {
        sent: hub.sent.load(Ordering::Relaxed),
        skipped: hub.skipped.load(Ordering::Relaxed),
    })
}

async fn upgrade(ws: WebSocketUpgrade, State(hub): State<Arc<Hub>>) -> impl IntoResponse {
    ws.on_upgrade(move |socket| async move {
        if let Err(e) = connection(socket, hub).await {
            tracing::debug!(error = %e, "viewer connection closed");
        }
    })
}

/// A command from the page.
#[derive(Debug, Deserialize)]
#[serde(tag = "op", rename_all = "snake_case")]
enum Command {
    Select {
        instance: String,
    },
    Info,
    /// A state arrived at the page.
    Ack,
    Switch {
        #[serde(default)]
        id: u64,
        level: Option<String>,
        max_error: Option<f64>,
        method: Option<String>,
        /// Live at once with the scene's coefficients when the level is not
        /// prepared; the estimate follows in place.
        #[serde(default)]
        at_once: bool,
    },
    /// Live input: the op's fields, checked by [`input_request`] (which
    /// names the field at fault, as serde's own errors do not).
    Grab(Fields),
    Move(Fields),
    Release(Fields),
    ReleaseAll(Fields),
}

impl Command {
    /// An input op's name and fields.
    fn input(&self) -> Option<(&'static str, &Fields)> {
        match self {
            Command::Grab(f) => Some(("grab", f)),
            Command::Move(f) => Some(("move", f)),
            Command::Release(f) => Some(("release", f)),
            Command::ReleaseAll(f) => Some(("release_all", f)),
            _ => None,
        }
    }
}

pub use input::*;
use input::{input_error, track_hold};

/// The switch request a page command asks for, or why it cannot be sent.
pub fn switch_request(
    level: Option<&str>,
    max_error: Option<f64>,
    method: Option<&str>,
    at_once: bool,
) -> Result<v1::SwitchRequest, String> {
    use v1::switch_request::Target;
    let target = match (level, max_error) {
        (Some(l), None) => Target::Level(l.parse::<Level>().map_err(|e| format!("level '{l}': {e}"))?.to_wire()),
        (None, Some(e)) if e.is_finite() && e > 0.0 => Target::MaxError(e),
        (None, Some(e)) => return Err(format!("max_error {e} must be a positive fraction")),
        _ => return Err("a switch names either a level or a max_error".into()),
    };
    Ok(v1::SwitchRequest {
        target: Some(target),
        method: method.unwrap_or_default().to_string(),
        at_once,
    })
}

fn json(value: serde_json::Value) -> Message {
    Message::Text(value.to_string().into())
}

fn pct(e: Option<f64>) -> String {
    e.map_or_else(
        || "no prediction".into(),
        |e| format!("predicted error {:.2} %", 100.0 * e),
    )
}

fn level_text(l: &Option<v1::Level>) -> String {
    match l.as_ref().map(Level::from_wire) {
        Some(Ok(l)) => l.to_string(),
        _ => "?".into(),
    }
}

/// The reply to a switch command, as the page shows it.
fn switch_reply(id: u64, result: Result<v1::SwitchReply, String>) -> Message {
    match result {
        Ok(r) => json(serde_json::json!({
            "type": "switch", "id": id, "ok": true,
            "previous": level_text(&r.previous), "level": level_text(&r.level),
            "method": r.method, "predicted_error": r.predicted_error, "dt": r.dt,
            "coefficient_version": r.coefficient_version, "refining": r.refining,
            "message": format!(
                "switched {} → {} ({}, {}) in {:.2} s{}",
                level_text(&r.previous), level_text(&r.level), r.method, pct(r.predicted_error), r.seconds,
                if r.refining { ", the estimate follows" } else if r.cached { ", cached" } else { "" }
            ),
        })),
        Err(message) => {
            let (code, message) = match message.split_once(": ") {
                Some((c, m)) if !c.is_empty() && c.chars().all(|ch| ch.is_ascii_uppercase() || ch == '_') => {
                    (c.to_string(), m.to_string())
                }
                _ => ("BAD_REQUEST".to_string(), message),
            };
            json(serde_json::json!({"type": "switch", "id": id, "ok": false, "code": code, "message": message}))
        }
    }
}

type Frames = watch::Receiver<Option<(u64, Bytes)>>;

/// The selected instance of a connection: its feeds and the number of the
/// last state sent.
#[derive(Default)]
struct Selected {
    name: Option<String>,
    state: Option<Frames>,
    metrics: Option<Frames>,
    last_state: Option<u64>,
}

/// Completes when `rx` has news; never without a receiver.
async fn changed(rx: Option<&mut Frames>) {
    if let Some(rx) = rx {
        if rx.changed().await.is_ok() {
            return;
        }
    }
    std::future::pending().await
}

/// How long releasing a closed connection's grabs may take, each.
const RELEASE_TIMEOUT: Duration = Duration::from_secs(2);

async fn connection(mut socket: WebSocket, hub: Arc<Hub>) -> Result<(), axum::Error> {
    let mut held = BTreeSet::new();
    let result = serve_page(&mut socket, &hub, &mut held).await;
    // A page that closes (or loses its connection) mid-drag lets go at
    // once, not after the daemon's idle time.
    for (instance, id) in held {
        let request = crate::proto::input_request(&Input::Release { id });
        match tokio::time::timeout(RELEASE_TIMEOUT, hub.client.input(&instance, &request)).await {
            Ok(Ok(_)) => tracing::debug!(%instance, id, "released the grab of a closed page"),
            Ok(Err(e)) => tracing::debug!(%instance, id, error = %e, "releasing the grab of a closed page"),
            Err(_) => tracing::debug!(%instance, id, "releasing the grab of a closed page: no reply"),
        }
    }
    result
}

/// The page's input op as a [`Queued`] input for the selected instance, or
/// the reply refusing it.
fn page_input(op: &str, fields: &Fields, selected: &Selected) -> Result<Queued, serde_json::Value> {
    let id = fields
        .get("id")
        .and_then(|x| x.as_u64())
        .and_then(|n| u32::try_from(n).ok());
    let refuse = |message: String| input_reply(op, id, 0, Err(("CODE_BAD_REQUEST".into(), message)));
    let Some(instance) = selected.name.clone() else {
        return Err(refuse("select an instance first".into()));
    };
    let request = input_request(op, fields).map_err(refuse)?;
    Ok(Queued {
        instance,
        op: op.to_string(),
        id,
        request,
        replaced: 0,
    })
}

/// Send the next queued input when none is in flight; its reply comes back
/// on `done`.
fn send_next_input(inputs: &mut InputQueue, hub: &Arc<Hub>, done: &mpsc::Sender<Message>) {
    let Some(q) = inputs.take_next() else { return };
    let (hub, done) = (hub.clone(), done.clone());
    tokio::spawn(async move {
        let result = hub.client.input(&q.instance, &q.request).await.map_err(input_error);
        let _ = done.send(json(input_reply(&q.op, q.id, q.replaced, result))).await;
    });
}

async fn serve_page(
    socket: &mut WebSocket,
    hub: &Arc<Hub>,
    held: &mut BTreeSet<(String, u32)>,
) -> Result<(), axum::Error> {
    let mut list = hub.instances.subscribe();
    let mut shutdown = hub.shutdown.clone();
    let (out_tx, mut out_rx) = mpsc::channel::<Message>(16);
    // One input in flight at a time: its reply is the only message here.
    let (done_tx, mut done_rx) = mpsc::channel::<Message>(1);
    let mut inputs = InputQueue::default();
    let mut selected = Selected::default();
    let mut in_flight = 0u32;
    socket
        .send(json(serde_json::json!({
            "type": "hello", "prefix": hub.client.prefix, "connect": hub.connect,
        })))
        .await?;
    list.mark_changed();
    loop {
        tokio::select! {
            msg = socket.recv() => match msg {
                Some(Ok(Message::Text(text))) => {
                    match serde_json::from_str::<Command>(text.as_str()) {
                        Ok(Command::Ack) => in_flight = in_flight.saturating_sub(1),
                        Ok(cmd) => match cmd.input().map(|(op, fields)| page_input(op, fields, &selected)) {
                            Some(Ok(q)) => {
                                track_hold(held, &q);
                                inputs.push(q);
                                send_next_input(&mut inputs, hub, &done_tx);
                            }
                            Some(Err(reply)) => socket.send(json(reply)).await?,
                            None => {
                                if matches!(cmd, Command::Select { .. }) {
                                    in_flight = 0;
                                }
                                command(cmd, hub, &mut selected, &out_tx);
                            }
                        },
                        Err(e) => socket.send(json(serde_json::json!({
                            "type": "error", "message": format!("unreadable command {:?}: {e}", text.as_str()),
                        }))).await?,
                    }
                }
                Some(Ok(Message::Close(_))) | None => break,
                Some(Err(e)) => return Err(e),
                Some(Ok(_)) => {}
            },
            Ok(()) = list.changed() => {
                let entries: Vec<Entry> = list.borrow_and_update().iter()
                    .map(|(name, &alive)| Entry { name: name.clone(), alive }).collect();
                socket.send(json(serde_json::json!({"type": "instances", "instances": entries}))).await?;
            }
            () = changed(selected.state.as_mut()), if in_flight < MAX_IN_FLIGHT => {
                let latest = selected.state.as_mut().and_then(|rx| rx.borrow_and_update().clone());
                if let Some((seq, bytes)) = latest {
                    if let Some(last) = selected.last_state {
                        hub.skipped.fetch_add(seq.saturating_sub(last + 1), Ordering::Relaxed);
                    }
                    selected.last_state = Some(seq);
                    in_flight += 1;
                    send_frame(socket, hub, bytes).await?;
                }
            }
            () = changed(selected.metrics.as_mut()) => {
                let latest = selected.metrics.as_mut().and_then(|rx| rx.borrow_and_update().clone());
                if let Some((_, bytes)) = latest {
                    send_frame(socket, hub, bytes).await?;
                }
            }
            Some(msg) = out_rx.recv() => socket.send(msg).await?,
            Some(reply) = done_rx.recv() => {
                inputs.done();
                send_next_input(&mut inputs, hub, &done_tx);
                socket.send(reply).await?;
            }
            _ = shutdown.changed() => break,
        }
    }
    let _ = socket.send(Message::Close(None)).await;
    Ok(())
}

async fn send_frame(socket: &mut WebSocket, hub: &Hub, bytes: Bytes) -> Result<(), axum::Error> {
    hub.sent.fetch_add(1, Ordering::Relaxed);
    socket.send(Message::Binary(bytes)).await
}

fn command(cmd: Command, hub: &Arc<Hub>, selected: &mut Selected, out: &mpsc::Sender<Message>) {
    match cmd {
        Command::Select { instance } => {
            let feed = hub.feed(&instance);
            let mut state = feed.state.subscribe();
            let mut metrics = feed.metrics.subscribe();
            state.mark_changed();
            metrics.mark_changed();
            *selected = Selected {
                name: Some(instance.clone()),
                state: Some(state),
                metrics: Some(metrics),
                last_state: None,
            };
            send_info(hub, instance, out);
        }
        // Acks and inputs are the connection's own (flow control, order).
        Command::Ack | Command::Grab(_) | Command::Move(_) | Command::Release(_) | Command::ReleaseAll(_) => {}
        Command::Info => match &selected.name {
            Some(name) => send_info(hub, name.clone(), out),
            None => {
                let _ = out.try_send(json(
                    serde_json::json!({"type": "error", "message": "no instance selected"}),
                ));
            }
        },
        Command::Switch {
            id,
            level,
            max_error,
            method,
            at_once,
        } => {
            let Some(name) = selected.name.clone() else {
                let _ = out.try_send(switch_reply(id, Err("select an instance first".into())));
                return;
            };
            let request = switch_request(level.as_deref(), max_error, method.as_deref(), at_once);
            let (hub, out) = (hub.clone(), out.clone());
            tokio::spawn(async move {
                let result = match request {
                    Ok(r) => hub
                        .client
                        .switch(&name, &r, SWITCH_TIMEOUT)
                        .await
                        .map_err(|e| e.to_string()),
                    Err(e) => Err(e),
                };
                let _ = out.send(switch_reply(id, result)).await;
            });
        }
    }
}

fn send_info(hub: &Arc<Hub>, instance: String, out: &mpsc::Sender<Message>) {
    let (hub, out) = (hub.clone(), out.clone());
    tokio::spawn(async move {
        let msg = match hub.client.info(&instance).await {
            Ok(info) => {
                let mut framed = vec![tag::INFO];
                info.encode(&mut framed).expect("a Vec grows");
                Message::Binary(Bytes::from(framed))
            }
            Err(e) => json(serde_json::json!({"type": "error", "message": format!("info of '{instance}': {e}")})),
        };
        let _ = out.send(msg).await;
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn page_commands_become_switch_requests_or_clear_refusals() {
        let r = switch_request(Some("16x16"), None, Some("bcd"), true).unwrap();
        assert_eq!(r.method, "bcd");
        assert!(matches!(r.target, Some(v1::switch_request::Target::Level(l)) if l.nx == 16 && l.ny == 16));
        let r = switch_request(None, Some(0.05), None, false).unwrap();
        assert!(matches!(r.target, Some(v1::switch_request::Target::MaxError(e)) if e == 0.05));
        assert!(switch_request(Some("16by16"), None, None, false)
            .unwrap_err()
            .contains("16by16"));
        assert!(switch_request(None, Some(f64::NAN), None, false)
            .unwrap_err()
            .contains("max_error"));
        assert!(switch_request(None, Some(-0.1), None, false)
            .unwrap_err()
            .contains("positive"));
        assert!(switch_request(Some("8x8"), Some(0.1), None, false).is_err());
        assert!(switch_request(None, None, None, false).is_err());
        let cmd: Command = serde_json::from_str(r#"{"op":"switch","id":3,"max_error":0.1}"#).unwrap();
        assert!(matches!(
            cmd,
            Command::Switch {
                id: 3,
                max_error: Some(_),
                level: None,
                ..
            }
        ));
    }

    fn fields(text: &str) -> (&'static str, Fields) {
        let cmd: Command = serde_json::from_str(text).unwrap();
        let (op, f) = cmd.input().expect("an input op");
        (op, f.clone())
    }

    pub(super) fn request(text: &str) -> Result<v1::InputRequest, String> {
        let (op, f) = fields(text);
        input_request(op, &f)
    }

    #[test]
    fn a_refusal_keeps_its_code_and_reason() {
        let Message::Text(t) = switch_reply(7, Err("NOT_FOUND: level 9x9 is not allowed".into())) else {
            panic!("a text reply")
        };
        let v: serde_json::Value = serde_json::from_str(t.as_str()).unwrap();
        assert_eq!(v["ok"], false);
        assert_eq!(v["code"], "NOT_FOUND");
        assert_eq!(v["message"], "level 9x9 is not allowed");
        assert_eq!(v["id"], 7);
    }
}
