//! What makes a simulated session look like a real unit's: a session clock that runs on
//! across the runs, jittered time stamps, quantised outputs, SI output units, and
//! disturbances that are not in the effects catalogue (a stand wobble at twice the cone
//! frequency in some runs, a mechanical resonance not locked to the cone, a sensor that
//! saturates softly). Tests of `diagnose` use them as effects nobody told the tool about.

use crate::units::{SensorKind, AXES};

/// A disturbance outside the effects catalogue, added to the outputs (SI).
#[derive(Debug, Clone, PartialEq)]
pub enum Disturbance {
    /// A stand wobble: `amplitude` · sin(h θ + 0.7) on output `channel` (0..6: gyro x, y, z,
    /// accel x, y, z) in every `every`-th conic run (runs 0, every, 2·every, …).
    Wobble {
        /// Output channel 0..6.
        channel: usize,
        /// Harmonic of the cone phase.
        harmonic: u32,
        /// Amplitude, SI.
        amplitude: f64,
        /// In every n-th conic run.
        every: usize,
    },
    /// A sinusoid not locked to the cone (a resonance, mains): `amplitude` · sin(2π f t + 0.3)
    /// on output `channel` in every run.
    Sine {
        /// Output channel 0..6.
        channel: usize,
        /// Frequency, Hz.
        frequency_hz: f64,
        /// Amplitude, SI.
        amplitude: f64,
    },
    /// Soft saturation of a sensor's outputs: u → L tanh(u / L) per axis.
    Saturation {
        /// Sensor.
        sensor: SensorKind,
        /// Level L, SI.
        limit: f64,
    },
    /// A knee on one output: u → u + slope · max(u − threshold, 0) (a scale factor that
    /// changes above a level; a negative threshold with a negative slope acts below it).
    Knee {
        /// Output channel 0..6.
        channel: usize,
        /// Level above which the scale changes, SI.
        threshold: f64,
        /// Change of scale above it (0.03 = +3 %).
        slope: f64,
    },
    /// A turn-on bias: a different constant offset on one output in each run, drawn once per
    /// run (standard deviation `sigma`, SI) from a fixed sequence, so that every session
    /// with the same runs gets the same offsets.
    TurnOn {
        /// Output channel 0..6.
        channel: usize,
        /// Standard deviation of the offsets, SI.
        sigma: f64,
    },
    /// A hard clip of one output at ±limit.
    Clip {
        /// Output channel 0..6.
        channel: usize,
        /// Limit, SI.
        limit: f64,
    },
}

