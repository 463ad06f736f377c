//! Forward-mode automatic differentiation for the turbo model's Jacobians.
//!
//! The model's right-hand side is written once, generic over a [`Scalar`]: with `f64` it is the
//! plain evaluation; with [`Dual<N>`] (a value and its gradient with respect to `N` seeded
//! variables) the same code returns the exact partial derivatives. This gives `df/dx` (13 or 14
//! seeds) and `df/du` (6 seeds) to rounding error, with no finite-difference step to choose
//! across the model's kinks (linearized restriction regions, clamps), and an independent check
//! for the tests, which compare it against central differences.
//!
//! Branches (regions of a flow function, clamps) are taken on the value: a clamped quantity is a
//! constant (zero gradient), as it is for the one-sided derivative away from the kink.

use std::ops::{Add, Div, Mul, Neg, Sub};

/// The arithmetic the model needs: the four operations (also with an `f64` on the right), and
/// `sqrt`, `powf` with a constant exponent and `exp`. Comparisons go through [`Scalar::val`].
pub trait Scalar:
    Copy
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + Add<f64, Output = Self>
    + Sub<f64, Output = Self>
    + Mul<f64, Output = Self>
    + Div<f64, Output = Self>
{
    /// A constant (zero gradient).
    fn cst(v: f64) -> Self;
    /// The value.
    fn val(self) -> f64;
    /// Square root. The gradient at 0 is returned as 0 (callers never differentiate there:
    /// the flow functions are linearized around their zeros).
    fn sqrt(self) -> Self;
    /// `self^e` for a constant exponent; the base must be positive where it is differentiated.
    fn powf(self, e: f64) -> Self;
    /// Exponential.
    fn exp(self) -> Self;

    /// `max(self, lo)`, with a zero gradient where the bound is active.
    #[inline]
    fn max_c(self, lo: f64) -> Self {
        if self.val() < lo {
            Self::cst(lo)
        } else {
            self
        }
    }

    /// `min(self, hi)`, with a zero gradient where the bound is active.
    #[inline]
    fn min_c(self, hi: f64) -> Self {
        if self.val() > hi {
            Self::cst(hi)
        } else {
            self
        }
    }

    /// `self` clamped to `[lo, hi]`; NaN maps to `lo` so that it cannot propagate.
    #[inline]
    fn clamp_c(self, lo: f64, hi: f64) -> Self {
        let v = self.val();
        if v.is_nan() || v < lo {
            Self::cst(lo)
        } else if v > hi {
            Self::cst(hi)
        } else {
            self
        }
    }

    /// `|self|` (the gradient of `-self` below 0).
    #[inline]
    fn abs_s(self) -> Self {
        if self.val() < 0.0 {
            -self
        } else {
            self
        }
    }
}

impl Scalar for f64 {
    #[inline]
    fn cst(v: f64) -> Self {
        v
    }
    #[inline]
    fn val(self) -> f64 {
        self
    }
    #[inline]
    fn sqrt(self) -> Self {
        f64::sqrt(self)
    }
    #[inline]
    fn powf(self, e: f64) -> Self {
        f64::powf(self, e)
    }
    #[inline]
    fn exp(self) -> Self {
        f64::exp(self)
    }
}

/// A value `v` with its gradient `d` (`d[j] = dv/dz_j` for the `N` seeded variables `z`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Dual<const N: usize> {
    /// The value.
    pub v: f64,
    /// The gradient with respect to the seeded variables.
    pub d: [f64; N],
}

impl<const N: usize> Dual<N> {
    /// The seeded variable number `j` with value `v` (gradient: unit vector `e_j`).
    #[inline]
    pub fn var(v: f64, j: usize) -> Self {
        let mut d = [0.0; N];
        d[j] = 1.0;
        Self { v, d }
    }

    /// `self` with value `v` and the gradient scaled by `k` (the chain rule `g'(u) du`).
    #[inline]
    fn chain(self, v: f64, k: f64) -> Self {
        let mut d = self.d;
        for x in &mut d {
            *x *= k;
        }
        Self { v, d }
    }
}

impl<const N: usize> Add for Dual<N> {
    type Output = Self;
    #[inline]
    fn add(self, o: Self) -> Self {
        let mut d = self.d;
        for (a, b) in d.iter_mut().zip(o.d) {
            *a += b;
        }
        Self { v: self.v + o.v, d }
    }
}

