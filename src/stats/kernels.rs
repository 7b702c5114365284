//! Small loops over contiguous samples compiled for the processor's widest vector unit:
//! pulp's runtime dispatch picks AVX-512 or AVX2 where the processor has them, else the
//! baseline. The arithmetic is the same element by element, in the same order (Rust does
//! not contract `y + a·x` into a fused multiply-add), so the numbers are those of the plain
//! loop, bit for bit, on every processor.

/// `y[i] += a·x[i]` for i < min(len y, len x).
pub fn axpy(y: &mut [f64], a: f64, x: &[f64]) {
    pulp::Arch::new().dispatch(Axpy { y, a, x });
}

/// [`axpy`] as a `pulp` operation: its body is inlined into the function compiled for the
/// vector unit.
struct Axpy<'a> {
    y: &'a mut [f64],
    a: f64,
    x: &'a [f64],
}

impl pulp::WithSimd for Axpy<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) {
        for (y, &x) in self.y.iter_mut().zip(self.x) {
            *y += self.a * x;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axpy_is_the_plain_loop_bit_for_bit() {
        let x: Vec<f64> = (0..1037).map(|i| (i as f64 * 0.37).sin() * 1e3).collect();
        let mut y: Vec<f64> = (0..1040).map(|i| (i as f64 * 0.11).cos() / 7.0).collect();
        let mut want = y.clone();
        for (w, &v) in want.iter_mut().zip(&x) {
            *w += 0.3 * v;
        }
        axpy(&mut y, 0.3, &x);
        assert_eq!(
            y.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            want.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
        );
    }
}
