//! A headless Chromium driven over the Chrome DevTools Protocol (CDP), for
//! the browser test (`tests/clients.rs`) and the page benchmark
//! (`benches/view_bench.rs`).
#![allow(dead_code)]

use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use futures_util::{SinkExt, StreamExt};
use serde_json::{json, Value};
use tokio::net::TcpStream;
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::{MaybeTlsStream, WebSocketStream};

type Ws = WebSocketStream<MaybeTlsStream<TcpStream>>;

/// Fail instead of hanging.
async fn within<T>(seconds: u64, what: &str, f: impl std::future::Future<Output = T>) -> T {
    match tokio::time::timeout(Duration::from_secs(seconds), f).await {
        Ok(v) => v,
        Err(_) => panic!("{what}: no result within {seconds} s"),
    }
}

/// The browser the tests drive: `LODCLOTH_CHROMIUM`, else Debian's
/// `chromium`.
fn executable() -> String {
    std::env::var("LODCLOTH_CHROMIUM").unwrap_or_else(|_| "chromium".into())
}

/// Whether the browser starts (`--version`). When it does not, a test that
/// needs it is not run: this says so on the terminal itself (not in the
/// test's captured output, which a passing test never shows) and how to run
/// it, and returns `false` — unless `LODCLOTH_REQUIRE_BROWSER` is set, as
/// `.ci/run` sets it, where a missing browser fails the test.
pub fn available(test: &str) -> bool {
    use std::io::Write as _;
    let exe = executable();
    let runs = Command::new(&exe)
        .arg("--version")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    if runs {
        return true;
    }
    assert!(
        std::env::var_os("LODCLOTH_REQUIRE_BROWSER").is_none(),
        "{test}: LODCLOTH_REQUIRE_BROWSER is set but `{exe} --version` does not run"
    );
    let _ = writeln!(
        std::io::stderr(),
        "\n*** NOT RUN: {test} needs a headless browser and `{exe} --version` does not run.\n\
         *** Install Debian's chromium (`apt-get install chromium`) or name one with LODCLOTH_CHROMIUM=…,\n\
         *** then run `cargo test --release --test bus -- {test}`. CI (`bash .ci/run`) always runs it.\n"
    );
    false
}

/// A headless Chromium with one page, driven over CDP.
pub struct Browser {
    child: Child,
    ws: Ws,
    next_id: u64,
    session: String,
    _profile: tempfile::TempDir,
}

impl Browser {
    pub async fn open(url: &str) -> Browser {
        let exe = executable();
        let profile = tempfile::tempdir().expect("profile dir");
        // SwiftShader gives WebGL without a GPU; the network flags keep
        // Chromium off everything but loopback.
        let child = Command::new(&exe)
            .args([
                "--headless",
                "--no-sandbox",
                "--use-angle=swiftshader",
                "--enable-unsafe-swiftshader",
                "--window-size=1400,900",
                "--remote-debugging-port=0",
                "--no-first-run",
                "--disable-background-networking",
                "--disable-component-update",
                "--disable-sync",
                "--disable-quic",
            ])
            .arg(format!("--user-data-dir={}", profile.path().display()))
            .arg("about:blank")
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap_or_else(|e| panic!("starting {exe}: {e} (install Debian's chromium, as .ci/run does)"));
        // Chromium writes its DevTools port and browser path here.
        let active = profile.path().join("DevToolsActivePort");
        let deadline = Instant::now() + Duration::from_secs(30);
        let endpoint = loop {
            if let Ok(text) = std::fs::read_to_string(&active) {
                let mut lines = text.lines();
                if let (Some(port), Some(path)) = (lines.next(), lines.next()) {
                    break format!("ws://127.0.0.1:{port}{path}");
                }
            }
            assert!(Instant::now() < deadline, "Chromium wrote no DevToolsActivePort");
            tokio::time::sleep(Duration::from_millis(100)).await;
        };
        let (ws, _) = within(10, "CDP connect", tokio_tungstenite::connect_async(&endpoint))
            .await
            .expect("CDP WebSocket");
        let mut b = Browser {
            child,
            ws,
            next_id: 0,
            session: String::new(),
            _profile: profile,
        };
        let target = b.call("Target.createTarget", json!({ "url": url })).await;
        let attached = b
            .call(
                "Target.attachToTarget",
                json!({ "targetId": target["targetId"], "flatten": true }),
            )
            .await;
        b.session = attached["sessionId"].as_str().expect("a session id").to_string();
        b
    }

