use lodcloth::scene::Scene;
fn main() {
    let scene = Scene::load(std::path::Path::new("config/scenes/hanging.toml")).unwrap();
    let mut sim = scene.build().unwrap();
    let t = std::time::Instant::now();
    let n = 3000;
    for _ in 0..n {
        sim.step();
    }
    println!(
        "{:.1} us/step, report {:?}",
        t.elapsed().as_secs_f64() * 1e6 / n as f64,
        sim.last_report()
    );
}
