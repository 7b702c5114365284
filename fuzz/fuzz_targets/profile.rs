//! The profile reader on arbitrary text: an error, or a profile that can correct.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    if let Ok(p) = crosscal::profile::Profile::from_json(std::path::Path::new("p.json"), &text) {
        assert!(crosscal::correct::Calibration::from_profile(&p).is_ok());
    }
});
