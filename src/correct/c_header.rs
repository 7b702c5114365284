//! A profile as a self-contained C99 header: `crosscal_correct()` applies the profile's
//! linear correction with the same constants and the same fused multiply-adds as
//! [`super::Streaming::push`], so on a unit's controller it gives the bits crosscal gives.
//!
//! For a profile whose gyro has no C_ε and no further effects, `push` computes per sample
//! (module docs of [`super`], `M = (A + h₀E)⁻¹` with E = 0)
//! ```text
//! ω̂ = C_ω⁻¹ (u_g − b_g) = M_g u_g + c_g,   c_g = −C_ω⁻¹ b_g
//! â = K⁻¹ (u_a − b_a)   = M_a u_a + c_a,   c_a = −K⁻¹ b_a
//! ```
//! each row as `fma(m_i2, u_2, fma(m_i1, u_1, fma(m_i0, u_0, c_i)))`; its remaining terms
//! (the derivative's share through D = M E = 0) add exact zeros. The header holds M and c as
//! hexadecimal floating constants (exact) and repeats that arithmetic with C99's `fma()`,
//! which is correctly rounded like Rust's `mul_add`: the outputs are equal bit for bit (an
//! exact zero may differ in sign only). The function has no state and no time stamps.
//!
//! What it cannot apply is listed, and `CROSSCAL_CORRECT_EXACT` is 0 then: C_ε (it needs the
//! derivative of the corrected rate), g-sensitivity, temperature and the other effects
//! crosscal inverts by fixed-point passes, a dead zone. Those profiles are still exported —
//! the function then applies b, C_ω and K only, as the other exports keep what their target
//! holds — so a build can refuse them with `#if !CROSSCAL_CORRECT_EXACT`. A time delay changes
//! no value (crosscal re-stamps the output), so it is noted but keeps the header exact.

use super::{Calibration, CorrectError};
use crate::profile::interop::unheld;
use crate::profile::Profile;
use std::fmt::Write;

/// C99 hexadecimal floating constant of `x` (exact), e.g. `0x1.8p+1` for 3.
fn hex(x: f64) -> String {
    if !x.is_finite() {
        return if x.is_nan() {
            "NAN".into()
        } else if x > 0.0 {
            "INFINITY".into()
        } else {
            "-INFINITY".into()
        };
    }
    let bits = x.to_bits();
    let sign = if bits >> 63 == 1 { "-" } else { "" };
    let exp = ((bits >> 52) & 0x7ff) as i64;
    let frac = bits & ((1u64 << 52) - 1);
    let (lead, e) = match (exp, frac) {
        (0, 0) => return format!("{sign}0x0p+0"),
        (0, _) => (0, -1022),
        _ => (1, exp - 1023),
    };
    let digits = format!("{frac:013x}");
    let digits = digits.trim_end_matches('0');
    let point = if digits.is_empty() { String::new() } else { format!(".{digits}") };
    format!("{sign}0x{lead}{point}p{e:+}")
}

fn c_matrix(s: &mut String, name: &str, what: &str, m: &[[f64; 3]; 3], c: &[f64; 3]) {
    let _ = writeln!(s, "    /* {what} */");
    let _ = writeln!(s, "    static const double {name}_m[3][3] = {{");
    for row in m {
        let cells: Vec<String> = row.iter().map(|v| format!("{} /* {v:?} */", hex(*v))).collect();
        let _ = writeln!(s, "        {{{}}},", cells.join(", "));
    }
    let _ = writeln!(s, "    }};");
    let cells: Vec<String> = c.iter().map(|v| format!("{} /* {v:?} */", hex(*v))).collect();
    let _ = writeln!(s, "    static const double {name}_c[3] = {{{}}};", cells.join(", "));
}

const C_EPS: &str = "gyro-angular-acceleration";

