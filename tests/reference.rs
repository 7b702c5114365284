//! Reference-column sessions on non-uniform time stamps, plus static runs: the reader,
//! the derived ε and the fit work together.

use crate::common::fit_session;
use crosscal::estimate::{CoefStatus, FitOptions};
use crosscal::frames::{Mount, Stand, V3};
use crosscal::model::{forward, State};
use crosscal::motion::Conic;
use crosscal::session::Session;
use crosscal::simulate::UnitTruth;
use crosscal::units::SensorKind;
use std::fmt::Write;

const G: f64 = 9.80665;

fn write_reference_session(dir: &std::path::Path) -> UnitTruth {
    let truth = UnitTruth::paper();
    let gt = truth.model.terms(SensorKind::Gyro);
    let at = truth.model.terms(SensorKind::Accel);
    let gv = truth.term_values(SensorKind::Gyro);
    let av = truth.term_values(SensorKind::Accel);
    let deg = 180.0 / std::f64::consts::PI;
    let mut runs = Vec::new();
    let mounts = [["+x", "+y", "+z"], ["+y", "+z", "+x"], ["+z", "+x", "+y"]];
    for (mi, names) in mounts.iter().enumerate() {
        let mount = Mount::parse(names).unwrap();
        for (ri, &(alpha, rate)) in [(10.0, 10.0), (10.0, -10.0), (20.0, 20.0)].iter().enumerate() {
            let c = Conic::from_deg(alpha, rate, 15.0);
            let name = format!("ref{mi}{ri}");
            let mut text = String::from(
                "# reference columns, jittered clock\nt,gx,gy,gz,ax,ay,az,wx_ref,wy_ref,wz_ref,ax_ref,ay_ref,az_ref\n",
            );
            for k in 0..3600 {
                // Irregular sampling: 10 ms ± up to 3 ms, deterministic.
                let t = k as f64 * 0.01 + 0.003 * ((k * 7919 % 13) as f64 / 13.0 - 0.5);
                let kin = c.at(t, G);
                let s = State {
                    t_session_s: t,
                    w: mount.to_sensor(kin.w_rad_s).xyz,
                    e: mount.to_sensor(kin.e_rad_s2).xyz,
                    a: mount.to_sensor(kin.a_m_s2).xyz,
                    temp_c: f64::NAN,
                    temp_rate_c_s: f64::NAN,
                };
                let ug = forward(&gt, &gv, &s);
                let ua = forward(&at, &av, &s);
                let w = kin.w_rad_s.xyz;
                let a = kin.a_m_s2.xyz;
                let _ = writeln!(
                    text,
                    "{t},{},{},{},{},{},{},{},{},{},{},{},{}",
                    ug[0] * deg,
                    ug[1] * deg,
                    ug[2] * deg,
                    ua[0] / G,
                    ua[1] / G,
                    ua[2] / G,
                    w[0] * deg,
                    w[1] * deg,
                    w[2] * deg,
                    a[0] / G,
                    a[1] / G,
                    a[2] / G
                );
            }
            std::fs::write(dir.join(format!("{name}.csv")), text).unwrap();
            runs.push(format!(
                "{{\"name\": \"{name}\", \"file\": \"{name}.csv\", \"motion\": {{\"kind\": \"reference\"}}, \"mount\": [\"{}\", \"{}\", \"{}\"]}}",
                names[0], names[1], names[2]
            ));
        }
    }
    // Two static poses (accelerometer only sees gravity; gyro sees nothing).
    for (i, up) in [[0.0, 0.0, 1.0], [0.0, 1.0, 0.0]].iter().enumerate() {
        let name = format!("static{i}");
        let mut text = String::from("t,gx,gy,gz,ax,ay,az\n");
        let a_stand = V3::<Stand>::new([up[0] * G, up[1] * G, up[2] * G]);
        let s = State { a: Mount::identity().to_sensor(a_stand).xyz, ..Default::default() };
        let ua = forward(&at, &av, &s);
        for k in 0..500 {
            let _ = writeln!(text, "{},0,0,0,{},{},{}", k as f64 * 0.01, ua[0] / G, ua[1] / G, ua[2] / G);
        }
        std::fs::write(dir.join(format!("{name}.csv")), text).unwrap();
        runs.push(format!(
            "{{\"name\": \"{name}\", \"file\": \"{name}.csv\", \"motion\": {{\"kind\": \"static\", \"up_stand\": [{}, {}, {}]}}}}",
            up[0], up[1], up[2]
        ));
    }
    let manifest = format!(
        "{{\"format\": \"crosscal-session/1\", \"serial\": \"REF-1\", \"units\": {{\"gyro\": \"deg/s\", \"accel\": \"g\", \"time\": \"s\"}}, \"stand\": {{\"g\": {G}}}, \"runs\": [{}]}}",
        runs.join(",\n")
    );
    std::fs::write(dir.join("session.json"), manifest).unwrap();
    truth
}

#[test]
fn reference_columns_on_irregular_clock_fit_the_paper_unit() {
    let d = tempfile::tempdir().unwrap();
    let truth = write_reference_session(d.path());
    let s = Session::load(&d.path().join("session.json")).unwrap();
    assert_eq!(s.runs.len(), 11);
    let fit = fit_session(&s, &crosscal::model::Model::default_model(), &FitOptions::default()).unwrap();
    for c in fit.gyro.coefficients.iter().chain(&fit.accel.coefficients) {
        assert_eq!(c.status, CoefStatus::Fitted, "{}", c.name);
        let t = truth.value(&c.name).unwrap();
        // ε comes from the local-polynomial derivative of ω_ref on the jittered clock:
        // accurate to ~1e-7 relative, so ε coefficients to ~1e-7 s, the rest tighter.
        let tol = if c.name.starts_with("gyro.e_") { 1e-6 } else { 1e-7 };
        assert!((c.value - t).abs() < tol, "{} = {} (true {t})", c.name, c.value);
    }
}
