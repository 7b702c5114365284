//! The rules reader on arbitrary text: an error or rules; never a panic.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    let _ = crosscal::check::rules::Rules::parse(std::path::Path::new("r.json"), &text);
});
