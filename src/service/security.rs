//! Who may connect and who may switch: zenoh's TLS/mTLS links, user/password
//! authentication and access control, set from the daemon's `[zenoh.*]`
//! sections and from client options.
//!
//! The policy the daemon generates (when `[zenoh.access]` is present) is
//! *observe for all, operate for operators*:
//! - any admitted session may subscribe to states, metrics and liveliness
//!   under the prefix, and query `info`, `instances` and `episode_inputs`;
//! - only sessions matching `operator_usernames` (user/password
//!   authentication) or `operator_certificates` (the common name of a client
//!   certificate checked by mTLS) may query `switch`, `control` and `input`
//!   (touch the cloth); to the
//!   others those queryables are not even declared, so their requests find
//!   no daemon;
//! - everything else on this session is denied.
//!
//! Who is *admitted* is the transports' business: with a user dictionary
//! every session must authenticate; with `mutual = true` a `quic/` or `tls/` endpoint
//! admits only certificates signed by `root_ca`, while a plain `tcp/`
//! endpoint beside it stays open to anonymous observers.

use std::path::{Path, PathBuf};

use serde::Deserialize;
use serde_json::json;

use super::keys;

/// TLS on `quic/` and `tls/` endpoints (`[zenoh.tls]`).
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawTls {
    /// PEM of the certificate authority that signs the peers' certificates.
    pub root_ca: Option<PathBuf>,
    /// PEM certificate chain of this daemon.
    pub certificate: Option<PathBuf>,
    /// PEM private key of `certificate`.
    pub private_key: Option<PathBuf>,
    /// Require and verify a client certificate on `quic/` and `tls/` endpoints (mTLS).
    #[serde(default)]
    pub mutual: bool,
}

/// User/password authentication (`[zenoh.auth]`).
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawAuth {
    /// `user:password` lines; when set, every session must authenticate.
    pub dictionary: Option<PathBuf>,
    /// This daemon's own credentials, for the endpoints it connects to.
    pub user: Option<String>,
    pub password: Option<String>,
}

/// The access policy (`[zenoh.access]`).
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawAccess {
    /// Authenticated user names that may switch and control instances.
    #[serde(default)]
    pub operator_usernames: Vec<String>,
    /// Client-certificate common names that may switch and control (mTLS).
    #[serde(default)]
    pub operator_certificates: Vec<String>,
}

/// The problems of the security sections, by path.
pub fn problems(tls: Option<&RawTls>, auth: Option<&RawAuth>, access: Option<&RawAccess>) -> Vec<String> {
    let mut p = Vec::new();
    let file = |p: &mut Vec<String>, path: &str, f: &Option<PathBuf>| {
        if let Some(f) = f {
            if !f.is_file() {
                p.push(format!("{path}: {} is not a readable file", f.display()));
            }
        }
    };
    if let Some(t) = tls {
        file(&mut p, "zenoh.tls.root_ca", &t.root_ca);
        file(&mut p, "zenoh.tls.certificate", &t.certificate);
        file(&mut p, "zenoh.tls.private_key", &t.private_key);
        if t.certificate.is_some() != t.private_key.is_some() {
            p.push("zenoh.tls: certificate and private_key go together; set both or neither".into());
        }
        if t.mutual && t.root_ca.is_none() {
            p.push("zenoh.tls.mutual: verifying client certificates needs root_ca (the CA that signs them)".into());
        }
    }
    if let Some(a) = auth {
        file(&mut p, "zenoh.auth.dictionary", &a.dictionary);
        if let Some(d) = a.dictionary.as_deref().filter(|d| d.is_file()) {
            p.extend(dictionary_problems(d));
        }
        if a.user.is_some() != a.password.is_some() {
            p.push("zenoh.auth: user and password go together; set both or neither".into());
        }
    }
    if let Some(a) = access {
        if a.operator_usernames.is_empty() && a.operator_certificates.is_empty() {
            p.push(
                "zenoh.access: name at least one operator (operator_usernames or operator_certificates); \
                 with none, nobody could switch"
                    .into(),
            );
        }
        if !a.operator_usernames.is_empty() && auth.and_then(|a| a.dictionary.as_ref()).is_none() {
            p.push("zenoh.access.operator_usernames: needs zenoh.auth.dictionary to authenticate them".into());
        }
        if !a.operator_certificates.is_empty() && !tls.is_some_and(|t| t.mutual) {
            p.push("zenoh.access.operator_certificates: needs zenoh.tls.mutual = true to verify them".into());
        }
        for (field, names) in [
            ("operator_usernames", &a.operator_usernames),
            ("operator_certificates", &a.operator_certificates),
        ] {
            for (i, n) in names.iter().enumerate() {
                if n.trim().is_empty() {
                    p.push(format!("zenoh.access.{field}[{i}]: empty name"));
                }
            }
        }
    }
    p
}

