//! A client of the daemon, used by the CLI (`list`, `watch`, `switch`,
//! `record`, `health`) and the tests. Speaks only the wire contract.

use std::time::Duration;

use prost::Message;
use zenoh::query::{ConsolidationMode, QueryTarget};
use zenoh::Session;

pub use super::security::ClientSecurity;
use super::{encoding, keys};
use crate::proto::{schema, v1};

/// What went wrong talking to the daemon.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    #[error("zenoh: {0}")]
    Zenoh(String),
    #[error(
        "no reply to {what} within {seconds} s; is a daemon running and reachable (and, for switch, \
         control or input on a secured daemon, are you one of its operators)?"
    )]
    NoReply { what: String, seconds: f64 },
    #[error("{code}: {message}")]
    Refused { code: String, message: String },
    #[error("undecodable reply to {what}: {message}")]
    Decode { what: String, message: String },
}

fn zerr(e: zenoh::Error) -> ClientError {
    ClientError::Zenoh(e.to_string())
}

/// A refusal from the daemon as a [`ClientError`].
fn refused(bytes: &[u8]) -> ClientError {
    match v1::Error::decode(bytes) {
        Ok(e) => ClientError::Refused {
            code: v1::error::Code::try_from(e.code)
                .map_or_else(|_| format!("code {}", e.code), |c| c.as_str_name().to_string()),
            message: e.message,
        },
        Err(_) => ClientError::Refused {
            code: "UNKNOWN".into(),
            message: String::from_utf8_lossy(bytes).into_owned(),
        },
    }
}

/// How a client joins zenoh.
#[derive(Debug, Clone, Default)]
pub struct ClientOptions {
    /// Endpoints of daemons or routers; empty: discover peers by multicast.
    pub connect: Vec<String>,
    /// zenoh `client` mode: one connection, to a router, re-established
    /// when the router comes back. Otherwise a peer connected to every
    /// endpoint (several daemons on different endpoints are all reached).
    pub client_mode: bool,
    /// Credentials and certificates for a secured daemon.
    pub security: ClientSecurity,
}

impl ClientOptions {
    /// A peer connected to `connect`, no credentials.
    pub fn new(connect: &[String]) -> ClientOptions {
        ClientOptions {
            connect: connect.to_vec(),
            ..ClientOptions::default()
        }
    }
}

/// A zenoh session config for a client (see [`ClientOptions`]); multicast
/// scouting is off when endpoints are given.
pub fn client_config(options: &ClientOptions) -> Result<zenoh::Config, ClientError> {
    let problems = options.security.problems();
    if !problems.is_empty() {
        return Err(ClientError::Zenoh(problems.join("; ")));
    }
    if options.client_mode && options.connect.is_empty() {
        return Err(ClientError::Zenoh("client mode needs an endpoint to connect to".into()));
    }
    let mut c = zenoh::Config::default();
    let set = |c: &mut zenoh::Config, k: &str, v: &str| {
        c.insert_json5(k, v)
            .map_err(|e| ClientError::Zenoh(format!("{k}: {e}")))
    };
    set(
        &mut c,
        "mode",
        if options.client_mode { "\"client\"" } else { "\"peer\"" },
    )?;
    // A client listens on nothing.
    set(&mut c, "listen/endpoints", "[]")?;
    if !options.connect.is_empty() {
        let endpoints = serde_json::to_string(&options.connect).map_err(|e| ClientError::Zenoh(e.to_string()))?;
        set(&mut c, "connect/endpoints", &endpoints)?;
        set(&mut c, "scouting/multicast/enabled", "false")?;
    }
    options.security.apply(&mut c).map_err(ClientError::Zenoh)?;
    Ok(c)
}

/// A connected client.
pub struct Client {
    pub session: Session,
    pub prefix: String,
    pub timeout: Duration,
}

impl Client {
    /// Open a peer session connected to `connect`, without credentials.
    pub async fn connect(connect: &[String], prefix: &str) -> Result<Client, ClientError> {
        Client::open(&ClientOptions::new(connect), prefix).await
    }

    /// Open a session (see [`client_config`]).
    pub async fn open(options: &ClientOptions, prefix: &str) -> Result<Client, ClientError> {
        let config = client_config(options)?;
        super::security::warn_if_tls(&config);
        let session = zenoh::open(config).await.map_err(zerr)?;
        Ok(Client {
            session,
            prefix: prefix.to_string(),
            timeout: Duration::from_secs(10),
        })
    }

    /// Wrap an open session.
    pub fn with_session(session: Session, prefix: &str) -> Client {
        Client {
            session,
            prefix: prefix.to_string(),
            timeout: Duration::from_secs(10),
        }
    }

