//! The recording reader on arbitrary bytes: an error or a recording whose every value is
//! finite and whose time increases; never a panic.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    for reference in [false, true] {
        let opts = crosscal::session::ReadOptions { reference, strict: data.first().is_some_and(|b| b & 1 == 1), angle_column: None };
        let units = crosscal::units::Units::default();
        if let Ok(r) = crosscal::session::parse_recording(std::path::Path::new("f.csv"), data, &units, 9.80665, opts) {
            assert!(r.t_s.windows(2).all(|w| w[1] > w[0]));
            assert!(r.gyro.iter().chain(&r.accel).all(|v| v.iter().all(|x| x.is_finite())));
        }
    }
});
