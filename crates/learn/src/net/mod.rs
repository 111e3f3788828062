//! The network: the 3D U-Net ([`unet`]: its architecture, documented there and in
//! `docs/method.md`, and its parameters) and the engines that run it.
//!
//! Four engines compute the same network from the same parameters:
//! - the repacked CPU inference engine (channels-last GEMMs, Winograd) — [`inference`];
//! - the hand-written CPU backward pass used for training — [`backprop`];
//! - burn's own kernels and autodiff on the CPU (`flex`; the `cpu-burn` feature) — `burn_unet`;
//! - burn on a GPU through wgpu (the `gpu` feature) — `burn_unet`.
//!
//! [`compute`] chooses among them; [`predict`] times single predictions.
//!
//! The reference is none of them: a plain `f64` forward pass written with direct loops from the
//! architecture of `docs/method.md` (`tests/common/reference.rs`). Each engine is tested against
//! it, directly or through one tested before: the inference engine's output
//! (`tests/inference.rs`, to 1e-5), the backward pass's gradients against central differences of
//! the reference (`tests/backprop.rs`), burn's forward pass, gradients and Adam steps against
//! these two (`tests/burn_engine.rs`), and the PyTorch twin `augsim.torch` against `augsim
//! predict` (`python/tests/test_torch.py`, to 1e-5 m).

pub mod backprop;
#[cfg(feature = "cpu-burn")]
pub mod burn_unet;
pub mod compute;
pub mod inference;
pub(crate) mod lanes;
pub mod predict;
pub mod unet;
pub(crate) mod winograd;
