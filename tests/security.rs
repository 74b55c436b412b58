//! Who is admitted and who may switch, against a daemon secured with zenoh's
//! own mTLS (on a QUIC link: zenoh's `tls/` link is unsound in 1.10.2,
//! docs/deployment.md), user/password authentication and access control (the
//! observe-for-all, operate-for-operators policy of `[zenoh.access]`).
//! Certificates and passwords are made at run time; nothing is committed.

use crate::daemon;

use std::io::Read;
use std::path::{Path, PathBuf};
use std::time::Duration;

use daemon::{collect_states, free_port, level_of, scene_path, within, Daemon, PREFIX};
use lodcloth::plan::Level;
use lodcloth::proto::{v1, WireLevel};
use lodcloth::service::client::{Client, ClientError, ClientOptions, ClientSecurity};
use lodcloth::service::config::ServiceConfig;
use rcgen::{BasicConstraints, CertificateParams, CertifiedIssuer, DnType, IsCa, KeyPair};

const INSTANCE: &str = "guarded";

/// Hex of 16 random bytes: a password nobody committed.
fn random_secret() -> String {
    let mut bytes = [0u8; 16];
    std::fs::File::open("/dev/urandom")
        .and_then(|mut f| f.read_exact(&mut bytes))
        .expect("random bytes");
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// A certificate authority that writes PEM files into a directory.
struct Authority {
    issuer: CertifiedIssuer<'static, KeyPair>,
    dir: PathBuf,
    name: String,
}

impl Authority {
    fn new(dir: &Path, name: &str) -> Authority {
        let mut params = CertificateParams::new(Vec::<String>::new()).expect("CA params");
        params.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
        params
            .distinguished_name
            .push(DnType::CommonName, format!("{name} test CA"));
        let issuer = CertifiedIssuer::self_signed(params, KeyPair::generate().expect("CA key")).expect("CA cert");
        std::fs::write(dir.join(format!("{name}-ca.pem")), issuer.pem()).expect("write CA");
        Authority {
            issuer,
            dir: dir.to_path_buf(),
            name: name.to_string(),
        }
    }

    fn ca(&self) -> PathBuf {
        self.dir.join(format!("{}-ca.pem", self.name))
    }

    /// A certificate with common name `cn` (and loopback names), signed by
    /// this authority: (certificate, key).
    fn issue(&self, cn: &str) -> (PathBuf, PathBuf) {
        let mut params =
            CertificateParams::new(vec!["localhost".to_string(), "127.0.0.1".to_string()]).expect("params");
        params.distinguished_name.push(DnType::CommonName, cn);
        let key = KeyPair::generate().expect("key");
        let cert = params.signed_by(&key, &self.issuer).expect("signed certificate");
        let stem = format!("{}-{cn}", self.name);
        let (c, k) = (
            self.dir.join(format!("{stem}.pem")),
            self.dir.join(format!("{stem}.key")),
        );
        std::fs::write(&c, cert.pem()).expect("write certificate");
        std::fs::write(&k, key.serialize_pem()).expect("write key");
        (c, k)
    }
}

/// One instance of paper scene 1 at 8×8 and 12×12 (method `same`: ready in
/// well under a second), starting at 8×8.
fn instance_block() -> String {
    format!(
        r#"
[estimation]
reference_steps = 2000
[[instances]]
name = "{INSTANCE}"
scene = "{scene}"
reference = "16x16"
levels = ["8x8", "12x12"]
start = "8x8"
method = "same"
"#,
        scene = scene_path("paper-1-top-edge.toml").display()
    )
}

fn header(cache: &Path, listen: &[String]) -> String {
    format!(
        r#"
prefix = "{PREFIX}"
cache = "{cache}"
[engine]
threads = 1
publish_hz = 50.0
[zenoh]
mode = "peer"
listen = {listen:?}
multicast_scouting = false
"#,
        cache = cache.display(),
    )
}

/// Open a client-mode session (so a refused link is an error, not a peer
/// waiting for someone else); retry while the daemon's listeners come up
/// unless `expect_refusal`.
async fn open(options: ClientOptions, expect_refusal: bool) -> Result<Client, ClientError> {
    let options = ClientOptions {
        client_mode: true,
        ..options
    };
    let mut tries = 0;
    loop {
        match Client::open(&options, PREFIX).await {
            Ok(mut c) => {
                c.timeout = Duration::from_secs(3);
                return Ok(c);
            }
            Err(e) if expect_refusal || tries >= 30 => return Err(e),
            Err(_) => {
                tries += 1;
                tokio::time::sleep(Duration::from_millis(200)).await;
            }
        }
    }
}

fn to(level: Level) -> v1::SwitchRequest {
    v1::SwitchRequest {
        at_once: false,
        target: Some(v1::switch_request::Target::Level(level.to_wire())),
        method: String::new(),
    }
}

/// A switch that is not allowed must fail without an OK reply, and the
/// instance must stay where it was.
async fn assert_switch_denied(c: &Client, observer: &Client) {
    let before = level_of(collect_states(observer, INSTANCE, 0.3).await.last().expect("states"));
    let target = if before == Level::new(8, 8) {
        Level::new(12, 12)
    } else {
        Level::new(8, 8)
    };
    let r = c.switch(INSTANCE, &to(target), Duration::from_secs(3)).await;
    assert!(
        matches!(r, Err(ClientError::NoReply { .. } | ClientError::Refused { .. })),
        "an unauthorised switch must not succeed: {r:?}"
    );
    let after = collect_states(observer, INSTANCE, 0.5).await;
    assert!(!after.is_empty(), "the instance keeps publishing");
    assert!(
        after.iter().all(|s| level_of(s) == before),
        "the instance must stay at {before} after a refused switch"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn mtls_admits_only_the_ca_and_lets_only_operators_switch() {
    let _serial = daemon::serial().await;
    let dir = tempfile::tempdir().expect("temp dir");
    let pki = tempfile::tempdir().expect("pki dir");
    let trusted = Authority::new(pki.path(), "trusted");
    let rogue = Authority::new(pki.path(), "rogue");
    let (daemon_cert, daemon_key) = trusted.issue("lodcloth-daemon");
    let (op_cert, op_key) = trusted.issue("operator");
    let (viewer_cert, viewer_key) = trusted.issue("viewer");
    let (rogue_cert, rogue_key) = rogue.issue("operator");

    let (tcp, quic) = (free_port(), free_port());
    let text = header(
        dir.path(),
        &[format!("tcp/127.0.0.1:{tcp}"), format!("quic/127.0.0.1:{quic}")],
    ) + &format!(
        r#"
[zenoh.tls]
root_ca = "{ca}"
certificate = "{cert}"
private_key = "{key}"
mutual = true
[zenoh.access]
operator_certificates = ["operator"]
"#,
        ca = trusted.ca().display(),
        cert = daemon_cert.display(),
        key = daemon_key.display(),
    ) + &instance_block();
    let d = Daemon::run(tcp, &text, dir);
    let quic_with = |cert: &Path, key: &Path, ca: &Path| ClientOptions {
        connect: vec![format!("quic/localhost:{quic}")],
        security: ClientSecurity {
            tls_root_ca: Some(ca.to_path_buf()),
            tls_certificate: Some(cert.to_path_buf()),
            tls_private_key: Some(key.to_path_buf()),
            ..ClientSecurity::default()
        },
        ..ClientOptions::default()
    };

    // Anyone on plain TCP observes: info, instance list, states.
    let anon = within(15, "anonymous client", open(ClientOptions::new(&[d.endpoint()]), false))
        .await
        .expect("an anonymous observer is admitted on tcp/");
    let info = within(15, "info", daemon::wait_info(&anon, INSTANCE)).await;
    assert_eq!(info.instance, INSTANCE);
    let lists = within(10, "list", anon.list()).await.expect("list");
    assert!(lists.iter().any(|l| l.instances.iter().any(|i| i.instance == INSTANCE)));
    assert!(
        !collect_states(&anon, INSTANCE, 0.5).await.is_empty(),
        "anonymous observers get states"
    );
    // ... but cannot switch or control.
    within(15, "anonymous switch", assert_switch_denied(&anon, &anon)).await;
    let paused = anon.control(INSTANCE, v1::control_request::Action::Pause).await;
    assert!(paused.is_err(), "an anonymous pause must fail: {paused:?}");
    let release_all = v1::InputRequest {
        action: Some(v1::input_request::Action::ReleaseAll(v1::input_request::ReleaseAll {})),
    };
    let touched = anon.input(INSTANCE, &release_all).await;
    assert!(touched.is_err(), "an anonymous input must fail: {touched:?}");

    // A certificate from another CA is not admitted on quic/.
    let refused = within(
        20,
        "rogue client",
        open(quic_with(&rogue_cert, &rogue_key, &trusted.ca()), true),
    )
    .await;
    assert!(
        refused.is_err(),
        "a certificate from an unknown CA must not be admitted"
    );

    // An admitted viewer certificate observes but cannot switch.
    let viewer = within(
        20,
        "viewer client",
        open(quic_with(&viewer_cert, &viewer_key, &trusted.ca()), false),
    )
    .await
    .expect("a CA-signed viewer is admitted");
    within(15, "viewer info", daemon::wait_info(&viewer, INSTANCE)).await;
    within(15, "viewer switch", assert_switch_denied(&viewer, &anon)).await;

    // The operator switches, and everyone sees the new level.
    let operator = within(
        20,
        "operator client",
        open(quic_with(&op_cert, &op_key, &trusted.ca()), false),
    )
    .await
    .expect("the operator is admitted");
    within(15, "operator info", daemon::wait_info(&operator, INSTANCE)).await;
    let reply = within(
        30,
        "operator switch",
        operator.switch(INSTANCE, &to(Level::new(12, 12)), Duration::from_secs(20)),
    )
    .await
    .expect("the operator's switch succeeds");
    assert_eq!(
        Level::from_wire(reply.level.as_ref().expect("level")),
        Ok(Level::new(12, 12))
    );
    let states = collect_states(&anon, INSTANCE, 0.5).await;
    assert!(
        states.iter().any(|s| level_of(s) == Level::new(12, 12)),
        "observers see the switch"
    );
    let release_all = v1::InputRequest {
        action: Some(v1::input_request::Action::ReleaseAll(v1::input_request::ReleaseAll {})),
    };
    within(10, "operator input", operator.input(INSTANCE, &release_all))
        .await
        .expect("the operator may touch the cloth");

    for c in [anon, viewer, operator] {
        let _ = c.session.close().await;
    }
    d.shutdown().await.expect("clean shutdown");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn passwords_admit_users_and_only_operators_switch() {
    let _serial = daemon::serial().await;
    let dir = tempfile::tempdir().expect("temp dir");
    let (op_pw, viewer_pw) = (random_secret(), random_secret());
    let users = dir.path().join("users.txt");
    std::fs::write(&users, format!("operator:{op_pw}\nviewer:{viewer_pw}\n")).expect("write users");
    let port = free_port();
    let text = header(dir.path(), &[format!("tcp/127.0.0.1:{port}")])
        + &format!(
            r#"
[zenoh.auth]
dictionary = "{users}"
[zenoh.access]
operator_usernames = ["operator"]
"#,
            users = users.display()
        )
        + &instance_block();
    let d = Daemon::run(port, &text, dir);
    let as_user = |user: &str, password: &str| ClientOptions {
        connect: vec![d.endpoint()],
        security: ClientSecurity {
            user: Some(user.into()),
            password: Some(password.into()),
            ..ClientSecurity::default()
        },
        ..ClientOptions::default()
    };

    // The viewer is admitted (retrying while the daemon starts) and observes.
    let viewer = within(20, "viewer", open(as_user("viewer", &viewer_pw), false))
        .await
        .expect("the viewer is admitted");
    within(15, "viewer info", daemon::wait_info(&viewer, INSTANCE)).await;
    assert!(!collect_states(&viewer, INSTANCE, 0.5).await.is_empty());

    // No credentials, a wrong password, an unknown user: not admitted.
    for (what, options) in [
        ("no credentials", ClientOptions::new(&[d.endpoint()])),
        ("a wrong password", as_user("operator", &viewer_pw)),
        ("an unknown user", as_user("intruder", &op_pw)),
    ] {
        let r = within(20, what, open(options, true)).await;
        assert!(r.is_err(), "{what} must not be admitted");
    }

    within(15, "viewer switch", assert_switch_denied(&viewer, &viewer)).await;
    let operator = within(20, "operator", open(as_user("operator", &op_pw), false))
        .await
        .expect("the operator is admitted");
    within(15, "operator info", daemon::wait_info(&operator, INSTANCE)).await;
    let reply = within(
        30,
        "operator switch",
        operator.switch(INSTANCE, &to(Level::new(12, 12)), Duration::from_secs(20)),
    )
    .await
    .expect("the operator's switch succeeds");
    assert_eq!(reply.instance, INSTANCE);
    let states = collect_states(&viewer, INSTANCE, 0.5).await;
    assert!(
        states.iter().any(|s| level_of(s) == Level::new(12, 12)),
        "the viewer sees the switch"
    );

    for c in [viewer, operator] {
        let _ = c.session.close().await;
    }
    d.shutdown().await.expect("clean shutdown");
}

#[test]
fn insecure_or_inconsistent_security_sections_are_refused_by_path() {
    let dir = tempfile::tempdir().expect("temp dir");
    let cases = [
        (
            "[zenoh]\nlisten = [\"tls/127.0.0.1:7999\"]\n",
            "a quic/ or tls/ endpoint needs [zenoh.tls]",
        ),
        (
            "[zenoh]\nlisten = [\"quic/127.0.0.1:7999\"]\n",
            "a quic/ or tls/ endpoint needs [zenoh.tls]",
        ),
        (
            "[zenoh.access]\noperator_usernames = [\"ops\"]\n",
            "zenoh.access.operator_usernames: needs zenoh.auth.dictionary",
        ),
        ("[zenoh.access]\n", "zenoh.access: name at least one operator"),
        (
            "[zenoh.tls]\nroot_ca = \"/nonexistent/ca.pem\"\nmutual = true\n",
            "zenoh.tls.root_ca: /nonexistent/ca.pem is not a readable file",
        ),
        (
            "[zenoh.tls]\ncertificate = \"/nonexistent/c.pem\"\n",
            "certificate and private_key go together",
        ),
        (
            "[zenoh.access]\noperator_certificates = [\"operator\"]\n",
            "zenoh.access.operator_certificates: needs zenoh.tls.mutual = true",
        ),
        (
            "[zenoh.auth]\nuser = \"me\"\n",
            "zenoh.auth: user and password go together",
        ),
    ];
    for (section, expected) in cases {
        let text =
            format!("prefix = \"{PREFIX}\"\ncache = \"{}\"\n{section}", dir.path().display()) + &instance_block();
        let err = ServiceConfig::from_toml(&text, "sec.toml")
            .expect_err(section)
            .to_string();
        assert!(
            err.contains(expected),
            "for\n{section}\nexpected '{expected}' in:\n{err}"
        );
    }
    // A dictionary line without a password is named by line.
    let users = dir.path().join("users.txt");
    std::fs::write(&users, "ok:pw\nnopassword\n").expect("write");
    let text = format!(
        "prefix = \"{PREFIX}\"\ncache = \"{}\"\n[zenoh.auth]\ndictionary = \"{}\"\n",
        dir.path().display(),
        users.display()
    ) + &instance_block();
    let err = ServiceConfig::from_toml(&text, "sec.toml")
        .expect_err("bad dictionary")
        .to_string();
    assert!(err.contains("line 2: expected user:password"), "{err}");
}
