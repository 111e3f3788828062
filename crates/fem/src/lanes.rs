//! `N` f64 lanes with element-wise arithmetic written so that the compiler turns it into
//! vector instructions: a kernel on [`Lanes`] treats `N` independent problems at once. Each
//! lane is IEEE-rounded on its own, so a lane's result depends neither on `N`, nor on the
//! vector width the code is compiled for, nor on the other lanes.

// Index loops throughout, deliberately (see `lane_op`).
#![allow(clippy::needless_range_loop)]

use std::ops::{Add, Div, Mul, Sub};

/// `N` f64 lanes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Lanes<const N: usize>(pub [f64; N]);

/// A lane-wise condition.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Mask<const N: usize>(pub [bool; N]);

// Plain index loops, not `array::from_fn` or `map`: their closures are not always inlined
// into a caller compiled for wider vectors, and a call per operation defeats the purpose.
macro_rules! lane_op {
    ($trait:ident, $method:ident, $op:tt) => {
        impl<const N: usize> $trait for Lanes<N> {
            type Output = Lanes<N>;
            #[inline(always)]
            fn $method(mut self, o: Lanes<N>) -> Lanes<N> {
                for l in 0..N {
                    self.0[l] $op o.0[l];
                }
                self
            }
        }
    };
}

lane_op!(Add, add, +=);
lane_op!(Sub, sub, -=);
lane_op!(Mul, mul, *=);
lane_op!(Div, div, /=);

impl<const N: usize> Lanes<N> {
    /// Every lane `v`.
    #[inline(always)]
    pub fn splat(v: f64) -> Self {
        Lanes([v; N])
    }

    /// Lane-wise square root.
    #[inline(always)]
    pub fn sqrt(mut self) -> Self {
        for l in 0..N {
            self.0[l] = self.0[l].sqrt();
        }
        self
    }

    /// Where `self > o` (false where either is NaN).
    #[inline(always)]
    pub fn gt(self, o: Self) -> Mask<N> {
        let mut m = [false; N];
        for l in 0..N {
            m[l] = self.0[l] > o.0[l];
        }
        Mask(m)
    }

    /// Where the lane is finite and not zero.
    #[inline(always)]
    pub fn finite_nonzero(self) -> Mask<N> {
        let mut m = [false; N];
        for l in 0..N {
            m[l] = self.0[l] != 0.0 && self.0[l].is_finite();
        }
        Mask(m)
    }
}

impl<const N: usize> Mask<N> {
    /// `a` where the mask holds, `b` elsewhere.
    #[inline(always)]
    pub fn select(self, mut a: Lanes<N>, b: Lanes<N>) -> Lanes<N> {
        for l in 0..N {
            if !self.0[l] {
                a.0[l] = b.0[l];
            }
        }
        a
    }

    /// Lane-wise `self && !o`.
    #[inline(always)]
    pub fn and_not(mut self, o: Self) -> Self {
        for l in 0..N {
            self.0[l] = self.0[l] && !o.0[l];
        }
        self
    }

    /// Lane-wise `self && o`.
    #[inline(always)]
    pub fn and(mut self, o: Self) -> Self {
        for l in 0..N {
            self.0[l] = self.0[l] && o.0[l];
        }
        self
    }

    /// Lane-wise `self || o`.
    #[inline(always)]
    pub fn or(mut self, o: Self) -> Self {
        for l in 0..N {
            self.0[l] = self.0[l] || o.0[l];
        }
        self
    }

    /// Whether any lane holds.
    #[inline(always)]
    pub fn any(self) -> bool {
        let mut any = false;
        for l in 0..N {
            any |= self.0[l];
        }
        any
    }
}
