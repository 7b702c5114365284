//! An imperfect stand for the simulator: the session is recorded on a stand that does not
//! move exactly as its manifest says (cone angle, rate, phase, base tilt, speed ripple, a
//! wobble of the cone axis, a run on another mount, the Earth's rotation), while the
//! manifest written carries the nominal motion. Tests of `diagnose` and `fit --stand` use
//! it as the stand's troubles nobody declared.

use crate::frames::Mount;
use crate::motion::stand::StandMotion;
use crate::session::MotionSpec;

/// The Earth's rotation rate, rad/s (sidereal day).
pub const EARTH_RATE_RAD_S: f64 = 7.292_115e-5;

/// How the real stand differs from its manifest (all zero by default: a perfect stand).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct StandErrors {
    /// Added to every conic run's cone angle, degrees.
    pub cone_angle_deg: f64,
    /// Relative error of every conic run's rate (−0.005: 0.5 % slow).
    pub rate_scale: f64,
    /// Drift of the conic runs' rate from each run's first sample on: the relative change
    /// per second (−1e-4: the stand slows by 0.01 % of its rate each second), taken in turn
    /// (cyclically).
    pub rate_drift_per_s: Vec<f64>,
    /// Starting phase offset of the conic runs, degrees, taken in turn (cyclically).
    pub phase_deg: Vec<f64>,
    /// Base tilt about the base's x and y axes, degrees (common to the runs).
    pub tilt_deg: [f64; 2],
    /// Speed ripple once and twice per revolution: relative amplitude of the rate and its
    /// phase in degrees (`[[r1, ψ1], [r2, ψ2]]`).
    pub ripple: [[f64; 2]; 2],
    /// Cone-axis wobble once per revolution: amplitude and phase, degrees.
    pub wobble_deg: [f64; 2],
    /// Runs recorded on another mount than the manifest declares: (run name, true mount).
    pub mounts: Vec<(String, Mount)>,
    /// The Earth's rotation, not declared in the manifest: (latitude, heading), degrees.
    pub earth: Option<[f64; 2]>,
    /// The stand logs its angle (an encoder) with this resolution, degrees (0: exact): each
    /// conic run's CSV gets a `theta_deg` column, named by the run's `angle_column` in the
    /// manifest. Not an imperfection: it is what lets a fit follow the others.
    pub encoder_deg: Option<f64>,
    /// The encoder's zero is off the stand's: its logged angle reads this many degrees
    /// more than the stand's angle.
    pub encoder_offset_deg: f64,
    /// Each conic run is recorded from rest: the stand's rate rises from 0 to its own over
    /// this many seconds (raised cosine, θ̇ = ω (1 − cos(π t/T))/2), so that its angle then
    /// lags the manifest's by ω T/2. 0: at speed from the first sample.
    pub spin_up_s: f64,
}

impl StandErrors {
    /// True when the stand moves exactly as declared (whether it logs its angle or not).
    pub fn is_zero(&self) -> bool {
        Self { encoder_deg: None, encoder_offset_deg: 0.0, ..self.clone() } == Self::default()
    }

    /// The angle an encoder of [`Self::encoder_deg`] logs for the true angle `theta_rad`,
    /// degrees (rounded to the resolution).
    pub fn logged_deg(&self, theta_rad: f64) -> Option<f64> {
        let res = self.encoder_deg?;
        let deg = theta_rad.to_degrees() + self.encoder_offset_deg;
        Some(if res > 0.0 { (deg / res).round() * res } else { deg })
    }

    /// The Earth's rate in a base whose x axis points `heading` degrees east of north
    /// (x, y horizontal, z up), rad/s.
    pub fn earth_base_rad_s(&self) -> [f64; 3] {
        let Some([lat, heading]) = self.earth else { return [0.0; 3] };
        let (lat, h) = (lat.to_radians(), heading.to_radians());
        let horizontal = EARTH_RATE_RAD_S * lat.cos();
        // North is `heading` to the left of x (x = heading east of north), y = x rotated 90° left.
        [horizontal * h.cos(), horizontal * h.sin(), EARTH_RATE_RAD_S * lat.sin()]
    }

