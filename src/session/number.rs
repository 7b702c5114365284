//! Decimal numbers straight from CSV bytes, correctly rounded, for the common case only.
//!
//! [`scan`] reads a plain decimal (`[+-]digits[.digits][(e|E)[+-]digits]`) at the start of
//! a field and converts it to the nearest `f64` when it has at most 19 significant digits
//! and a decimal exponent q (after moving the point to the end of the digits) in
//! [−22, 22] — the numbers sensors and loggers write. Anything else returns `None` and
//! the caller parses the field with the general parser, so the result is always the
//! correctly rounded value (the one `str::parse` gives).
//!
//! With w the digits as an integer, the value is w·10^q:
//! - w ≤ 2^53: Clinger's fast path — w and 10^|q| are exact doubles, so one IEEE
//!   multiplication or division rounds the exact value once (Clinger, PLDI 1990).
//! - otherwise the Eisel–Lemire algorithm (Lemire, "Number parsing at a gigabyte per
//!   second", Softw. Pract. Exper. 51, 2021, §5): w normalised times a 128-bit
//!   approximation of 5^q, keeping 55 bits; within q ∈ [−27, 55] the truncated product
//!   always decides the rounding, so no fallback is needed in our range.

/// Largest |q| handled here (10^22 is the largest power of ten exact in an f64).
const MAX_Q: i32 = 22;

/// 10^k for k = 0..=22, each exact in an f64.
const POW10: [f64; 23] = [
    1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16, 1e17, 1e18, 1e19, 1e20,
    1e21, 1e22,
];

/// ⌊2^n / p⌋ by binary long division (p < 2^64, quotient < 2^128).
const fn pow2_div(n: u32, p: u128) -> u128 {
    let mut r: u128 = 0;
    let mut quo: u128 = 0;
    let mut bit = n as i64;
    while bit >= 0 {
        r = (r << 1) | (bit == n as i64) as u128;
        quo <<= 1;
        if r >= p {
            r -= p;
            quo |= 1;
        }
        bit -= 1;
    }
    quo
}

/// 5^q for q = −22..=22 as 128-bit mantissas with the top bit set, (high word, low word):
/// exact for q ≥ 0; for q < 0, ⌊2^(z+127) / 5^−q⌋ + 1 with z the bit length of 5^−q (the
/// rounding Eisel–Lemire's error bound assumes).
const POW5: [(u64, u64); 45] = {
    let mut t = [(0u64, 0u64); 45];
    let mut i = 0;
    while i < 45 {
        let q = i as i32 - MAX_Q;
        let mut p: u128 = 1;
        let mut k = 0;
        while k < q.unsigned_abs() {
            p *= 5;
            k += 1;
        }
        let m = if q >= 0 {
            p << p.leading_zeros()
        } else {
            let z = 128 - p.leading_zeros();
            pow2_div(z + 127, p) + 1
        };
        t[i] = ((m >> 64) as u64, m as u64);
        i += 1;
    }
    t
};

/// w · 10^q, correctly rounded, for 2^53 < w < 2^64 and |q| ≤ 22 (Lemire 2021, §5).
#[inline]
fn eisel_lemire(q: i32, w: u64) -> Option<f64> {
    let lz = w.leading_zeros();
    let w = w << lz;
    let (hi5, lo5) = POW5[(q + MAX_Q) as usize];
    let first = (w as u128) * (hi5 as u128);
    let (mut lo, mut hi) = (first as u64, (first >> 64) as u64);
    // 55 bits kept (52 explicit + implicit + 2 for rounding): refine with the low word of
    // 5^q only when the bits below them are all ones.
    const MASK: u64 = u64::MAX >> 55;
    if hi & MASK == MASK {
        let second_hi = (((w as u128) * (lo5 as u128)) >> 64) as u64;
        lo = lo.wrapping_add(second_hi);
        if second_hi > lo {
            hi += 1;
        }
    }
    let upper = (hi >> 63) as u32;
    let mut m = hi >> (upper + 9);
    // ⌊q·log2(10)⌋ + 63, then the binary exponent with the f64 bias.
    let power = ((q.wrapping_mul(152_170 + 65_536)) >> 16) + 63;
    let mut e = power + upper as i32 - lz as i32 + 1023;
    if e <= 0 || e >= 0x7FF {
        return None;
    }
    // Exactly half-way between two doubles (only possible for small |q|): round to even.
    if lo <= 1 && (-4..=23).contains(&q) && m & 3 == 1 && (m << (upper + 9)) == hi {
        m &= !1;
    }
    m += m & 1;
    m >>= 1;
    if m >= 2 << 52 {
        m = 1 << 52;
        e += 1;
    }
    m &= !(1 << 52);
    Some(f64::from_bits(m | ((e as u64) << 52)))
}