/// Lines of a `user:password` dictionary that zenoh would refuse, by line.
fn dictionary_problems(path: &Path) -> Vec<String> {
    let Ok(text) = std::fs::read_to_string(path) else {
        return vec![format!("zenoh.auth.dictionary: {} cannot be read", path.display())];
    };
    let mut p = Vec::new();
    let mut users = 0;
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() {
            continue;
        }
        match line.split_once(':') {
            Some((u, pw)) if !u.trim().is_empty() && !pw.trim().is_empty() => users += 1,
            _ => p.push(format!(
                "zenoh.auth.dictionary: {} line {}: expected user:password",
                path.display(),
                i + 1
            )),
        }
    }
    if users == 0 && p.is_empty() {
        p.push(format!("zenoh.auth.dictionary: {} lists no user", path.display()));
    }
    p
}

fn path_text(p: &Path) -> String {
    p.to_string_lossy().into_owned()
}

/// Insert one value at a `/`-separated path of a zenoh config.
fn set(config: &mut zenoh::Config, key: &str, value: serde_json::Value) -> Result<(), String> {
    config
        .insert_json5(key, &value.to_string())
        .map_err(|e| format!("{key}: {e}"))
}

/// The daemon's side: its certificate for `quic/` and `tls/` listeners (and for the
/// endpoints it connects to), the user dictionary, the access policy.
pub fn apply_daemon(
    config: &mut zenoh::Config,
    prefix: &str,
    tls: Option<&RawTls>,
    auth: Option<&RawAuth>,
    access: Option<&RawAccess>,
) -> Result<(), String> {
    if let Some(t) = tls {
        let base = "transport/link/tls";
        if let Some(ca) = &t.root_ca {
            set(config, &format!("{base}/root_ca_certificate"), json!(path_text(ca)))?;
        }
        if let (Some(cert), Some(key)) = (&t.certificate, &t.private_key) {
            for side in ["listen", "connect"] {
                set(config, &format!("{base}/{side}_certificate"), json!(path_text(cert)))?;
                set(config, &format!("{base}/{side}_private_key"), json!(path_text(key)))?;
            }
        }
        set(config, &format!("{base}/enable_mtls"), json!(t.mutual))?;
    }
    if let Some(a) = auth {
        let base = "transport/auth/usrpwd";
        if let Some(d) = &a.dictionary {
            set(config, &format!("{base}/dictionary_file"), json!(path_text(d)))?;
        }
        if let (Some(u), Some(p)) = (&a.user, &a.password) {
            set(config, &format!("{base}/user"), json!(u))?;
            set(config, &format!("{base}/password"), json!(p))?;
        }
    }
    if let Some(a) = access {
        set(config, "access_control", access_control(prefix, a))?;
    }
    Ok(())
}

/// The zenoh `access_control` section of the observe-for-all,
/// operate-for-operators policy.
pub fn access_control(prefix: &str, access: &RawAccess) -> serde_json::Value {
    // Explicit deny beats explicit allow in zenoh, so the policy is built of
    // allow rules over a default deny: operators get one more rule.
    let mut subjects = vec![json!({ "id": "anyone" })];
    let mut operators = Vec::new();
    if !access.operator_usernames.is_empty() {
        subjects.push(json!({ "id": "operator-users", "usernames": access.operator_usernames }));
        operators.push("operator-users");
    }
    if !access.operator_certificates.is_empty() {
        subjects.push(json!({ "id": "operator-certificates", "cert_common_names": access.operator_certificates }));
        operators.push("operator-certificates");
    }
    json!({
        "enabled": true,
        "default_permission": "deny",
        "rules": [
            {
                "id": "observe",
                "permission": "allow",
                "flows": ["ingress", "egress"],
                "messages": ["put", "delete", "declare_subscriber", "liveliness_token",
                             "declare_liveliness_subscriber", "liveliness_query"],
                "key_exprs": [format!("{prefix}/**")],
            },
            {
                "id": "ask",
                "permission": "allow",
                "flows": ["ingress", "egress"],
                "messages": ["query", "reply", "declare_queryable"],
                "key_exprs": [keys::info(prefix, "*"), keys::instances(prefix), keys::episode_inputs(prefix, "*")],
            },
            {
                "id": "operate",
                "permission": "allow",
                "flows": ["ingress", "egress"],
                "messages": ["query", "reply", "declare_queryable"],
                "key_exprs": [keys::switch(prefix, "*"), keys::control(prefix, "*"), keys::input(prefix, "*")],
            },
        ],
        "subjects": subjects,
        "policies": [
            { "rules": ["observe", "ask"], "subjects": ["anyone"] },
            { "rules": ["operate"], "subjects": operators },
        ],
    })
}

