//! Training and evaluation: the loop ([`train`](mod@train): Adam, checkpoints, resume,
//! fine-tuning), the loss and error metrics ([`metrics`]), evaluation over held-out samples
//! ([`evaluation`]) and the learning curve ([`curve`]).

pub mod curve;
pub mod evaluation;
pub mod metrics;
pub mod train;