/// True when all eight bytes of `v` are ASCII digits.
#[inline]
fn eight_digits(v: u64) -> bool {
    const HI: u64 = 0xF0F0_F0F0_F0F0_F0F0;
    (v & HI) == 0x3030_3030_3030_3030 && (v.wrapping_add(0x0606_0606_0606_0606) & HI) == 0x3030_3030_3030_3030
}

/// The value of eight ASCII digits loaded little-endian (first digit in the low byte).
#[inline]
fn eight_value(v: u64) -> u64 {
    let v = v - 0x3030_3030_3030_3030;
    let v = (v * 10) + (v >> 8);
    (((v & 0x0000_00FF_0000_00FF).wrapping_mul(100 + (1_000_000 << 32)))
        .wrapping_add(((v >> 16) & 0x0000_00FF_0000_00FF).wrapping_mul(1 + (10_000 << 32))))
        >> 32
}

/// Digits from `s[i..]` appended to `w` (wrapping; the caller bounds the count): the end.
#[inline]
fn digits(s: &[u8], mut i: usize, w: &mut u64) -> usize {
    while let Some(chunk) = s.get(i..i + 8) {
        let mut b = [0u8; 8];
        b.copy_from_slice(chunk);
        let v = u64::from_le_bytes(b);
        if !eight_digits(v) {
            break;
        }
        *w = w.wrapping_mul(100_000_000).wrapping_add(eight_value(v));
        i += 8;
    }
    while let Some(&c) = s.get(i) {
        let d = c.wrapping_sub(b'0');
        if d > 9 {
            break;
        }
        *w = w.wrapping_mul(10).wrapping_add(d as u64);
        i += 1;
    }
    i
}

/// Zeros from `s[i..]`: the end.
#[inline]
fn zeros(s: &[u8], mut i: usize) -> usize {
    while s.get(i) == Some(&b'0') {
        i += 1;
    }
    i
}

