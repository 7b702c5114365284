//! Every k-th sample of prepared runs, owned: what a search on reduced data works on (a
//! nonlinear effect's parameters, the stand's first estimates on a large session). The
//! motion of a conic stand is slow against the sampling, so the reduced runs hold the same
//! shapes at a k-th of the cost; the answers are then refined or judged on every sample.

use crate::estimate::FitRun;
use crate::motion::Track;

/// A run's reduced outputs: gyro, accelerometer, temperature.
type Outputs = (Vec<[f64; 3]>, Vec<[f64; 3]>, Option<Vec<f64>>);

/// Every k-th sample of each run (from its first), owned.
pub(super) struct Reduced {
    tracks: Vec<Track>,
    outputs: Vec<Outputs>,
}

impl Reduced {
    /// Every `k`-th sample of `runs`; a track for which `materialise` holds is stored as
    /// its sampled motion (the same numbers, without the kinematics worked out again at
    /// each evaluation of a search).
    pub(super) fn new(runs: &[FitRun<'_>], k: usize, materialise: impl Fn(&Track) -> bool) -> Self {
        let k = k.max(1);
        let every = |v: &[[f64; 3]]| v.iter().step_by(k).copied().collect::<Vec<_>>();
        let tracks =
            runs.iter().map(|r| r.track.every(k)).map(|t| if materialise(&t) { t.materialised() } else { t }).collect();
        let outputs = runs
            .iter()
            .map(|r| (every(r.gyro), every(r.accel), r.temp_c.map(|t| t.iter().step_by(k).copied().collect())))
            .collect();
        Self { tracks, outputs }
    }

    /// The reduced runs, each with the rest of its description from `runs` (the runs it
    /// was made from).
    pub(super) fn runs<'x>(&'x self, runs: &[FitRun<'x>]) -> Vec<FitRun<'x>> {
        runs.iter()
            .zip(&self.tracks)
            .zip(&self.outputs)
            .map(|((r, tr), (g, a, temp))| FitRun { track: tr, gyro: g, accel: a, temp_c: temp.as_deref(), ..*r })
            .collect()
    }
}

/// The step k that leaves about `target` samples of `runs` (1 when they hold fewer).
pub(super) fn step_for(runs: &[FitRun<'_>], target: usize) -> usize {
    let total: usize = runs.iter().map(FitRun::len).sum();
    total.div_ceil(target.max(1)).max(1)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keeps_every_kth_sample_from_the_first() {
        let rec = crate::session::Recording {
            t_s: (0..10).map(f64::from).collect(),
            gyro: (0..10).map(|i| [f64::from(i), 0.0, 0.0]).collect::<Vec<_>>().into(),
            accel: vec![[0.0; 3]; 10].into(),
            ..Default::default()
        };
        let motion = crate::session::MotionSpec::Conic { cone_angle_deg: 10.0, rate_deg_s: 30.0, phase_deg: 0.0 };
        let mount = crate::frames::Mount::identity();
        let track = crate::motion::track_for(&motion, &mount, &rec, 9.81, &Default::default());
        let run = FitRun {
            name: "r",
            track: &track,
            gyro: &rec.gyro,
            accel: &rec.accel,
            temp_c: None,
            temp_const_c: Some(25.0),
            start_s: None,
        };
        let red = Reduced::new(std::slice::from_ref(&run), 3, |_| false);
        let rr = red.runs(std::slice::from_ref(&run));
        assert_eq!(rr[0].len(), 4);
        assert!(rr[0].gyro.iter().map(|g| g[0]).eq([0.0, 3.0, 6.0, 9.0]));
        assert_eq!(rr[0].track.t_s[3].to_bits(), 9.0f64.to_bits());
        assert_eq!(step_for(std::slice::from_ref(&run), 4), 3);
        assert_eq!(step_for(std::slice::from_ref(&run), 100), 1);
    }
}
