//! The datasheet quantities: name (as the `datasheet` rule kind names them), datasheet unit,
//! definition (IEEE Std 952-1997 / 1293-1998 terms) and what would measure it.

/// One quantity of the datasheet.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Spec {
    /// Name, `sensor.quantity`.
    pub name: &'static str,
    /// Datasheet unit.
    pub unit: &'static str,
    /// Definition, as in the reference (`docs/reference-datasheet.md`).
    pub definition: &'static str,
    /// The session or effect that would give it when the profile cannot.
    pub remedy: &'static str,
}

const fn s(name: &'static str, unit: &'static str, definition: &'static str, remedy: &'static str) -> Spec {
    Spec { name, unit, definition, remedy }
}

const NOISE: &str = "record the unit at rest and add its noise: `crosscal noise still/session.json --store STORE --serial UNIT` (or `crosscal fit --noise`)";
const REPEAT: &str = "two or more stored calibrations of the unit, each after a power cycle";
const TREND: &str = "stored calibrations of the unit on more than one date";

/// Every quantity, in the order the datasheet lists them.
pub const QUANTITIES: &[Spec] = &[
    s("gyro.bias", "deg/h", "output at zero input: the fitted bias b_i (at 20 degC when the model has temperature terms)", "the gyro-bias effect (in every preset)"),
    s("accel.bias", "mg", "output at zero input: the fitted bias b_i", "the accel-bias effect (in every preset)"),
    s("gyro.bias_repeatability", "deg/h", "turn-on to turn-on bias repeatability: 1 sigma of the bias over the unit's stored calibrations (one per power cycle; profiles fitted on the same files count once), with a 90 % chi-square interval", REPEAT),
    s("accel.bias_repeatability", "mg", "turn-on to turn-on bias repeatability: 1 sigma of the bias over the unit's stored calibrations (one per power cycle), with a 90 % chi-square interval", REPEAT),
    s("gyro.bias_instability", "deg/h", "in-run bias stability: the Allan deviation's flat minimum / 0.664 (IEEE 952 C.1.3), from the profile's noise reading; uncertainty half its 68 % interval", NOISE),
    s("accel.bias_instability", "ug", "in-run bias stability: the Allan deviation's flat minimum / 0.664 (IEEE 952 C.1.3); uncertainty half its 68 % interval", NOISE),
    s("gyro.arw", "deg/sqrt(h)", "angle random walk: white rate-noise density N (Allan deviation at slope -1/2, tau = 1 s), x 60; uncertainty half its 68 % interval", NOISE),
    s("accel.vrw", "m/s/sqrt(h)", "velocity random walk: white acceleration-noise density N x 60; uncertainty half its 68 % interval", NOISE),
    s("gyro.scale_factor_error", "ppm", "(s_i - 1) x 1e6 with s_i = |row i of C_w|, the scale factor of sensing axis i (see the axes decomposition)", "the gyro-scale-coupling effect"),
    s("accel.scale_factor_error", "ppm", "(s_i - 1) x 1e6 with s_i = |row i of K|", "the accel-scale-coupling effect"),
    s("gyro.nonlinearity", "ppm", "scale-factor nonlinearity, ppm of full scale: the largest departure of the fitted output from its straight line over +-FS, (|q_i| FS + |k3_i| FS^2) x 1e6, FS the calibrated range (--gyro-range)", "--effect gyro-quadratic and/or gyro-cubic, and the calibrated range (--gyro-range DEG_S)"),
    s("accel.nonlinearity", "ppm", "scale-factor nonlinearity, ppm of full scale: (|q_i| FS + |k3_i| FS^2) x 1e6, FS the calibrated range (--accel-range, 1 g by default)", "--effect accel-quadratic and/or accel-cubic"),
    s("gyro.asymmetry", "ppm", "scale-factor asymmetry: scale 1 + sa for positive and 1 - sa for negative input; sa_i x 1e6", "--effect gyro-scale-asymmetry"),
    s("accel.asymmetry", "ppm", "scale-factor asymmetry: sa_i x 1e6", "--effect accel-scale-asymmetry"),
    s("gyro.misalignment", "mrad", "axis-to-axis misalignment: non-orthogonality asin(n_i . n_j) of the sensing axes i, j (rows of C_w normalised); positive when closer than 90 deg", "the gyro-scale-coupling effect"),
    s("accel.misalignment", "mrad", "axis-to-axis misalignment: non-orthogonality asin(n_i . n_j) of the sensing axes (rows of K normalised)", "the accel-scale-coupling effect"),
    s("gyro.frame_alignment", "mrad", "axis-to-frame alignment: rotation vector (about x, y, z) of R, the rotation closest to the sensing axes (polar decomposition N = P R)", "the gyro-scale-coupling effect"),
    s("accel.frame_alignment", "mrad", "axis-to-frame alignment: rotation vector of the polar factor R of K's normalised rows", "the accel-scale-coupling effect"),
    s("gyro.g_sensitivity", "deg/h/g", "g-sensitivity g_ij: rate error of output i per g of specific force along j", "--effect gyro-g-sensitivity (re-mounts, two cone angles)"),
    s("gyro.g2_sensitivity", "deg/h/g^2", "g^2-sensitivity (anisoelasticity) n_i_jk: rate error of output i per g^2 of a_j a_k", "--effect gyro-anisoelastic"),
    s("gyro.angular_accel_sensitivity", "s", "angular-acceleration sensitivity C_eps (the paper's e_ij): rate error of output i per rad/s^2 about j", "the gyro-angular-acceleration effect (default preset)"),
    s("gyro.bias_tempco", "deg/h/degC", "temperature coefficient of bias: the end-point slope (b(T_hi) - b(T_lo)) / (T_hi - T_lo) of the fitted temperature-bias polynomial over the calibrated range (its linear term at 20 degC without a range)", "a thermal session and --effect gyro-temp-bias"),
    s("accel.bias_tempco", "mg/degC", "temperature coefficient of bias: end-point slope of the temperature-bias polynomial over the calibrated range", "a thermal session and --effect accel-temp-bias"),
    s("gyro.scale_tempco", "ppm/degC", "temperature coefficient of scale factor: end-point slope of the temperature-scale polynomial over the calibrated range, x 1e6", "a thermal session and --effect gyro-temp-scale"),
    s("accel.scale_tempco", "ppm/degC", "temperature coefficient of scale factor: end-point slope of the temperature-scale polynomial, x 1e6", "a thermal session and --effect accel-temp-scale"),
    s("gyro.thermal_hysteresis", "deg/h", "thermal hysteresis: the bias gap between warming and cooling at one temperature, 2 thy_i", "a thermal session warming and cooling, --effect gyro-temp-hysteresis"),
    s("accel.thermal_hysteresis", "mg", "thermal hysteresis: the bias gap between warming and cooling, 2 thy_i", "a thermal session warming and cooling, --effect accel-temp-hysteresis"),
    s("gyro.bias_trend", "deg/h/year", "long-term bias trend: weighted least-squares slope of the bias over the unit's calibrations against their dates", TREND),
    s("accel.bias_trend", "mg/year", "long-term bias trend: weighted least-squares slope of the bias against the calibrations' dates", TREND),
    s("gyro.scale_factor_trend", "ppm/year", "long-term scale-factor trend: weighted least-squares slope of the scale-factor error against the calibrations' dates", TREND),
    s("accel.scale_factor_trend", "ppm/year", "long-term scale-factor trend: weighted least-squares slope of the scale-factor error against the calibrations' dates", TREND),
];

/// The quantity called `name`.
pub fn spec(name: &str) -> Option<&'static Spec> {
    QUANTITIES.iter().find(|q| q.name == name)
}

/// The anchor of a quantity in `docs/reference-datasheet.md` (a heading `gyro.bias` is
/// `#gyrobias`, as Markdown renderers make anchors).
pub fn reference(name: &str) -> String {
    format!("docs/reference-datasheet.md#{}", name.replace('.', ""))
}