    /// Query `key`; the Ok replies' payloads, and the error replies.
    async fn query(
        &self,
        key: &str,
        payload: Option<(Vec<u8>, &'static str)>,
        timeout: Duration,
    ) -> Result<(Vec<Vec<u8>>, Vec<ClientError>), ClientError> {
        // Every reply counts (several daemons answer `<prefix>/instances`
        // on the same key): no consolidation.
        let mut get = self
            .session
            .get(key)
            .target(QueryTarget::All)
            .consolidation(ConsolidationMode::None)
            .timeout(timeout);
        if let Some((bytes, schema)) = payload {
            get = get.payload(bytes).encoding(encoding(schema));
        }
        let replies = get.await.map_err(zerr)?;
        let mut ok = Vec::new();
        let mut errors = Vec::new();
        while let Ok(reply) = replies.recv_async().await {
            match reply.result() {
                Ok(sample) => ok.push(sample.payload().to_bytes().into_owned()),
                Err(e) => errors.push(refused(&e.payload().to_bytes())),
            }
        }
        Ok((ok, errors))
    }

    /// One reply of type `M` to `key` (the first success; else the first
    /// refusal).
    async fn request<M: Message + Default>(
        &self,
        key: &str,
        payload: Option<(Vec<u8>, &'static str)>,
        timeout: Duration,
    ) -> Result<M, ClientError> {
        let (ok, mut errors) = self.query(key, payload, timeout).await?;
        if let Some(bytes) = ok.first() {
            return M::decode(bytes.as_slice()).map_err(|e| ClientError::Decode {
                what: key.to_string(),
                message: e.to_string(),
            });
        }
        if !errors.is_empty() {
            return Err(errors.swap_remove(0));
        }
        Err(ClientError::NoReply {
            what: key.to_string(),
            seconds: timeout.as_secs_f64(),
        })
    }

    /// Every instance of every daemon that answers.
    pub async fn list(&self) -> Result<Vec<v1::InstanceList>, ClientError> {
        let key = keys::instances(&self.prefix);
        let (ok, _) = self.query(&key, None, self.timeout).await?;
        ok.iter()
            .map(|b| {
                v1::InstanceList::decode(b.as_slice()).map_err(|e| ClientError::Decode {
                    what: key.clone(),
                    message: e.to_string(),
                })
            })
            .collect()
    }

    /// Names of the instances whose liveliness tokens are present.
    pub async fn alive(&self) -> Result<Vec<String>, ClientError> {
        let replies = self
            .session
            .liveliness()
            .get(keys::alive(&self.prefix, "*"))
            .timeout(self.timeout)
            .await
            .map_err(zerr)?;
        let mut names = Vec::new();
        while let Ok(reply) = replies.recv_async().await {
            if let Ok(sample) = reply.result() {
                if let Some(n) = keys::alive_instance(&self.prefix, sample.key_expr().as_str()) {
                    names.push(n.to_string());
                }
            }
        }
        names.sort();
        names.dedup();
        Ok(names)
    }

    pub async fn info(&self, instance: &str) -> Result<v1::InstanceInfo, ClientError> {
        self.request(&keys::info(&self.prefix, instance), None, self.timeout)
            .await
    }

    /// The inputs of `instance`'s latest episode so far (a recorder
    /// starting mid-episode asks for the ones before it subscribed).
    pub async fn episode_inputs(&self, instance: &str) -> Result<v1::EpisodeInputs, ClientError> {
        self.request(&keys::episode_inputs(&self.prefix, instance), None, self.timeout)
            .await
    }

    /// Send a switch request; waits up to `timeout` (an uncached level is
    /// estimated first).
    pub async fn switch(
        &self,
        instance: &str,
        request: &v1::SwitchRequest,
        timeout: Duration,
    ) -> Result<v1::SwitchReply, ClientError> {
        self.request(
            &keys::switch(&self.prefix, instance),
            Some((request.encode_to_vec(), schema::SWITCH_REQUEST)),
            timeout,
        )
        .await
    }

    /// Send raw bytes as a switch request (tests of malformed input).
    pub async fn switch_raw(&self, instance: &str, payload: Option<Vec<u8>>) -> Result<v1::SwitchReply, ClientError> {
        self.request(
            &keys::switch(&self.prefix, instance),
            payload.map(|p| (p, schema::SWITCH_REQUEST)),
            self.timeout,
        )
        .await
    }

    pub async fn control(
        &self,
        instance: &str,
        action: v1::control_request::Action,
    ) -> Result<v1::ControlReply, ClientError> {
        let req = v1::ControlRequest { action: action as i32 };
        self.request(
            &keys::control(&self.prefix, instance),
            Some((req.encode_to_vec(), schema::CONTROL_REQUEST)),
            self.timeout,
        )
        .await
    }

    /// Send an input (grab, move, release, pin move, wind, impulse); the
    /// reply says the step after which it took effect.
    pub async fn input(&self, instance: &str, request: &v1::InputRequest) -> Result<v1::InputReply, ClientError> {
        self.request(
            &keys::input(&self.prefix, instance),
            Some((request.encode_to_vec(), schema::INPUT_REQUEST)),
            self.timeout,
        )
        .await
    }
}
