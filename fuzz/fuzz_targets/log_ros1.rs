//! The log reader on arbitrary bytes written as a `.bag` file (seeds: fuzz/corpus/logs/seed.bag):
//! an error, or samples with their warnings; never a panic, an abort or a hang.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let dir = std::env::temp_dir().join(format!("crosscal-fuzz-{}", std::process::id()));
    let _ = std::fs::create_dir_all(&dir);
    let path = dir.join("input.bag");
    if std::fs::write(&path, data).is_err() {
        return;
    }
    let opts = crosscal::session::logs::ReadOptions::default();
    if let Ok((contents, stats)) = crosscal::session::logs::list(&path, &opts) {
        assert_eq!(contents.streams.len(), stats.len());
    }
});