/// The plain decimal at the start of `s` and the number of bytes it takes, or `None` when
/// `s` does not start with one this fast path converts (see the module docs).
#[inline]
pub(crate) fn scan(s: &[u8]) -> Option<(f64, usize)> {
    let neg = s.first() == Some(&b'-');
    let mut i = usize::from(matches!(s.first(), Some(b'-' | b'+')));
    let int_start = i;
    i = zeros(s, i);
    let mut w = 0u64;
    let sig_start = i;
    i = digits(s, i, &mut w);
    let mut sig = i - sig_start;
    let mut any = i > int_start;
    let mut q = 0i64;
    if s.get(i) == Some(&b'.') {
        i += 1;
        let frac_start = i;
        if sig == 0 {
            i = zeros(s, i);
        }
        let f = i;
        i = digits(s, i, &mut w);
        sig += i - f;
        q = -((i - frac_start) as i64);
        any |= i > frac_start;
    }
    if !any || sig > 19 {
        return None;
    }
    if let Some(b'e' | b'E') = s.get(i) {
        let mut j = i + 1;
        let eneg = s.get(j) == Some(&b'-');
        j += usize::from(matches!(s.get(j), Some(b'-' | b'+')));
        let start = j;
        let mut e = 0i64;
        while let Some(&c) = s.get(j) {
            let d = c.wrapping_sub(b'0');
            if d > 9 {
                break;
            }
            e = (e * 10 + d as i64).min(1 << 20);
            j += 1;
        }
        if j == start {
            return None;
        }
        q += if eneg { -e } else { e };
        i = j;
    }
    let v = if w == 0 {
        0.0
    } else if !(-(MAX_Q as i64)..=MAX_Q as i64).contains(&q) {
        return None;
    } else if w <= 1 << 53 {
        let f = w as f64;
        if q < 0 {
            f / POW10[(-q) as usize]
        } else {
            f * POW10[q as usize]
        }
    } else {
        eisel_lemire(q as i32, w)?
    };
    Some((if neg { -v } else { v }, i))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// `scan` of the whole text agrees bit for bit with `str::parse` (or declines).
    fn agrees(text: &str) -> Result<(), TestCaseError> {
        let want: f64 = text.parse().map_err(|e| TestCaseError::fail(format!("{text}: {e}")))?;
        if let Some((v, n)) = scan(text.as_bytes()) {
            prop_assert_eq!(n, text.len(), "{} read to {}", text, n);
            prop_assert_eq!(v.to_bits(), want.to_bits(), "{}: {} vs {}", text, v, want);
        }
        Ok(())
    }

    #[test]
    fn powers_of_five_match_the_published_table() {
        // Entries of the Eisel–Lemire table (Lemire 2021) for 5^-1, 5^0, 5^1, 5^-22.
        assert_eq!(POW5[MAX_Q as usize - 1], (0xcccc_cccc_cccc_cccc, 0xcccc_cccc_cccc_cccd));
        assert_eq!(POW5[MAX_Q as usize], (0x8000_0000_0000_0000, 0));
        assert_eq!(POW5[MAX_Q as usize + 1], (0xa000_0000_0000_0000, 0));
        assert_eq!(POW5[0], (0xf1c9_0080_baf7_2cb1, 0x5324_c68b_12dd_6339));
    }

    #[test]
    fn typical_logger_output_is_exact() {
        for t in [
            "0",
            "-0",
            "1",
            "0.01",
            "1.7360120825521914",
            "0.0021852819577377414",
            "-0.1638283164908205",
            "0.9830866245063603",
            "9.80665",
            "1e-5",
            "-2.5E+3",
            "123456789012345678",
            "9007199254740993",
            "0.30000000000000004",
            "4.9406564584124654e-324",
            "1.7976931348623157e308",
            "00012.500",
        ] {
            agrees(t).unwrap();
        }
        assert_eq!(scan(b"1.5,2"), Some((1.5, 3)));
        assert_eq!(scan(b"-.5 "), Some((-0.5, 3)));
        for declined in ["", "-", ".", "abc", "1e", "nan", "inf", "12345678901234567890"] {
            assert!(scan(declined.as_bytes()).is_none(), "{declined}");
        }
    }

    #[test]
    fn half_way_cases_round_to_even() {
        // 2^53 + 1 and 2^53 + 3 are half-way between doubles.
        for t in ["9007199254740993", "9007199254740995", "9007199254740993.0", "900719925474099.3e1"] {
            agrees(t).unwrap();
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(20_000))]

        #[test]
        fn any_double_printed_shortest_reads_back(bits in any::<u64>()) {
            let v = f64::from_bits(bits);
            prop_assume!(v.is_finite());
            agrees(&format!("{v}"))?;
            agrees(&format!("{v:e}"))?;
        }

        #[test]
        fn any_digits_and_point_agree(w in 0u64..10_000_000_000_000_000_000, point in 0usize..21, e in -30i32..30, neg in any::<bool>()) {
            let digits = w.to_string();
            let p = point.min(digits.len());
            let sign = if neg { "-" } else { "" };
            agrees(&format!("{sign}{}.{}", &digits[..p], &digits[p..]))?;
            agrees(&format!("{sign}{}.{}e{e}", &digits[..p], &digits[p..]))?;
            agrees(&format!("{sign}0.000{digits}"))?;
        }
    }
}