/// The `i`-th draw of a fixed standard normal sequence (SplitMix64 to two uniforms, then
/// Box–Muller): the same offsets for the same run on every call.
fn standard_normal(i: usize) -> f64 {
    let mix = |mut z: u64| {
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    };
    let seed = (i as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15).wrapping_add(0x2545_f491_4f6c_dd1d);
    let uniform = |z: u64| ((z >> 11) as f64 + 0.5) / (1u64 << 53) as f64;
    let (u1, u2) = (uniform(mix(seed)), uniform(mix(seed ^ 0x5851_f42d_4c95_7f2d)));
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

fn channel_of(s: &str) -> Result<(usize, f64), String> {
    let (sensor, axis) = s.split_once('-').ok_or_else(|| format!("'{s}': expected a channel like gyro-y"))?;
    let base = match sensor {
        "gyro" => 0,
        "accel" => 3,
        _ => return Err(format!("'{sensor}': expected gyro or accel")),
    };
    let a = AXES
        .iter()
        .position(|c| axis.len() == 1 && axis.starts_with(*c))
        .ok_or_else(|| format!("'{axis}': expected x, y or z"))?;
    // Amplitudes are given in deg/s (gyro) and g (accel).
    let k = if base == 0 { std::f64::consts::PI / 180.0 } else { 9.806_65 };
    Ok((base + a, k))
}

fn number(s: &str, what: &str) -> Result<f64, String> {
    let v: f64 = s.trim().parse().map_err(|_| format!("{what}: '{s}' is not a number"))?;
    if v.is_finite() {
        Ok(v)
    } else {
        Err(format!("{what}: '{s}' is not finite"))
    }
}

impl Disturbance {
    /// Parses `wobble:CHANNEL:HARMONIC:AMPLITUDE:EVERY`, `sine:CHANNEL:FREQ_HZ:AMPLITUDE`,
    /// `saturate:SENSOR:LIMIT`, `knee:CHANNEL:LEVEL:SLOPE`, `turnon:CHANNEL:SIGMA` or
    /// `clip:CHANNEL:LIMIT`
    /// (amplitudes, levels and limits in deg/s for the gyro, g for the accelerometer;
    /// channels like `gyro-y`; a slope is relative, 0.03 = +3 %).
    pub fn parse(s: &str) -> Result<Self, String> {
        let parts: Vec<&str> = s.split(':').collect();
        match parts.as_slice() {
            ["wobble", ch, h, a, every] => {
                let (channel, k) = channel_of(ch)?;
                let harmonic: u32 = h.parse().map_err(|_| format!("harmonic: '{h}' is not a whole number"))?;
                let every: usize = every.parse().map_err(|_| format!("every: '{every}' is not a whole number"))?;
                if harmonic == 0 || every == 0 {
                    return Err("wobble: harmonic and every must be at least 1".into());
                }
                Ok(Self::Wobble { channel, harmonic, amplitude: number(a, "amplitude")? * k, every })
            }
            ["sine", ch, f, a] => {
                let (channel, k) = channel_of(ch)?;
                let frequency_hz = number(f, "frequency")?;
                if frequency_hz <= 0.0 {
                    return Err("sine: the frequency must be positive".into());
                }
                Ok(Self::Sine { channel, frequency_hz, amplitude: number(a, "amplitude")? * k })
            }
            ["saturate", sensor, l] => {
                let sensor = match *sensor {
                    "gyro" => SensorKind::Gyro,
                    "accel" => SensorKind::Accel,
                    other => return Err(format!("'{other}': expected gyro or accel")),
                };
                let k = if sensor == SensorKind::Gyro { std::f64::consts::PI / 180.0 } else { 9.806_65 };
                let limit = number(l, "limit")? * k;
                if limit <= 0.0 {
                    return Err("saturate: the limit must be positive".into());
                }
                Ok(Self::Saturation { sensor, limit })
            }
            ["knee", ch, level, slope] => {
                let (channel, k) = channel_of(ch)?;
                Ok(Self::Knee { channel, threshold: number(level, "threshold")? * k, slope: number(slope, "slope")? })
            }
            ["turnon", ch, sd] => {
                let (channel, k) = channel_of(ch)?;
                let sigma = number(sd, "sigma")? * k;
                if sigma <= 0.0 {
                    return Err("turnon: the standard deviation must be positive".into());
                }
                Ok(Self::TurnOn { channel, sigma })
            }
            ["clip", ch, l] => {
                let (channel, k) = channel_of(ch)?;
                let limit = number(l, "limit")? * k;
                if limit <= 0.0 {
                    return Err("clip: the limit must be positive".into());
                }
                Ok(Self::Clip { channel, limit })
            }
            _ => Err(format!(
                "'{s}': expected wobble:CHANNEL:HARMONIC:AMPLITUDE:EVERY, sine:CHANNEL:FREQ_HZ:AMPLITUDE, saturate:SENSOR:LIMIT, knee:CHANNEL:LEVEL:SLOPE, turnon:CHANNEL:SIGMA or clip:CHANNEL:LIMIT"
            )),
        }
    }
}

/// Realism settings of a simulation (all off by default: the clean sessions of the paper).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Realism {
    /// Time runs on across the runs (each run's stamps continue the previous run's, after
    /// this pause, s); None: every run starts at t = 0.
    pub session_clock_gap_s: Option<f64>,
    /// Standard deviation of the time stamps' jitter, s (the samples are taken on a regular
    /// clock; only their stamps are jittered).
    pub jitter_s: f64,
    /// Output resolution (gyro deg/s or rad/s, accel g or m/s², in the file's units); 0 for none.
    pub quantum: [f64; 2],
    /// Write rad/s and m/s² instead of deg/s and g.
    pub si_units: bool,
    /// Disturbances outside the catalogue.
    pub disturbances: Vec<Disturbance>,
}