/// A client's credentials and certificates.
#[derive(Debug, Clone, Default)]
pub struct ClientSecurity {
    pub user: Option<String>,
    pub password: Option<String>,
    /// CA that signed the daemon's certificate (for `quic/` and `tls/` endpoints).
    pub tls_root_ca: Option<PathBuf>,
    /// This client's certificate and key, for a daemon that requires mTLS.
    pub tls_certificate: Option<PathBuf>,
    pub tls_private_key: Option<PathBuf>,
}

impl ClientSecurity {
    /// What is inconsistent or missing, by option name.
    pub fn problems(&self) -> Vec<String> {
        let mut p = Vec::new();
        if self.user.is_some() != self.password.is_some() {
            p.push("--user and --password go together".to_string());
        }
        if self.tls_certificate.is_some() != self.tls_private_key.is_some() {
            p.push("--tls-cert and --tls-key go together".to_string());
        }
        for (name, f) in [
            ("--tls-ca", &self.tls_root_ca),
            ("--tls-cert", &self.tls_certificate),
            ("--tls-key", &self.tls_private_key),
        ] {
            if let Some(f) = f.as_ref().filter(|f| !f.is_file()) {
                p.push(format!("{name}: {} is not a readable file", f.display()));
            }
        }
        p
    }

    /// Set the credentials and certificates on a client's zenoh config.
    pub fn apply(&self, config: &mut zenoh::Config) -> Result<(), String> {
        let tls = "transport/link/tls";
        if let Some(ca) = &self.tls_root_ca {
            set(config, &format!("{tls}/root_ca_certificate"), json!(path_text(ca)))?;
        }
        if let (Some(cert), Some(key)) = (&self.tls_certificate, &self.tls_private_key) {
            set(config, &format!("{tls}/connect_certificate"), json!(path_text(cert)))?;
            set(config, &format!("{tls}/connect_private_key"), json!(path_text(key)))?;
            // The client side of mTLS: present the certificate.
            set(config, &format!("{tls}/enable_mtls"), json!(true))?;
        }
        if let (Some(u), Some(p)) = (&self.user, &self.password) {
            set(config, "transport/auth/usrpwd/user", json!(u))?;
            set(config, "transport/auth/usrpwd/password", json!(p))?;
        }
        Ok(())
    }
}

/// The endpoints of `config` (listen and connect, for any mode) that use
/// zenoh's `tls/` link.
///
/// zenoh-link-tls 1.10.2 hands one rustls connection to a link's reader and
/// writer at once (eclipse-zenoh/zenoh#2557): when a peer goes away while
/// a batch is written, the writer can read what the reader is storing, and
/// the process aborts (docs/deployment.md, "QUIC, not `tls/`"). `quic/`
/// reads the same `[zenoh.tls]` settings and is sound.
pub fn tls_endpoints(config: &zenoh::Config) -> Vec<String> {
    fn collect(v: &serde_json::Value, out: &mut Vec<String>) {
        match v {
            serde_json::Value::String(s) if s.starts_with("tls/") => out.push(s.clone()),
            serde_json::Value::Array(a) => a.iter().for_each(|v| collect(v, out)),
            serde_json::Value::Object(o) => o.values().for_each(|v| collect(v, out)),
            _ => {}
        }
    }
    let mut out = Vec::new();
    for key in ["listen/endpoints", "connect/endpoints"] {
        if let Some(v) = config.get_json(key).ok().and_then(|j| serde_json::from_str(&j).ok()) {
            collect(&v, &mut out);
        }
    }
    out
}

