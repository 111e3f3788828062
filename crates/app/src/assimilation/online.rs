//! The ROUKF of an assimilation experiment stepped with measurements as they arrive: from Python
//! one step at a time, or on an OpenIGTLink stream ([`OnlineFilter::step_points`]).

use filter::{FemModel, Roukf};
use mesh::Point;
use nalgebra::DVector;

use super::tracks::spread_in_another_unit;
use super::{AssimilationError, Context, Experiment};

/// The filter at its prior, waiting for measurements.
pub struct OnlineFilter {
    filter: Roukf<FemModel>,
    names: Vec<String>,
    features: usize,
    /// The observed points' rest positions (m), and the organ's size (m): no point moves farther.
    rest: Vec<Point>,
    size: f64,
}

/// The filter's estimate after a step.
#[derive(Clone, Debug, PartialEq)]
pub struct Estimate {
    /// Filter steps done.
    pub iteration: usize,
    /// The parameters' estimate (physical units), in the order of [`OnlineFilter::names`].
    pub mean: Vec<f64>,
    /// Their standard deviations.
    pub std: Vec<f64>,
    /// Norm of the step's innovation over the measured components (m); `None` when no point was seen.
    pub innovation: Option<f64>,
    /// Measured components the validation gate left out of the step (the scenario's `[filter] gate`).
    pub gated: usize,
}

impl OnlineFilter {
    /// The filter of `experiment` ([`Experiment::filter`]).
    pub fn new(experiment: &Experiment) -> Result<OnlineFilter, AssimilationError> {
        let filter = experiment.filter()?;
        let names = filter.config().parameters.iter().map(|p| p.name.clone()).collect();
        let (rest, size) = (experiment.observed_points(), experiment.organ_size());
        Ok(OnlineFilter { filter, names, features: experiment.setup().features, rest, size })
    }

    /// The estimated parameters' names, in order (`young`, `k_<node>` for a spring).
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// Observed points per step.
    pub fn features(&self) -> usize {
        self.features
    }

    /// One step with the observed points' positions stacked (x, y, z per point, m; NaN for a
    /// component not measured).
    pub fn step(&mut self, z: Vec<f64>) -> Result<Estimate, AssimilationError> {
        if z.len() != 3 * self.features {
            return Err(AssimilationError::Setup(format!(
                "{} values measured for {} observed points",
                z.len(),
                self.features
            )));
        }
        // NaN is a component not measured; any other value must be a position within reach.
        let bound = mesh::MAX_MEASURED_COORDINATE;
        if let Some(k) = z.iter().position(|v| !v.is_nan() && !(v.abs() <= bound)) {
            return Err(AssimilationError::Setup(format!(
                "observed point {} has the coordinate {:e}: not finite or beyond {bound:e} m, out of reach",
                k / 3,
                z[k]
            )));
        }
        // A step in another unit, or a feature mistaken for another, would drive the estimate
        // anywhere: refused, the filter left as it was.
        for (k, (p, rest)) in z.chunks_exact(3).zip(&self.rest).enumerate() {
            let moved = (0..3).filter(|&d| !p[d].is_nan()).map(|d| (p[d] - rest[d]).powi(2)).sum::<f64>().sqrt();
            if moved > self.size {
                return Err(AssimilationError::Setup(format!(
                    "observed point {k} lies {:.1} mm from its rest position, farther than the organ's size ({:.1} \
                     mm, its mesh's box diagonal): is the step in another unit?",
                    mesh::length::mm(moved),
                    mesh::length::mm(self.size)
                )));
            }
        }
        self.check_spread(&z)?;
        self.check_frame(&z)?;
        let available: Vec<bool> = z.iter().map(|v| !v.is_nan()).collect();
        let record = self.filter.step_partial(&DVector::from_vec(z), &available).context(|| "a filter step".into())?;
        let (innovation, gated) = (record.innovation_norm, record.gated);
        Ok(Estimate { iteration: self.iteration(), mean: self.mean(), std: self.std(), innovation, gated })
    }

    /// Refuses a step whose fully seen points span another unit's ([`spread_in_another_unit`]) than their
    /// rest positions (the check of each point misses metres read as millimetres).
    fn check_spread(&self, z: &[f64]) -> Result<(), AssimilationError> {
        let (seen, rest): (Vec<Point>, Vec<Point>) = z
            .chunks_exact(3)
            .zip(&self.rest)
            .filter(|(p, _)| p.iter().all(|v| !v.is_nan()))
            .map(|(p, rest)| ([p[0], p[1], p[2]], *rest))
            .unzip();
        match spread_in_another_unit(&rest, &seen) {
            None => Ok(()),
            Some((now, at_rest)) => Err(AssimilationError::Setup(format!(
                "the {} observed points seen span {:.3e} mm, {:.1e} times what they span at rest ({:.1} mm): is the \
                 step in another unit?",
                seen.len(),
                mesh::length::mm(now),
                now / at_rest,
                mesh::length::mm(at_rest)
            ))),
        }
    }

