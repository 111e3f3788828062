//! Vectors of 16 `f32` lanes for channel-blocked loops, and running code compiled for AVX-512.
//!
//! Kernels written once over [`Vector`] run with 512-bit registers (`__m512`) where the CPU has
//! AVX-512 and as portable arrays elsewhere ([`run`]).

#[cfg(target_arch = "x86_64")]
use std::arch::x86_64::*;

/// Lanes of a [`Vector`].
pub(crate) const LANES: usize = 16;

/// 16 `f32` lanes.
pub(crate) trait Vector: Copy {
    /// Zeros.
    fn zero() -> Self;
    /// The first 16 values of `from`.
    fn load(from: &[f32]) -> Self;
    /// The 16 values at `from`.
    ///
    /// # Safety
    /// `from` points to 16 readable values.
    unsafe fn load_ptr(from: *const f32) -> Self;
    /// Stores the lanes into the first 16 values of `to`.
    fn store(self, to: &mut [f32]);
    /// `self + o`.
    fn add(self, o: Self) -> Self;
    /// `self - o`.
    fn sub(self, o: Self) -> Self;
    /// `s · self`.
    fn scale(self, s: f32) -> Self;
    /// `self + x · w` (fused where the CPU has FMA).
    fn fma(self, x: f32, w: Self) -> Self;
    /// `max(self, 0)`.
    fn relu(self) -> Self;
    /// The lanes where `mask` is positive (not `<= 0`), zeros elsewhere.
    fn keep_where(self, mask: Self) -> Self;
    /// Adds the lanes to the first 16 values of `to`.
    #[inline(always)]
    fn add_to(self, to: &mut [f32]) {
        self.add(Self::load(to)).store(to)
    }
}

/// `[at(0), at(1), …, at(N - 1)]`: as `std::array::from_fn`, whose calls of `at` are not
/// always inlined, and so would not be compiled for AVX-512 by [`run`].
#[inline(always)]
pub(crate) fn gather<V: Vector, const N: usize>(mut at: impl FnMut(usize) -> V) -> [V; N] {
    let mut out = [V::zero(); N];
    for (i, o) in out.iter_mut().enumerate() {
        *o = at(i);
    }
    out
}

/// The portable lanes.
pub(crate) type Portable = [f32; LANES];

impl Vector for Portable {
    #[inline(always)]
    fn zero() -> Self {
        [0.0; LANES]
    }
    #[inline(always)]
    fn load(from: &[f32]) -> Self {
        from[..LANES].try_into().expect("16 values")
    }
    #[inline(always)]
    unsafe fn load_ptr(from: *const f32) -> Self {
        // SAFETY: 16 readable values (the caller's promise).
        unsafe { from.cast::<[f32; LANES]>().read_unaligned() }
    }
    #[inline(always)]
    fn store(self, to: &mut [f32]) {
        to[..LANES].copy_from_slice(&self);
    }
    #[inline(always)]
    fn add(self, o: Self) -> Self {
        std::array::from_fn(|i| self[i] + o[i])
    }
    #[inline(always)]
    fn sub(self, o: Self) -> Self {
        std::array::from_fn(|i| self[i] - o[i])
    }
    #[inline(always)]
    fn scale(self, s: f32) -> Self {
        self.map(|v| v * s)
    }
    #[inline(always)]
    fn fma(self, x: f32, w: Self) -> Self {
        std::array::from_fn(|i| self[i] + x * w[i])
    }
    #[inline(always)]
    fn relu(self) -> Self {
        self.map(|v| v.max(0.0))
    }
    #[inline(always)]
    fn keep_where(self, mask: Self) -> Self {
        std::array::from_fn(|i| if mask[i] <= 0.0 { 0.0 } else { self[i] })
    }
}

// SAFETY (every method): `__m512` values exist only in code that `run` reaches after checking
// that the CPU has AVX-512F; loads and stores go through slices of at least 16 values, or
// pointers to 16 values (`load_ptr`'s promise).
#[cfg(target_arch = "x86_64")]
impl Vector for __m512 {
    #[inline(always)]
    fn zero() -> Self {
        unsafe { _mm512_setzero_ps() }
    }
    #[inline(always)]
    fn load(from: &[f32]) -> Self {
        let from = &from[..LANES];
        unsafe { _mm512_loadu_ps(from.as_ptr()) }
    }
    #[inline(always)]
    unsafe fn load_ptr(from: *const f32) -> Self {
        unsafe { _mm512_loadu_ps(from) }
    }
    #[inline(always)]
    fn store(self, to: &mut [f32]) {
        let to = &mut to[..LANES];
        unsafe { _mm512_storeu_ps(to.as_mut_ptr(), self) }
    }
    #[inline(always)]
    fn add(self, o: Self) -> Self {
        unsafe { _mm512_add_ps(self, o) }
    }
    #[inline(always)]
    fn sub(self, o: Self) -> Self {
        unsafe { _mm512_sub_ps(self, o) }
    }
    #[inline(always)]
    fn scale(self, s: f32) -> Self {
        unsafe { _mm512_mul_ps(self, _mm512_set1_ps(s)) }
    }
    #[inline(always)]
    fn fma(self, x: f32, w: Self) -> Self {
        unsafe { _mm512_fmadd_ps(_mm512_set1_ps(x), w, self) }
    }
    #[inline(always)]
    fn relu(self) -> Self {
        unsafe { _mm512_max_ps(self, _mm512_setzero_ps()) }
    }
    #[inline(always)]
    fn keep_where(self, mask: Self) -> Self {
        unsafe { _mm512_maskz_mov_ps(_mm512_cmpnle_ps_mask(mask, _mm512_setzero_ps()), self) }
    }
}

/// Work written over [`Vector`]: `run` must be `#[inline(always)]`, and so must everything it
/// calls, to be compiled for AVX-512 by [`run`].
pub(crate) trait Kernel {
    /// What the work returns.
    type Output;
    /// Does the work with vectors `V`.
    fn run<V: Vector>(self) -> Self::Output;
}

/// Whether the CPU has AVX-512F (where [`vectorised`] code uses 512-bit vectors).
pub(crate) fn has_avx512() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        is_x86_feature_detected!("avx512f")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Runs `kernel` with `__m512` vectors, compiled for AVX-512, where the CPU has it, with
/// [`Portable`] vectors elsewhere or when `portable`.
#[inline(always)]
pub(crate) fn run<K: Kernel>(kernel: K, portable: bool) -> K::Output {
    #[cfg(target_arch = "x86_64")]
    if !portable && has_avx512() {
        #[target_feature(enable = "avx512f,avx2,fma")]
        fn avx512<K: Kernel>(kernel: K) -> K::Output {
            kernel.run::<__m512>()
        }
        // SAFETY: the CPU has AVX-512F (checked above).
        return unsafe { avx512(kernel) };
    }
    kernel.run::<Portable>()
}

/// Runs `f` compiled for AVX-512 where the CPU has it, so that the element-wise loops it
/// inlines use 16 lanes (functions it calls must be `#[inline(always)]` to be compiled so).
#[inline(always)]
pub(crate) fn vectorised<T>(f: impl FnOnce() -> T) -> T {
    #[cfg(target_arch = "x86_64")]
    if has_avx512() {
        #[target_feature(enable = "avx512f,avx2,fma")]
        fn avx512<T>(f: impl FnOnce() -> T) -> T {
            f()
        }
        // SAFETY: the CPU has AVX-512F (checked above).
        return unsafe { avx512(f) };
    }
    f()
}