/// Log a warning when `config` uses `tls/` endpoints ([`tls_endpoints`]).
pub fn warn_if_tls(config: &zenoh::Config) {
    let tls = tls_endpoints(config);
    if !tls.is_empty() {
        tracing::warn!(
            endpoints = ?tls,
            "zenoh's tls/ link is unsound in zenoh 1.10.2 (eclipse-zenoh/zenoh#2557): a peer that goes away \
             mid-write can abort this process; use quic/ (TLS 1.3 over UDP, the same [zenoh.tls] settings)"
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tls_endpoints_are_found_in_listen_and_connect_for_any_mode() {
        let mut config = zenoh::Config::default();
        set(
            &mut config,
            "listen/endpoints",
            json!({"router": ["tls/0.0.0.0:7447", "quic/0.0.0.0:7448"], "peer": ["tcp/0.0.0.0:7449"]}),
        )
        .unwrap();
        set(
            &mut config,
            "connect/endpoints",
            json!(["tls/router:7447", "tcp/router:7446"]),
        )
        .unwrap();
        let mut found = tls_endpoints(&config);
        found.sort();
        assert_eq!(found, ["tls/0.0.0.0:7447", "tls/router:7447"]);
        set(&mut config, "listen/endpoints", json!(["quic/0.0.0.0:7447"])).unwrap();
        set(&mut config, "connect/endpoints", json!(["quic/router:7447"])).unwrap();
        assert!(tls_endpoints(&config).is_empty());
    }

    /// The roles of the compose deployment's router policy: the subjects a
    /// session of each role matches there.
    const OBSERVER: &[&str] = &["anyone"];
    const OPERATOR: &[&str] = &["anyone", "operators"];

    /// Whether `acl` (zenoh's `access_control` section) lets a session
    /// matching `subjects` send or receive (`flow`) `message` on every key
    /// of `key` (`includes`), or on any of them (`!includes`: intersects).
    fn allows(
        acl: &serde_json::Value,
        subjects: &[&str],
        flow: &str,
        message: &str,
        key: &str,
        includes: bool,
    ) -> bool {
        use zenoh::key_expr::KeyExpr;
        let key = KeyExpr::try_from(key).unwrap();
        let list = |v: &serde_json::Value, name: &str| -> Vec<String> {
            v[name]
                .as_array()
                .map(|a| a.iter().filter_map(|x| x.as_str().map(String::from)).collect())
                .unwrap_or_default()
        };
        let rules = acl["rules"].as_array().unwrap();
        acl["policies"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|p| list(p, "subjects").iter().any(|s| subjects.contains(&s.as_str())))
            .flat_map(|p| list(p, "rules"))
            .filter_map(|id| rules.iter().find(|r| r["id"] == id.as_str()))
            .filter(|r| r["permission"] == "allow")
            .filter(|r| list(r, "flows").iter().any(|f| f == flow))
            .filter(|r| list(r, "messages").iter().any(|m| m == message))
            .flat_map(|r| list(r, "key_exprs"))
            .any(|k| {
                let k = KeyExpr::try_from(k.as_str()).unwrap();
                if includes {
                    k.includes(&key)
                } else {
                    k.intersects(&key)
                }
            })
    }

    /// config/compose-router-secure.json5 holds its own copy of the
    /// observe-for-all, operate-for-operators policy (the daemons behind the
    /// router only ever see the router): every query the daemons' policy
    /// lets observers or operators make, with the queryable it needs to
    /// reach them, the router must let them make too, and what only
    /// operators may ask, no observer may. (It once lacked `input` and
    /// `episode_inputs`: nobody could touch a cloth through it.)
    #[test]
    fn the_compose_routers_policy_grants_what_the_daemons_policy_grants() {
        let router = zenoh::Config::from_json5(include_str!("../../config/compose-router-secure.json5")).unwrap();
        let acl: serde_json::Value = serde_json::from_str(&router.get_json("access_control").unwrap()).unwrap();
        let daemons = access_control(
            "lodcloth",
            &RawAccess {
                operator_usernames: vec!["operator".into()],
                operator_certificates: vec![],
            },
        );
        let mut checked = 0;
        for rule in daemons["rules"].as_array().unwrap() {
            let id = rule["id"].as_str().unwrap();
            let (role, others): (&[&str], Option<&[&str]>) = match id {
                "observe" | "ask" => (OBSERVER, None),
                "operate" => (OPERATOR, Some(OBSERVER)),
                other => panic!("the daemons' policy has a rule '{other}' this test does not know"),
            };
            let messages: Vec<&str> = rule["messages"]
                .as_array()
                .unwrap()
                .iter()
                .map(|m| m.as_str().unwrap())
                .collect();
            for key in rule["key_exprs"]
                .as_array()
                .unwrap()
                .iter()
                .map(|k| k.as_str().unwrap())
            {
                // What a client sends comes into the router (ingress from
                // its session); what a daemon sends goes out to it (egress).
                // Clients' own puts stay refused there: publishing under the
                // prefix is the daemons' alone.
                for (message, flow) in [
                    ("query", "ingress"),
                    ("declare_subscriber", "ingress"),
                    ("declare_liveliness_subscriber", "ingress"),
                    ("liveliness_query", "ingress"),
                    ("reply", "egress"),
                    ("declare_queryable", "egress"),
                    ("put", "egress"),
                    ("liveliness_token", "egress"),
                ] {
                    if !messages.contains(&message) {
                        continue;
                    }
                    assert!(
                        allows(&acl, role, flow, message, key, true),
                        "the daemons' rule '{id}' lets {role:?} {flow} '{message}' on {key}; the compose router does not"
                    );
                    checked += 1;
                }
                if let Some(observer) = others {
                    assert!(
                        !allows(&acl, observer, "ingress", "query", key, false),
                        "the compose router lets an observer query {key}, which only operators may"
                    );
                }
            }
        }
        assert!(checked >= 10, "only {checked} grants checked");
    }
}
