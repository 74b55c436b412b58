//! Issue 22: each level's prediction under input (its error under the
//! scene's standard drags, `lodcloth_core::estimate::touched`), made by the
//! daemon in the background and published in `info`, `Metrics` and switch
//! replies; a `max_error` switch while a client touches the cloth chooses
//! by it. The truth: the same levels prepared and predicted again in this
//! process, without the daemon or a cache.

use crate::daemon;

use std::sync::Arc;
use std::time::Duration;

use daemon::*;
use lodcloth::estimate::Method;
use lodcloth::plan::{Level, Preparer};
use lodcloth::proto::{v1, WireLevel};
use lodcloth::service::config::ServiceConfig;

/// Each level's (scripted prediction, prediction under input), prepared in
/// this process from the test daemon's own config.
fn in_process(names: (&str, &str)) -> Vec<(Level, f64, f64)> {
    let dir = tempfile::tempdir().expect("temp dir");
    let config = ServiceConfig::from_toml(&config_text(free_port(), dir.path(), names), "truth").expect("config");
    let plan = Arc::new(config.instances[0].clone());
    let preparer = Preparer::new(plan.clone(), config.estimation, None);
    plan.levels
        .iter()
        .map(|&level| {
            let p = preparer.prepare(level, Method::Same).expect("prepares");
            let t = preparer
                .predict_touched(&p, &|| false)
                .expect("predicts")
                .expect("a cloth");
            (level, p.predicted_error, t.error)
        })
        .collect()
}

/// The coarsest level whose error (`pick`) is at most `bound`.
fn cheapest(levels: &[(Level, f64, f64)], bound: f64, pick: fn(&(Level, f64, f64)) -> f64) -> Option<Level> {
    let mut sorted = levels.to_vec();
    sorted.sort_by_key(|l| l.0.nodes());
    sorted.into_iter().find(|l| pick(l) <= bound).map(|l| l.0)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn each_level_gets_a_prediction_under_input_and_max_error_chooses_by_it_while_touched() {
    let _serial = daemon::serial().await;
    let names = ("drag", "drag-b");
    let truth = tokio::task::spawn_blocking(move || in_process(names))
        .await
        .expect("in process");
    let d = Daemon::start(names);
    let c = client(&[d.endpoint()]).await;
    wait_info(&c, "drag").await;

    // Every level's prediction under input appears in `info`, equal to the
    // one made here.
    let info = within(120, "every level predicted under input", async {
        loop {
            let info = c.info("drag").await.expect("info");
            if info.levels.iter().all(|l| l.predicted_error_under_input.is_some()) {
                return info;
            }
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
    })
    .await;
    for (level, predicted, under_input) in &truth {
        let l = info
            .levels
            .iter()
            .find(|l| l.level.as_ref().map(Level::from_wire) == Some(Ok(*level)))
            .expect("the level in info");
        let got = l.predicted_error_under_input.expect("predicted");
        eprintln!(
            "{level}: predicted {:.3} %, under input {:.3} % (daemon {:.3} %)",
            100.0 * predicted,
            100.0 * under_input,
            100.0 * got
        );
        assert!(
            (got - under_input).abs() <= 1e-12 * under_input,
            "{level}: the daemon's prediction under input {got} against {under_input} made here"
        );
        assert_eq!(l.predicted_error, Some(*predicted), "{level}: the scripted prediction");
    }

    // The metrics of the live level carry it.
    let sub = c
        .session
        .declare_subscriber(lodcloth::service::keys::metrics(PREFIX, "drag"))
        .await
        .expect("subscriber");
    let live = within(10, "metrics with the prediction under input", async {
        loop {
            let s = sub.recv_async().await.expect("metrics");
            let m = <v1::Metrics as prost::Message>::decode(s.payload().to_bytes().as_ref()).expect("metrics");
            if m.predicted_error_under_input.is_some() {
                return m;
            }
        }
    })
    .await;
    let level = Level::from_wire(live.level.as_ref().expect("level")).expect("a level");
    let expected = truth.iter().find(|t| t.0 == level).expect("the live level").2;
    assert_eq!(
        live.predicted_error_under_input,
        Some(expected),
        "the live level's, in Metrics"
    );

    // A bound the coarsest level meets on the script but only a finer one
    // meets under input: the finest level's prediction under input.
    let bound = truth.iter().max_by_key(|t| t.0.nodes()).expect("levels").2 * 1.001;
    let scripted = cheapest(&truth, bound, |t| t.1).expect("a level meets it on the script");
    let touched = cheapest(&truth, bound, |t| t.2).expect("a level meets it under input");
    assert_ne!(scripted, touched, "the bound does not tell the two predictions apart");
    let to = |max_error: f64| v1::SwitchRequest {
        target: Some(v1::switch_request::Target::MaxError(max_error)),
        method: String::new(),
        at_once: false,
    };
    let t = Duration::from_secs(60);
    let untouched = c.switch("drag", &to(bound), t).await.expect("switch untouched");
    assert_eq!(
        level_from(&untouched),
        scripted,
        "untouched: by the scripted predictions"
    );

    // A hand takes the cloth; once the metrics say it is touched, the same
    // request chooses by the predictions under input.
    let at = lodcloth::touch::Patch {
        u: 0.5,
        v: 1.0,
        radius: 0.05,
    };
    let grab = grab_where_it_is(1, at, 4.0, 0.1);
    within(5, "grab", c.input("drag", &grab)).await.expect("grab");
    within(10, "metrics saying touched", async {
        loop {
            let s = sub.recv_async().await.expect("metrics");
            let m = <v1::Metrics as prost::Message>::decode(s.payload().to_bytes().as_ref()).expect("metrics");
            if m.touched {
                return;
            }
        }
    })
    .await;
    let held = c.switch("drag", &to(bound), t).await.expect("switch touched");
    assert_eq!(level_from(&held), touched, "touched: by the predictions under input");
    assert_eq!(
        held.predicted_error_under_input,
        truth.iter().find(|x| x.0 == touched).map(|x| x.2),
        "the reply carries the new level's prediction under input"
    );
    d.shutdown().await.expect("clean shutdown");
}

fn level_from(r: &v1::SwitchReply) -> Level {
    Level::from_wire(r.level.as_ref().expect("level")).expect("a level")
}
