//! SIMD vectors of `f32` lanes for channel-blocked loops, and running code compiled for AVX-512.
//!
//! Kernels written once over [`Vector`] run with 512-bit registers (`__m512`) where the CPU has
//! AVX-512 and as portable arrays elsewhere ([`run`]); the direct convolution loops of
//! [`crate::net::backprop`] also take its 256-bit half (`__m256`, 8 lanes).

#[cfg(target_arch = "x86_64")]
use std::arch::x86_64::*;

/// Lanes of the vectors [`run`] gives its kernels (`__m512` or [`Portable`]).
pub(crate) const LANES: usize = 16;

/// `Self::LANES` `f32` lanes.
pub(crate) trait Vector: Copy {
    /// Number of lanes.
    const LANES: usize;
    /// Zeros.
    fn zero() -> Self;
    /// The first `LANES` values of `from`.
    fn load(from: &[f32]) -> Self;
    /// The `LANES` values at `from`.
    ///
    /// # Safety
    /// `from` points to `LANES` readable values.
    unsafe fn load_ptr(from: *const f32) -> Self;
    /// Stores the lanes into the first `LANES` values of `to`.
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
    /// Adds the lanes to the first `LANES` values of `to`.
    #[inline(always)]
    fn add_to(self, to: &mut [f32]) {
        self.add(Self::load(to)).store(to)
    }
    /// A convolution output: `self + bias`, rectified if `relu`, zeroed where `mask` is not
    /// positive.
    #[inline(always)]
    fn finish(self, bias: Self, relu: bool, mask: Option<Self>) -> Self {
        let y = self.add(bias);
        let y = if relu { y.relu() } else { y };
        match mask {
            Some(m) => y.keep_where(m),
            None => y,
        }
    }
}

/// The portable lanes.
pub(crate) type Portable = [f32; LANES];

impl Vector for Portable {
    const LANES: usize = LANES;
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

/// Implements [`Vector`] for an x86 vector type of `$n` lanes from its intrinsics (`$keep`:
/// [`keep_512`] or [`keep_256`]).
///
/// SAFETY (every method): these vectors exist only in code compiled for AVX-512 and reached
/// after checking that the CPU has it (`run`, `vectorised`, the direct loops of `backprop`),
/// which implies AVX and FMA; loads and stores go through slices of at least `$n` values, or
/// pointers to `$n` values (`load_ptr`'s promise).
#[cfg(target_arch = "x86_64")]
macro_rules! intrinsics {
    ($v:ty, $n:literal, $setzero:ident, $set1:ident, $loadu:ident, $storeu:ident, $add:ident, $sub:ident,
     $mul:ident, $fmadd:ident, $max:ident, $keep:ident) => {
        impl Vector for $v {
            const LANES: usize = $n;
            #[inline(always)]
            fn zero() -> Self {
                unsafe { $setzero() }
            }
            #[inline(always)]
            fn load(from: &[f32]) -> Self {
                let from = &from[..$n];
                unsafe { $loadu(from.as_ptr()) }
            }
            #[inline(always)]
            unsafe fn load_ptr(from: *const f32) -> Self {
                unsafe { $loadu(from) }
            }
            #[inline(always)]
            fn store(self, to: &mut [f32]) {
                let to = &mut to[..$n];
                unsafe { $storeu(to.as_mut_ptr(), self) }
            }
            #[inline(always)]
            fn add(self, o: Self) -> Self {
                unsafe { $add(self, o) }
            }
            #[inline(always)]
            fn sub(self, o: Self) -> Self {
                unsafe { $sub(self, o) }
            }
            #[inline(always)]
            fn scale(self, s: f32) -> Self {
                unsafe { $mul(self, $set1(s)) }
            }
            #[inline(always)]
            fn fma(self, x: f32, w: Self) -> Self {
                unsafe { $fmadd($set1(x), w, self) }
            }
            #[inline(always)]
            fn relu(self) -> Self {
                unsafe { $max(self, $setzero()) }
            }
            #[inline(always)]
            fn keep_where(self, mask: Self) -> Self {
                unsafe { $keep(self, mask) }
            }
        }
    };
}

#[cfg(target_arch = "x86_64")]
intrinsics!(
    __m512,
    16,
    _mm512_setzero_ps,
    _mm512_set1_ps,
    _mm512_loadu_ps,
    _mm512_storeu_ps,
    _mm512_add_ps,
    _mm512_sub_ps,
    _mm512_mul_ps,
    _mm512_fmadd_ps,
    _mm512_max_ps,
    keep_512
);

#[cfg(target_arch = "x86_64")]
intrinsics!(
    __m256,
    8,
    _mm256_setzero_ps,
    _mm256_set1_ps,
    _mm256_loadu_ps,
    _mm256_storeu_ps,
    _mm256_add_ps,
    _mm256_sub_ps,
    _mm256_mul_ps,
    _mm256_fmadd_ps,
    _mm256_max_ps,
    keep_256
);

/// The lanes of `y` where `m` is not `<= 0`, zeros elsewhere.
///
/// # Safety
/// Needs AVX-512F.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn keep_512(y: __m512, m: __m512) -> __m512 {
    _mm512_maskz_mov_ps(_mm512_cmpnle_ps_mask(m, _mm512_setzero_ps()), y)
}

/// The lanes of `y` where `m` is not `<= 0`, zeros elsewhere.
///
/// # Safety
/// Needs AVX.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn keep_256(y: __m256, m: __m256) -> __m256 {
    _mm256_and_ps(y, _mm256_cmp_ps::<_CMP_NLE_UQ>(m, _mm256_setzero_ps()))
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

/// Runs `f` compiled for AVX-512 where the CPU has it (through [`run`]), so that the
/// element-wise loops it inlines use 16 lanes (functions it calls must be `#[inline(always)]` to
/// be compiled so).
#[inline(always)]
pub(crate) fn vectorised<T>(f: impl FnOnce() -> T) -> T {
    run(Closure(f), false)
}

/// A closure as a [`Kernel`] that does not use the vectors (see [`vectorised`]).
struct Closure<F>(F);

impl<T, F: FnOnce() -> T> Kernel for Closure<F> {
    type Output = T;
    #[inline(always)]
    fn run<V: Vector>(self) -> T {
        (self.0)()
    }
}