    /// The stand's angle at `t_s` on motion `m` (the run's first sample at `t0_s`), with the
    /// spin-up from rest ([`Self::spin_up_s`]) when there is one: the motion's own angle
    /// otherwise.
    pub fn angle_at(&self, m: &StandMotion, t_s: f64, t0_s: f64) -> crate::motion::stand::Angle {
        let big_t = self.spin_up_s;
        let tau = t_s - t0_s;
        if big_t.is_nan() || big_t <= 0.0 {
            return m.angle(t_s);
        }
        if tau >= big_t {
            // After the spin-up the stand runs at speed, ω T/2 behind.
            return m.angle(t_s - big_t / 2.0);
        }
        // From the steady angle at the first sample, the ramp's law:
        // θ = θ(t0) + ω (τ/2 − T/(2π) sin(πτ/T)) (no ripple during the ramp).
        let (w, k) = (m.rate_rad_s, std::f64::consts::PI / big_t);
        let (sn, cs) = (k * tau).sin_cos();
        crate::motion::stand::Angle {
            theta: m.phase_rad + w * t0_s + w * (tau / 2.0 - sn / (2.0 * k)),
            rate: w * (1.0 - cs) / 2.0,
            accel: w * k * sn / 2.0,
        }
    }

    /// The stand's true motion of conic run number `conic_index` declared as `declared`,
    /// the run's first sample at `t0_s` (None unless conic).
    pub fn conic_motion(&self, declared: &MotionSpec, conic_index: usize, t0_s: f64) -> Option<StandMotion> {
        let MotionSpec::Conic { cone_angle_deg, rate_deg_s, phase_deg } = *declared else { return None };
        let in_turn = |v: &[f64]| if v.is_empty() { 0.0 } else { v[conic_index % v.len()] };
        let phase_off = in_turn(&self.phase_deg);
        let ripple = std::array::from_fn(|h| {
            let [r, psi] = self.ripple[h];
            // Speed ripple r·cos(hθ₀ + ψ) is the angle ripple (r/h)·sin(hθ₀ + ψ).
            let amp = r / (h + 1) as f64;
            let psi = psi.to_radians();
            [amp * psi.sin(), amp * psi.cos()]
        });
        let [wa, wp] = self.wobble_deg;
        Some(StandMotion {
            cone_angle_rad: (cone_angle_deg + self.cone_angle_deg).to_radians(),
            rate_rad_s: (rate_deg_s * (1.0 + self.rate_scale)).to_radians(),
            phase_rad: (phase_deg + phase_off).to_radians(),
            tilt_rad: self.tilt_deg.map(f64::to_radians),
            ripple_rad: ripple,
            wobble_rad: [wa.to_radians() * wp.to_radians().cos(), wa.to_radians() * wp.to_radians().sin()],
            earth_rad_s: self.earth_base_rad_s(),
            rate_drift_per_s: in_turn(&self.rate_drift_per_s),
            drift_from_s: t0_s,
        })
    }

    /// The true motion of a static run declared as `declared`: with the Earth's rotation
    /// (vertical part along its up, horizontal part along a heading in the plane
    /// perpendicular to it) when it is on.
    pub fn static_motion(&self, declared: &MotionSpec) -> MotionSpec {
        match (declared, self.earth) {
            (MotionSpec::Static { up_stand, earth_rate_rad_s }, Some(_))
                if earth_rate_rad_s.iter().all(|&x| x == 0.0) =>
            {
                let [x, y, up] = self.earth_base_rad_s();
                let [e1, e2] = horizontal_basis(*up_stand);
                let w = std::array::from_fn(|i| x * e1[i] + y * e2[i] + up * up_stand[i]);
                MotionSpec::Static { up_stand: *up_stand, earth_rate_rad_s: w }
            }
            _ => declared.clone(),
        }
    }

    /// The mount run `name` was really recorded on (the declared one unless listed).
    pub fn mount_of<'a>(&'a self, name: &str, declared: &'a Mount) -> &'a Mount {
        self.mounts.iter().find(|(n, _)| n == name).map_or(declared, |(_, m)| m)
    }