impl Realism {
    /// Applies the disturbances to one sample's outputs (SI): `theta` is the cone phase
    /// (None for non-conic runs), `conic_index` the run's index among the conic runs and
    /// `run_index` among all runs.
    pub fn disturb(
        &self,
        t_s: f64,
        theta: Option<f64>,
        (conic_index, run_index): (usize, usize),
        g: &mut [f64; 3],
        a: &mut [f64; 3],
    ) {
        for d in &self.disturbances {
            match *d {
                Disturbance::Wobble { channel, harmonic, amplitude, every } => {
                    if let Some(th) = theta.filter(|_| conic_index % every == 0) {
                        add(channel, amplitude * (f64::from(harmonic) * th + 0.7).sin(), g, a);
                    }
                }
                Disturbance::Sine { channel, frequency_hz, amplitude } => {
                    add(channel, amplitude * (std::f64::consts::TAU * frequency_hz * t_s + 0.3).sin(), g, a);
                }
                Disturbance::Knee { channel, threshold, slope } => {
                    let v = if channel < 3 { &mut g[channel] } else { &mut a[channel - 3] };
                    *v += slope * if threshold >= 0.0 { (*v - threshold).max(0.0) } else { (*v - threshold).min(0.0) };
                }
                Disturbance::TurnOn { channel, sigma } => add(channel, sigma * standard_normal(run_index), g, a),
                Disturbance::Clip { channel, limit } => {
                    let v = if channel < 3 { &mut g[channel] } else { &mut a[channel - 3] };
                    *v = v.clamp(-limit, limit);
                }
                Disturbance::Saturation { sensor, limit } => {
                    let v = if sensor == SensorKind::Gyro { &mut *g } else { &mut *a };
                    for x in v.iter_mut() {
                        *x = limit * (*x / limit).tanh();
                    }
                }
            }
        }
    }

    /// After a run's samples are made: outputs quantised in the file's units (`to_file`:
    /// SI → file unit factors for gyro and accel), stamps jittered (the truth was sampled
    /// on the regular clock).
    pub fn finish<R: rand::Rng>(&self, rec: &mut crate::session::Recording, to_file: [f64; 2], rng: &mut R) {
        if self.quantum.iter().any(|q| *q > 0.0) {
            let [qg, qa] = to_file;
            let (gyro, accel) = (rec.gyro.make_mut(), rec.accel.make_mut());
            for (g, a) in gyro.iter_mut().zip(accel.iter_mut()) {
                for i in 0..3 {
                    g[i] = self.quantise(SensorKind::Gyro, g[i] * qg) / qg;
                    a[i] = self.quantise(SensorKind::Accel, a[i] * qa) / qa;
                }
            }
        }
        if let Ok(j) = rand_distr::Normal::new(0.0, self.jitter_s) {
            if self.jitter_s > 0.0 {
                let mut t_s = rec.t_s.to_vec();
                for t in &mut t_s {
                    *t += rand_distr::Distribution::sample(&j, rng);
                }
                rec.t_s = t_s.into();
            }
        }
    }

    /// Rounds an output to the resolution of its sensor (file units).
    pub fn quantise(&self, sensor: SensorKind, v: f64) -> f64 {
        let q = self.quantum[usize::from(sensor == SensorKind::Accel)];
        if q > 0.0 {
            (v / q).round() * q
        } else {
            v
        }
    }
}

fn add(channel: usize, v: f64, g: &mut [f64; 3], a: &mut [f64; 3]) {
    if channel < 3 {
        g[channel] += v;
    } else if channel < 6 {
        a[channel - 3] += v;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_the_three_kinds_and_refuses_nonsense() {
        assert!(matches!(
            Disturbance::parse("wobble:gyro-y:2:0.01:3"),
            Ok(Disturbance::Wobble { channel: 1, harmonic: 2, every: 3, .. })
        ));
        assert!(matches!(Disturbance::parse("sine:accel-z:7.3:1e-4"), Ok(Disturbance::Sine { channel: 5, .. })));
        assert!(matches!(
            Disturbance::parse("saturate:gyro:30"),
            Ok(Disturbance::Saturation { sensor: SensorKind::Gyro, .. })
        ));
        for bad in ["wobble:gyro-q:2:1:1", "sine:gyro-x:-1:1", "saturate:gyro:0", "sine:gyro-x:nan:1", "hum"] {
            assert!(Disturbance::parse(bad).is_err(), "{bad}");
        }
    }
}
