//! User effects against the catalogue (`cargo bench --bench user_effect`): the same fit with
//! the catalogue's `gyro-quadratic` (three coefficients, q_i · w_i² on channel i) and with
//! the same physics written as three user effects in an effects file. Prints both times
//! and their ratio (issue 37 asks for at most 2×) and checks the two fits agree.

use crosscal::estimate::{fit, FitRequest};
use crosscal::model::{user, Model};
use crosscal::simulate::{conic_plan, cyclic_mounts, SimConfig};
use std::time::Instant;

const EFFECTS: &str = r#"
[[effect]]
id = "user-quadratic-x"
sensor = "gyro"
output = "x"
expr = "q * w_x^2"
coefficients = ["q"]

[[effect]]
id = "user-quadratic-y"
sensor = "gyro"
output = "y"
expr = "q * w_y^2"
coefficients = ["q"]

[[effect]]
id = "user-quadratic-z"
sensor = "gyro"
output = "z"
expr = "q * w_z^2"
coefficients = ["q"]
"#;

/// Best wall time of `reps` fits, s, and the last fit.
fn best_fit(session: &crosscal::session::Session, model: &Model, reps: usize) -> (f64, crosscal::estimate::Fit) {
    let mut best = f64::INFINITY;
    let mut last = None;
    for _ in 0..reps {
        let t0 = Instant::now();
        let f = fit(&FitRequest::session(model, session)).expect("fit").fit;
        best = best.min(t0.elapsed().as_secs_f64());
        last = Some(f);
    }
    (best, last.expect("one fit"))
}

fn main() {
    let mut c = SimConfig::paper();
    c.runs = conic_plan(&[10.0, -10.0, 20.0], &[10.0, 20.0], &cyclic_mounts(3), 36.0);
    c.gyro_noise_deg_s = 0.002;
    c.accel_noise_g = 2e-5;
    c.truth.model.add_effect("gyro-quadratic").expect("catalogue effect");
    c.truth.values.insert("gyro.q_x".into(), 1e-3);
    let session = c.generate();
    let samples = session.n_samples();

    let loaded = user::load_str("bench.toml", EFFECTS).expect("effects");
    user::register(&loaded);
    let mut catalogue = Model::default_model();
    catalogue.add_effect("gyro-quadratic").expect("catalogue effect");
    let mut mine = Model::default_model();
    for e in &loaded {
        mine.add_user(std::sync::Arc::clone(e));
    }
    let reps = 15;
    let (t_cat, f_cat) = best_fit(&session, &catalogue, reps);
    let (t_user, f_user) = best_fit(&session, &mine, reps);
    let q_cat = f_cat.gyro.coefficients.iter().find(|c| c.name == "gyro.q_x").expect("q_x").value;
    let q_user = f_user.gyro.coefficients.iter().find(|c| c.name == "user-quadratic-x.q").expect("q").value;
    assert!((q_cat - q_user).abs() <= 1e-9 * q_cat.abs().max(1e-12), "{q_cat} vs {q_user}");
    println!("fit, {samples} samples, default model + 3 coefficients (best of {reps})");
    println!("catalogue gyro-quadratic | {t_cat:.3} s");
    println!("three user effects       | {t_user:.3} s");
    println!("ratio user / catalogue   | {:.2}×", t_user / t_cat);
}