    /// Refuses a step whose fully seen points are in the other frame ([`in_the_other_frame`]),
    /// which the filter's gate would only partly leave out.
    fn check_frame(&self, z: &[f64]) -> Result<(), AssimilationError> {
        let seen: Vec<(Point, Point)> = z
            .chunks_exact(3)
            .zip(&self.rest)
            .filter(|(p, _)| p.iter().all(|v| !v.is_nan()))
            .map(|(p, rest)| ([p[0], p[1], p[2]], *rest))
            .collect();
        match in_the_other_frame(&seen, self.size) {
            None => Ok(()),
            Some((given, negated)) => Err(AssimilationError::Setup(format!(
                "the {} observed points seen lie {:.1} mm from their rest positions on average, {:.1} mm with x and \
                 y negated: is the step in the other frame (RAS where the organ is in LPS, or the reverse)?",
                seen.len(),
                mesh::length::mm(given),
                mesh::length::mm(negated)
            ))),
        }
    }

    /// One step with the observed points' positions (m; NaN for a point not seen), the estimate
    /// as JSON fields: `iteration`, `names`, `mean`, `std`, `innovation`, `gated` (what a stream
    /// answers).
    pub fn step_points(&mut self, positions: &[Point]) -> Result<serde_json::Map<String, serde_json::Value>, String> {
        // The whole chain of causes, as the command line prints it: a context alone says nothing.
        let e = self
            .step(positions.iter().flatten().copied().collect())
            .map_err(|e| format!("{:#}", anyhow::Error::new(e)))?;
        let mut fields = serde_json::Map::new();
        fields.insert("iteration".into(), e.iteration.into());
        fields.insert("names".into(), self.names.clone().into());
        fields.insert("mean".into(), e.mean.into());
        fields.insert("std".into(), e.std.into());
        fields.insert("innovation".into(), e.innovation.into());
        fields.insert("gated".into(), e.gated.into());
        Ok(fields)
    }

    /// Filter steps done.
    pub fn iteration(&self) -> usize {
        self.filter.iteration()
    }

    /// The parameters' estimate (physical units).
    pub fn mean(&self) -> Vec<f64> {
        self.filter.mean_physical()
    }

    /// Their standard deviations.
    pub fn std(&self) -> Vec<f64> {
        self.filter.std_physical()
    }
}

/// For points seen (each with its rest position) of an organ of size `size` (its box's
/// diagonal): their mean distance from rest as given and with x and y negated, when they lie far
/// from rest (a tenth of the organ's size on average) and four times nearer negated: points in the
/// other frame (RAS for LPS). `None` otherwise.
fn in_the_other_frame(seen: &[(Point, Point)], size: f64) -> Option<(f64, f64)> {
    if seen.is_empty() {
        return None;
    }
    let mean = |flip: f64| {
        seen.iter().map(|(p, rest)| mesh::distance([flip * p[0], flip * p[1], p[2]], *rest)).sum::<f64>()
            / seen.len() as f64
    };
    let (given, negated) = (mean(1.0), mean(-1.0));
    (given > 0.1 * size && negated < 0.25 * given).then_some((given, negated))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Features about an organ around the origin, x and y negated, are told; moved a little in
    /// the organ's frame, or far from the origin, they are not.
    #[test]
    fn features_in_the_other_frame_are_told() {
        let rest = [[0.03, -0.02, 0.1], [-0.04, 0.05, 0.12], [0.06, 0.01, 0.08]];
        let pair = |f: &dyn Fn(Point) -> Point| rest.iter().map(|&r| (f(r), r)).collect::<Vec<_>>();
        let size = 0.25;
        let (given, negated) =
            in_the_other_frame(&pair(&|r| [-r[0], -r[1] + 0.002, r[2] - 0.003]), size).expect("the other frame");
        assert!(given > 0.05 && (negated - 0.0036).abs() < 1e-4, "{given} {negated}");
        assert_eq!(in_the_other_frame(&pair(&|r| [r[0], r[1], r[2] - 0.005]), size), None);
        assert_eq!(in_the_other_frame(&[], size), None);
        // An organ far from the origin: negated, its features lie farther still.
        let far = |r: Point| [r[0] + 0.5, r[1], r[2]];
        let shifted: Vec<(Point, Point)> = rest.iter().map(|&r| (far([r[0] + 0.02, r[1], r[2]]), far(r))).collect();
        assert_eq!(in_the_other_frame(&shifted, size), None);
    }
}
