//! The Adam optimiser, as burn's `AdamConfig::new()` defines it: `β₁ = 0.9`, `β₂ = 0.999`,
//! `ε = 1e-5`, no weight decay, no gradient clipping, no AMSGrad. Per parameter `p` with
//! gradient `g`, at its `t`-th step (in `f32`, in this order):
//!
//! ```text
//! m₁ ← β₁ m₁ + (1 − β₁) g        (m₁ = (1 − β₁) g at the first step)
//! m₂ ← β₂ m₂ + (1 − β₂) g²       (m₂ = (1 − β₂) g² at the first step)
//! c  = √(1 − β₂ᵗ) / (1 − β₁ᵗ)
//! p  ← p − lr · (m₁ c) / (√m₂ + ε √(1 − β₂ᵗ))
//! ```
//!
//! A parameter without a gradient (frozen) is left as it is and keeps no state.

use crate::net::unet::{Gradients, UNet};
use crate::{LearnError, Result};

const BETA_1: f32 = 0.9;
const BETA_2: f32 = 0.999;
const EPSILON: f32 = 1e-5;

/// The state of one parameter.
#[derive(Clone, Debug, PartialEq)]
pub struct Moments {
    /// Steps taken.
    pub time: usize,
    /// First moment.
    pub moment_1: Vec<f32>,
    /// Second moment.
    pub moment_2: Vec<f32>,
}

/// Adam's state for a network: one entry per parameter, in parameter order (see the module
/// documentation).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Adam {
    /// Per parameter, its state once it has taken a step.
    pub moments: Vec<Option<Moments>>,
}

impl Adam {
    /// A fresh optimiser for a network of `parameters` parameters.
    pub fn new(parameters: usize) -> Adam {
        Adam { moments: vec![None; parameters] }
    }

    /// One step of learning rate `lr` on `net` along `grads` (in `net`'s parameter order).
    pub fn step(&mut self, lr: f64, net: &mut UNet, grads: &Gradients) -> Result<()> {
        let values = net.values_mut();
        if grads.0.len() != values.len() || self.moments.len() != values.len() {
            return Err(LearnError::InvalidInput(format!(
                "Adam step: {} gradients and {} states for {} parameters",
                grads.0.len(),
                self.moments.len(),
                values.len()
            )));
        }
        let lr = lr as f32;
        for ((param, grad), state) in values.iter_mut().zip(&grads.0).zip(&mut self.moments) {
            let Some(grad) = grad else { continue };
            if grad.len() != param.len() {
                return Err(LearnError::InvalidInput(format!(
                    "Adam step: a gradient of {} values for a parameter of {}",
                    grad.len(),
                    param.len()
                )));
            }
            let s = match state {
                Some(s) => {
                    for ((m1, m2), g) in s.moment_1.iter_mut().zip(&mut s.moment_2).zip(grad) {
                        *m1 = *m1 * BETA_1 + g * (1.0 - BETA_1);
                        *m2 = *m2 * BETA_2 + g * g * (1.0 - BETA_2);
                    }
                    s.time += 1;
                    s
                }
                None => state.insert(Moments {
                    time: 1,
                    moment_1: grad.iter().map(|g| g * (1.0 - BETA_1)).collect(),
                    moment_2: grad.iter().map(|g| g * g * (1.0 - BETA_2)).collect(),
                }),
            };
            let t = i32::try_from(s.time).unwrap_or(i32::MAX);
            let correction_2 = (1.0 - BETA_2.powi(t)).sqrt();
            let factor = correction_2 / (1.0 - BETA_1.powi(t));
            let eps = EPSILON * correction_2;
            for ((p, m1), m2) in param.iter_mut().zip(&s.moment_1).zip(&s.moment_2) {
                *p -= m1 * factor / (m2.sqrt() + eps) * lr;
            }
        }
        Ok(())
    }
}
