//! The loads the registration experiments put on the built-in case's truth.

use mesh::phantom::SurfacePatch;
use scenario::CaseScenario;

/// A load of a registration case's truth and the camera's seed: the built-in case under another
/// load, seen anew.
pub(crate) struct CaseLoad {
    /// Short description for the tables.
    pub label: &'static str,
    /// Tool force (N) and its direction.
    pub force: f64,
    pub direction: [f64; 3],
    /// Where the tool pushes (`None`: the case's own patch, on the left lobe).
    pub patch: Option<SurfacePatch>,
    /// The camera's seed.
    pub seed: u64,
}

impl CaseLoad {
    /// `base` under this load, seen with this seed.
    pub fn apply(&self, base: &CaseScenario) -> CaseScenario {
        let mut scenario = base.clone();
        scenario.truth.force = self.force;
        scenario.truth.direction = self.direction;
        scenario.truth.patch = self.patch.or(scenario.truth.patch);
        scenario.camera.seed = self.seed;
        scenario
    }
}

/// A 2 cm patch on top of the right lobe.
pub(crate) const RIGHT_LOBE: SurfacePatch =
    SurfacePatch { from: [0.06, 0.02, 0.0], direction: [0.0, 0.0, 1.0], radius: 0.02 };

/// A 2 cm patch on the front of the left lobe.
pub(crate) const LEFT_LOBE_FRONT: SurfacePatch =
    SurfacePatch { from: [-0.04, -0.025, 0.0], direction: [0.0, 0.0, 1.0], radius: 0.02 };