    /// A CDP command on the page's session (the browser's before attaching).
    pub async fn call(&mut self, method: &str, params: Value) -> Value {
        self.next_id += 1;
        let id = self.next_id;
        let mut msg = json!({ "id": id, "method": method, "params": params });
        if !self.session.is_empty() {
            msg["sessionId"] = json!(self.session);
        }
        self.ws
            .send(Message::Text(msg.to_string().into()))
            .await
            .expect("CDP send");
        loop {
            let m = within(30, method, self.ws.next())
                .await
                .expect("CDP open")
                .expect("CDP message");
            let Message::Text(t) = m else { continue };
            let v: Value = serde_json::from_str(t.as_str()).expect("CDP JSON");
            if v["id"] == json!(id) {
                assert!(v.get("error").is_none(), "{method}: {}", v["error"]);
                return v["result"].clone();
            }
        }
    }

    /// The value of a page expression (promises awaited).
    pub async fn eval(&mut self, expression: &str) -> Value {
        let r = self
            .call(
                "Runtime.evaluate",
                json!({ "expression": expression, "returnByValue": true, "awaitPromise": true }),
            )
            .await;
        assert!(
            r.get("exceptionDetails").is_none(),
            "{expression}: {}",
            r["exceptionDetails"]
        );
        r["result"]["value"].clone()
    }

    /// Poll `expression` until it is true.
    pub async fn wait_for(&mut self, seconds: u64, what: &str, expression: &str) {
        let deadline = Instant::now() + Duration::from_secs(seconds);
        while self.eval(expression).await != json!(true) {
            if Instant::now() > deadline {
                let stats = self.eval("JSON.stringify(window.lodclothStats ?? null)").await;
                panic!("{what}: not within {seconds} s; page stats: {stats}");
            }
            tokio::time::sleep(Duration::from_millis(200)).await;
        }
    }

    /// A real mouse click at the centre of the element `selector`.
    pub async fn click(&mut self, selector: &str) {
        let at = self
            .eval(&format!(
                "(() => {{ const r = document.querySelector({selector:?}).getBoundingClientRect(); \
                 return [r.x + r.width / 2, r.y + r.height / 2]; }})()"
            ))
            .await;
        for kind in ["mousePressed", "mouseReleased"] {
            self.call(
                "Input.dispatchMouseEvent",
                json!({ "type": kind, "x": at[0], "y": at[1], "button": "left", "clickCount": 1 }),
            )
            .await;
        }
    }

    /// A left-button mouse event at client pixel (`x`, `y`) through CDP's
    /// `Input.dispatchMouseEvent` (the page sees trusted pointer events):
    /// `kind` is `mousePressed`, `mouseMoved` or `mouseReleased`; `held`
    /// says whether the button is down during it.
    pub async fn mouse(&mut self, kind: &str, x: f64, y: f64, held: bool) {
        self.call(
            "Input.dispatchMouseEvent",
            json!({ "type": kind, "x": x, "y": y, "button": "left", "buttons": u8::from(held), "clickCount": 1 }),
        )
        .await;
    }

    /// Press the left button at (`x`, `y`).
    pub async fn mouse_press(&mut self, x: f64, y: f64) {
        self.mouse("mousePressed", x, y, true).await;
    }

    /// Move to (`x`, `y`) with the left button held.
    pub async fn mouse_drag_to(&mut self, x: f64, y: f64) {
        self.mouse("mouseMoved", x, y, true).await;
    }

    /// Release the left button at (`x`, `y`).
    pub async fn mouse_release(&mut self, x: f64, y: f64) {
        self.mouse("mouseReleased", x, y, false).await;
    }

    pub async fn screenshot(&mut self, path: &Path) -> Vec<u8> {
        use base64::Engine;
        let r = self.call("Page.captureScreenshot", json!({ "format": "png" })).await;
        let png = base64::engine::general_purpose::STANDARD
            .decode(r["data"].as_str().expect("screenshot data"))
            .expect("base64 PNG");
        std::fs::write(path, &png).expect("writing the screenshot");
        png
    }
}

impl Drop for Browser {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
