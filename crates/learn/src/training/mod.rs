//! Training and evaluation: the loop ([`train`](mod@train): checkpoints, resume, fine-tuning),
//! the optimiser ([`adam`]), the loss and error metrics ([`metrics`]), evaluation over held-out
//! samples ([`evaluation`]) and the learning curve ([`curve`]).

pub mod adam;
pub mod curve;
pub mod evaluation;
pub mod metrics;
pub mod train;
