//! The manifest reader on arbitrary text: an error or a manifest within the limits.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    if let Ok(m) = crosscal::session::parse_manifest(std::path::Path::new("s.json"), &text) {
        let lim = crosscal::session::LIMITS;
        assert!((lim.g_m_s2.0..=lim.g_m_s2.1).contains(&m.g_m_s2));
        assert!(!m.runs.is_empty());
    }
});