    /// Parses the `simulate` flag values: `--stand KEY=VALUE` with keys `cone` (deg),
    /// `rate` (relative), `phase` (deg, comma list), `tilt` (deg,deg), `ripple1` and
    /// `ripple2` (relative,phase deg), `wobble` (deg,phase deg), `drift` (relative per
    /// second, comma list), `earth` (lat,heading deg),
    /// `mount` (RUN:+y,+x,-z), `encoder` (resolution, deg), `encoder-offset` (deg) and
    /// `spinup` (s).
    pub fn set(&mut self, spec: &str) -> Result<(), String> {
        let (key, value) =
            spec.split_once('=').ok_or_else(|| format!("'{spec}': expected KEY=VALUE, e.g. cone=0.3"))?;
        let nums = |v: &str, n: usize| -> Result<Vec<f64>, String> {
            let out: Vec<f64> = v
                .split(',')
                .map(|x| x.trim().parse::<f64>().map_err(|_| format!("{key}: '{x}' is not a number")))
                .collect::<Result<_, _>>()?;
            if out.iter().any(|x| !x.is_finite()) || (n > 0 && out.len() != n) {
                return Err(format!("{key}: expected {n} finite number(s), found '{v}'"));
            }
            Ok(out)
        };
        match key {
            "cone" => self.cone_angle_deg = nums(value, 1)?[0],
            "rate" => self.rate_scale = nums(value, 1)?[0],
            "drift" => self.rate_drift_per_s = nums(value, 0)?,
            "phase" => self.phase_deg = nums(value, 0)?,
            "tilt" => self.tilt_deg = <[f64; 2]>::try_from(nums(value, 2)?).unwrap_or_default(),
            "ripple1" => self.ripple[0] = <[f64; 2]>::try_from(nums(value, 2)?).unwrap_or_default(),
            "ripple2" => self.ripple[1] = <[f64; 2]>::try_from(nums(value, 2)?).unwrap_or_default(),
            "wobble" => self.wobble_deg = <[f64; 2]>::try_from(nums(value, 2)?).unwrap_or_default(),
            "earth" => self.earth = Some(<[f64; 2]>::try_from(nums(value, 2)?).unwrap_or_default()),
            "encoder" => {
                let res = nums(value, 1)?[0];
                if !(0.0..=1.0).contains(&res) {
                    return Err(format!("encoder: resolution {res}°: expected 0 (exact) to 1 degree"));
                }
                self.encoder_deg = Some(res);
            }
            "encoder-offset" => self.encoder_offset_deg = nums(value, 1)?[0],
            "spinup" => {
                self.spin_up_s = nums(value, 1)?[0];
                if self.spin_up_s < 0.0 {
                    return Err(format!("spinup: {value} s: expected a duration ≥ 0"));
                }
            }
            "mount" => {
                let (run, m) =
                    value.split_once(':').ok_or_else(|| format!("mount: '{value}': expected RUN:+y,+x,-z"))?;
                let names: Vec<&str> = m.split(',').collect();
                let mount = Mount::parse(&names).map_err(|e| format!("mount: {e}"))?;
                self.mounts.push((run.to_string(), mount));
            }
            _ => {
                return Err(format!(
                    "'{key}': expected one of cone, rate, drift, phase, tilt, ripple1, ripple2, wobble, earth, mount, encoder, encoder-offset, spinup"
                ))
            }
        }
        Ok(())
    }
}

pub use crate::motion::stand::horizontal_basis;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_every_key_and_refuses_nonsense() {
        let mut s = StandErrors::default();
        for ok in ["cone=0.3", "rate=-0.005", "phase=1,2,3", "tilt=0.2,-0.1", "ripple1=0.005,30", "earth=48,20"] {
            s.set(ok).unwrap();
        }
        s.set("mount=cone+10:+y,+x,-z").unwrap();
        assert_eq!(s.phase_deg, vec![1.0, 2.0, 3.0]);
        assert_eq!(s.mounts.len(), 1);
        for bad in ["cone", "cone=x", "tilt=1", "mount=+x,+y", "mount=a:+x,+x,+z", "spin=1"] {
            assert!(s.set(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn the_speed_ripple_has_the_asked_relative_size() {
        let s = StandErrors { ripple: [[0.01, 30.0], [0.0; 2]], ..Default::default() };
        let m = s.conic_motion(&MotionSpec::Conic { cone_angle_deg: 10.0, rate_deg_s: 20.0, phase_deg: 0.0 }, 0, 0.0);
        let m = m.unwrap();
        let rel: Vec<f64> = (0..400).map(|k| m.angle(k as f64 * 0.05).rate / m.rate_rad_s - 1.0).collect();
        let max = rel.iter().copied().fold(0.0, f64::max);
        assert!((max - 0.01).abs() < 2e-4, "{max}");
    }
}
