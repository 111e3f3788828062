//! The model interface that the filter drives.

use nalgebra::DVector;

/// A (possibly large) simulation whose uncertain parameters θ are estimated by the filter.
///
/// The filter keeps one [`Model::State`] per sigma point; each call to [`Model::step`] advances that state by one
/// time step, warm-started from the sigma point's own previous state (e.g. node positions used as the Newton
/// initial guess), with the sigma point's parameter values in physical space (after the [`crate::Transform`]s).
pub trait Model: Sync {
    /// Full state of the model (e.g. node positions plus any warm-start data).
    type State: Clone + Send + Sync;
    /// Error of a failed step (e.g. Newton did not converge).
    type Error: std::error::Error + Send + Sync + 'static;

    /// Advances `state` from time step `step - 1` to time step `step` (1-based: the first filter iteration passes
    /// `step = 1`) with the physical parameter values `theta` (length p).
    fn step(&self, state: &mut Self::State, theta: &[f64], step: usize) -> Result<(), Self::Error>;

    /// Observation operator H: the predicted measurement for `state` (same length and ordering as the data).
    fn observe(&self, state: &Self::State) -> DVector<f64>;

    /// Whether the physical parameter values `theta` are in the model's domain (e.g. a positive
    /// Young's modulus); the filter refuses an estimate outside it before taking it, and a sigma
    /// point outside it before stepping it. Any by default.
    fn admissible(&self, _theta: &[f64]) -> Result<(), Self::Error> {
        Ok(())
    }

    /// Called once per sigma point when the filter is built, on that sigma point's own copy of the initial state
    /// (`sigma_point` in `0..m`: m = p + 1 simplex or 2p + 1 star sigma points), so that a model can tie
    /// per-sigma-point resources to it (e.g. the index of a solver that keeps its factorisation between the steps of
    /// that sigma point). Does nothing by default.
    fn assign_sigma_point(&self, _state: &mut Self::State, _sigma_point: usize) {}
}

/// A model whose state (or its dynamic part) can be read and written as a vector, enabling joint state–parameter
/// filtering ([`crate::Roukf::new_joint`]): the mean state is then estimated and corrected along with θ.
pub trait VectorState: Model {
    /// The estimated part of `state` as a vector (e.g. all node coordinates); its length must never change.
    fn state_vector(&self, state: &Self::State) -> DVector<f64>;

    /// Overwrites the estimated part of `state` with `x` (length as returned by [`VectorState::state_vector`]),
    /// keeping any other warm-start data.
    fn set_state_vector(&self, state: &mut Self::State, x: &DVector<f64>);
}
