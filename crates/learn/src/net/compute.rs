//! Where the network runs: the CPU engines (default) or burn, on a GPU or the CPU.
//!
//! * [`Compute::Cpu`]: prediction by the repacked GEMM engine ([`InferenceNet`](crate::InferenceNet)),
//!   training by the hand-written backward pass ([`backprop`](crate::net::backprop)). Always available.
//! * [`Compute::Gpu`]: burn's own kernels and autodiff on a GPU through burn's wgpu runtime
//!   (WGSL kernels compiled at run time for Vulkan on Linux and Windows, Metal on macOS, DX12).
//!   Needs the crate's `gpu` cargo feature (off by default) and a GPU driver; otherwise choosing
//!   it is an error that says so.
//! * [`Compute::CpuBurn`]: burn's own kernels and autodiff on the CPU (`flex`): the code path the
//!   GPU runs, on any machine. Slower than [`Compute::Cpu`]; it is there to check that path
//!   (tests compare it with the CPU engines) and as a fallback. Needs the `cpu-burn` cargo
//!   feature (off by default; `gpu` implies it); otherwise choosing it is an error that says so.
//!
//! Weights, optimiser state and checkpoints are the same whichever runs them.

use std::fmt;
use std::str::FromStr;

#[cfg(feature = "cpu-burn")]
use burn::tensor::Device;
use serde::{Deserialize, Serialize};

use crate::{LearnError, Result};

/// Where the network runs (see the module documentation).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Compute {
    /// The repacked CPU engines (fastest on a CPU).
    #[default]
    Cpu,
    /// burn on a GPU through wgpu (`gpu` feature).
    Gpu,
    /// burn's own kernels on the CPU: the GPU's code path, without a GPU (`cpu-burn` feature).
    CpuBurn,
}

impl Compute {
    /// Whether this runs burn's kernels and autodiff (rather than the repacked CPU engines).
    pub fn uses_burn(self) -> bool {
        self != Compute::Cpu
    }

    /// Fails, saying which cargo feature to build with or which driver to install, when this
    /// is not built in or (the GPU) not found.
    pub fn ensure_available(self) -> Result<()> {
        match self {
            Compute::Cpu => Ok(()),
            Compute::CpuBurn => cpu_burn_available(),
            Compute::Gpu => gpu_available(),
        }
    }

    /// The burn device that runs the network: the GPU for [`Compute::Gpu`], else the CPU
    /// (`flex`). An error when the GPU is asked for but not built in or not found.
    #[cfg(feature = "cpu-burn")]
    pub fn device(self) -> Result<Device> {
        match self {
            Compute::Cpu | Compute::CpuBurn => Ok(Device::flex()),
            Compute::Gpu => gpu_device(),
        }
    }

    /// [`device`](Self::device) with autodiff, for training.
    #[cfg(feature = "cpu-burn")]
    pub fn training_device(self) -> Result<Device> {
        Ok(self.device()?.autodiff())
    }

    /// What runs the network, e.g. the GPU adapter's own name ("NVIDIA H100 80GB HBM3",
    /// "llvmpipe (LLVM 15.0.6, 256 bits)"), or the CPU engine.
    pub fn describe(self) -> Result<String> {
        match self {
            Compute::Cpu => Ok("cpu (repacked engines)".into()),
            Compute::CpuBurn => cpu_burn_available().map(|()| "cpu (burn flex)".into()),
            Compute::Gpu => gpu_name(),
        }
    }
}

impl fmt::Display for Compute {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Compute::Cpu => "cpu",
            Compute::Gpu => "gpu",
            Compute::CpuBurn => "cpu-burn",
        })
    }
}

impl FromStr for Compute {
    type Err = LearnError;

    fn from_str(s: &str) -> Result<Compute> {
        match s {
            "cpu" => Ok(Compute::Cpu),
            "gpu" => Ok(Compute::Gpu),
            "cpu-burn" => Ok(Compute::CpuBurn),
            other => {
                Err(LearnError::InvalidInput(format!("unknown device `{other}`: expected `cpu`, `gpu` or `cpu-burn`")))
            }
        }
    }
}

#[cfg(feature = "cpu-burn")]
fn cpu_burn_available() -> Result<()> {
    Ok(())
}

#[cfg(not(feature = "cpu-burn"))]
fn cpu_burn_available() -> Result<()> {
    Err(LearnError::InvalidInput(
        "this augsim was built without burn's CPU engine: rebuild with `cargo build --release -p augsim --features cpu-burn` \
         (or `--features gpu`), or use --device cpu"
            .into(),
    ))
}

#[cfg(feature = "gpu")]
fn gpu_available() -> Result<()> {
    gpu_device().map(drop)
}

#[cfg(feature = "gpu")]
fn gpu_device() -> Result<Device> {
    use burn::tensor::{DeviceKind, DeviceType};
    // Enumerating opens every adapter: once per process.
    static FOUND: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    if !*FOUND.get_or_init(|| Device::enumerate(DeviceType::Wgpu).into_iter().next().is_some()) {
        return Err(LearnError::InvalidInput(
            "no GPU adapter found by wgpu: install the GPU's Vulkan driver (e.g. the NVIDIA driver's \
             Vulkan ICD, or Mesa's) or use --device cpu"
                .into(),
        ));
    }
    Ok(Device::wgpu(DeviceKind::DefaultDevice))
}

#[cfg(feature = "gpu")]
fn gpu_name() -> Result<String> {
    let device = gpu_device()?;
    Ok(device.identity().map_or_else(|| "gpu (unnamed adapter)".into(), |id| format!("gpu: {}", id.name)))
}

#[cfg(not(feature = "gpu"))]
fn gpu_available() -> Result<()> {
    Err(LearnError::InvalidInput(
        "this augsim was built without GPU support: rebuild with `cargo build --release -p augsim --features gpu` \
         (burn's wgpu backend), or use --device cpu"
            .into(),
    ))
}

/// Without the `gpu` feature: the error that says so.
#[cfg(all(feature = "cpu-burn", not(feature = "gpu")))]
fn gpu_device() -> Result<Device> {
    gpu_available().map(|()| Device::flex())
}

#[cfg(not(feature = "gpu"))]
fn gpu_name() -> Result<String> {
    gpu_available().map(|()| String::new())
}