/// The profile as a C99 header defining `static inline void crosscal_correct(const double
/// gyro_in[3], const double accel_in[3], double gyro_out[3], double accel_out[3])` and
/// `CROSSCAL_CORRECT_EXACT`, and what the function does not apply (module docs). Inputs and
/// outputs are in the units [`super::Streaming`] takes: rad/s and m/s² in the unit's axes
/// (recordings in deg/s or g converted as crosscal's reader does; raw units as recorded).
/// Fails only when the profile's matrices cannot be inverted.
pub fn to_c_header(p: &Profile) -> Result<(String, Vec<String>), CorrectError> {
    let cal = Calibration::from_profile(p)?;
    let [(mg, cg), (ma, ca)] = super::streaming::linear_constants(&cal);
    let all_but = |id: &str| -> Vec<&str> { p.effects.iter().map(String::as_str).filter(|e| *e != id).collect() };
    let mut lost = unheld(
        p,
        &all_but(C_EPS),
        "C_eps needs the derivative of the corrected rate, which a stateless function does not have (refit without the effect for an exact header)",
    );
    let held = ["gyro-bias", "gyro-scale-coupling", "accel-bias", "accel-scale-coupling", C_EPS, "time-delay"];
    lost.extend(unheld(p, &held, "the function inverts only the biases and the scale/coupling matrices"));
    let exact = lost.is_empty();
    lost.extend(unheld(
        p,
        &all_but("time-delay"),
        "the values are crosscal's, but each estimates the truth that much before its time stamp (crosscal correct re-stamps the output)",
    ));
    // Text from the profile goes into a C comment: it must not end it.
    let safe = |t: &str| t.replace("*/", "* /");
    let mut s = String::new();
    let _ = writeln!(
        s,
        "/* crosscal correction of unit {}, profile {} ({})",
        p.serial,
        safe(&p.created_utc),
        safe(&p.tool)
    );
    let _ = writeln!(s, " *");
    let _ = writeln!(s, " * crosscal_correct() inverts the profile's linear model as crosscal's streaming corrector");
    let _ = writeln!(s, " * (crosscal::correct::Streaming::push) does, with the same constants and operations:");
    let _ = writeln!(s, " *   gyro_out  = C_w^-1 (gyro_in - b_g) = M_g gyro_in + c_g,   c_g = -C_w^-1 b_g");
    let _ = writeln!(s, " *   accel_out = K^-1 (accel_in - b_a)  = M_a accel_in + c_a,  c_a = -K^-1 b_a");
    let _ = writeln!(s, " * row i as fma(m_i2, u_2, fma(m_i1, u_1, fma(m_i0, u_0, c_i))): the same bits as crosscal.");
    let _ = writeln!(
        s,
        " * Units: gyro rad/s, accel m/s^2, the unit's own axes (crosscal's SI input; raw units as recorded)."
    );
    let _ = writeln!(s, " * C99 with <math.h> (link with -lm where needed); do not build it with -ffast-math.");
    let _ = writeln!(s, " * Not applied: {}", if lost.is_empty() { "nothing".into() } else { safe(&lost.join("; ")) });
    let _ = writeln!(s, " */");
    let _ = writeln!(s, "#ifndef CROSSCAL_CORRECT_H\n#define CROSSCAL_CORRECT_H\n\n#include <math.h>\n");
    let _ =
        writeln!(s, "/* 1 when crosscal_correct() applies the whole profile (its outputs equal crosscal's streaming");
    let _ = writeln!(s, "   correction bit for bit), 0 when it leaves out the effects listed above. */");
    let _ = writeln!(s, "#define CROSSCAL_CORRECT_EXACT {}\n", u8::from(exact));
    let _ = writeln!(s, "/* Corrects one sample of unit {}; the outputs may alias the inputs. */", p.serial);
    let _ = writeln!(s, "static inline void crosscal_correct(const double gyro_in[3], const double accel_in[3],");
    let _ = writeln!(s, "                                    double gyro_out[3], double accel_out[3])\n{{");
    c_matrix(&mut s, "gyro", "gyro: M_g = C_w^-1 (row-major), c_g = -C_w^-1 b_g", &mg, &cg);
    c_matrix(&mut s, "accel", "accelerometer: M_a = K^-1 (row-major), c_a = -K^-1 b_a", &ma, &ca);
    let _ = writeln!(s, "    const double g0 = gyro_in[0], g1 = gyro_in[1], g2 = gyro_in[2];");
    let _ = writeln!(s, "    const double a0 = accel_in[0], a1 = accel_in[1], a2 = accel_in[2];");
    let _ = writeln!(s, "    int i;");
    let _ = writeln!(s, "    for (i = 0; i < 3; i++) {{");
    let _ = writeln!(
        s,
        "        gyro_out[i] = fma(gyro_m[i][2], g2, fma(gyro_m[i][1], g1, fma(gyro_m[i][0], g0, gyro_c[i])));"
    );
    let _ = writeln!(
        s,
        "        accel_out[i] = fma(accel_m[i][2], a2, fma(accel_m[i][1], a1, fma(accel_m[i][0], a0, accel_c[i])));"
    );
    let _ = writeln!(s, "    }}\n}}\n\n#endif /* CROSSCAL_CORRECT_H */");
    Ok((s, lost))
}

#[cfg(test)]
mod tests {
    use super::hex;

    /// Hexadecimal constants name the value exactly (checked against values whose hex form is
    /// known), subnormals and signed zero included.
    #[test]
    fn hex_constants_are_exact() {
        assert_eq!(hex(1.0), "0x1p+0");
        assert_eq!(hex(3.0), "0x1.8p+1");
        assert_eq!(hex(-0.1), "-0x1.999999999999ap-4");
        assert_eq!(hex(0.0), "0x0p+0");
        assert_eq!(hex(-0.0), "-0x0p+0");
        assert_eq!(hex(f64::MIN_POSITIVE), "0x1p-1022");
        assert_eq!(hex(f64::from_bits(1)), "0x0.0000000000001p-1022");
        assert_eq!(hex(f64::MAX), "0x1.fffffffffffffp+1023");
    }
}