impl<const N: usize> Sub for Dual<N> {
    type Output = Self;
    #[inline]
    fn sub(self, o: Self) -> Self {
        let mut d = self.d;
        for (a, b) in d.iter_mut().zip(o.d) {
            *a -= b;
        }
        Self { v: self.v - o.v, d }
    }
}

impl<const N: usize> Mul for Dual<N> {
    type Output = Self;
    #[inline]
    fn mul(self, o: Self) -> Self {
        let mut d = self.d;
        for (a, b) in d.iter_mut().zip(o.d) {
            *a = *a * o.v + b * self.v;
        }
        Self { v: self.v * o.v, d }
    }
}

impl<const N: usize> Div for Dual<N> {
    type Output = Self;
    #[inline]
    fn div(self, o: Self) -> Self {
        let q = self.v / o.v;
        let r = 1.0 / o.v;
        let mut d = self.d;
        for (a, b) in d.iter_mut().zip(o.d) {
            *a = (*a - q * b) * r;
        }
        Self { v: q, d }
    }
}

impl<const N: usize> Neg for Dual<N> {
    type Output = Self;
    #[inline]
    fn neg(self) -> Self {
        self.chain(-self.v, -1.0)
    }
}

impl<const N: usize> Add<f64> for Dual<N> {
    type Output = Self;
    #[inline]
    fn add(self, c: f64) -> Self {
        Self {
            v: self.v + c,
            d: self.d,
        }
    }
}

impl<const N: usize> Sub<f64> for Dual<N> {
    type Output = Self;
    #[inline]
    fn sub(self, c: f64) -> Self {
        Self {
            v: self.v - c,
            d: self.d,
        }
    }
}

impl<const N: usize> Mul<f64> for Dual<N> {
    type Output = Self;
    #[inline]
    fn mul(self, c: f64) -> Self {
        self.chain(self.v * c, c)
    }
}

impl<const N: usize> Div<f64> for Dual<N> {
    type Output = Self;
    #[inline]
    fn div(self, c: f64) -> Self {
        let r = 1.0 / c;
        self.chain(self.v * r, r)
    }
}

impl<const N: usize> Scalar for Dual<N> {
    #[inline]
    fn cst(v: f64) -> Self {
        Self { v, d: [0.0; N] }
    }
    #[inline]
    fn val(self) -> f64 {
        self.v
    }
    #[inline]
    fn sqrt(self) -> Self {
        let s = self.v.sqrt();
        let k = if s > 0.0 { 0.5 / s } else { 0.0 };
        self.chain(s, k)
    }
    #[inline]
    fn powf(self, e: f64) -> Self {
        let p = self.v.powf(e);
        let k = if self.v != 0.0 {
            e * p / self.v
        } else {
            e * self.v.powf(e - 1.0)
        };
        self.chain(p, k)
    }
    #[inline]
    fn exp(self) -> Self {
        let e = self.v.exp();
        self.chain(e, e)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dual_derivatives_match_calculus() {
        let x = Dual::<2>::var(1.7, 0);
        let y = Dual::<2>::var(0.4, 1);
        // f = x^1.3 * exp(y) / sqrt(x + y) - 3 y
        let f = x.powf(1.3) * y.exp() / (x + y).sqrt() - y * 3.0;
        let (xv, yv) = (1.7f64, 0.4f64);
        let g = |a: f64, b: f64| a.powf(1.3) * b.exp() / (a + b).sqrt() - 3.0 * b;
        assert!((f.v - g(xv, yv)).abs() < 1e-14);
        let h = 1e-6;
        let dx = (g(xv + h, yv) - g(xv - h, yv)) / (2.0 * h);
        let dy = (g(xv, yv + h) - g(xv, yv - h)) / (2.0 * h);
        assert!((f.d[0] - dx).abs() < 1e-8, "{} vs {dx}", f.d[0]);
        assert!((f.d[1] - dy).abs() < 1e-8, "{} vs {dy}", f.d[1]);
        let c = x.clamp_c(0.0, 1.0);
        assert_eq!(c.d, [0.0, 0.0]);
        assert_eq!((-x).abs_s().d, [1.0, 0.0]);
    }
}
