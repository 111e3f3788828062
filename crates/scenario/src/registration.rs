//! Registration cases (`kind = "registration_case"`, `augsim register --demo | --case`): the truth
//! (phantom size, law, fixed and loaded regions, force), the camera (view, points, noise,
//! outliers, seed), an optional rigid misalignment of the camera's frame, the registration
//! models (phantom size, methods) and the registration settings.

use std::path::Path;

use fem::Material;
use mesh::length::Length;
use mesh::phantom::SurfacePatch;
use mesh::Point;
use register::{RegistrationOptions, RigidTransform};
use serde::{Deserialize, Serialize};

use crate::{Kind, Result, ScenarioError, ScenarioText};

/// The name of the built-in case of `augsim register --demo`.
pub const BUILTIN_CASE: &str = "register_case";

/// Settings given beside a comparison case's file (e.g. on the command line), which override
/// its own ([`CaseScenario::with_overrides`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CaseOverrides {
    /// The truth's largest force (N).
    pub force: Option<f64>,
    /// The truth's frames.
    pub frames: Option<usize>,
    /// The cloud's misalignment: its rotation (degrees)...
    pub misalign_deg: Option<f64>,
    /// ... and its translation.
    pub misalign_shift: Option<Length>,
    /// Match-and-deform iterations from rest, for every method.
    pub iterations: Option<usize>,
    /// A rigid pre-alignment (the default one) where the case has none.
    pub rigid: bool,
}

/// A registration comparison case.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CaseScenario {
    /// Short name.
    pub name: String,
    /// One line of description.
    #[serde(default)]
    pub description: String,
    /// The deformation to recover.
    pub truth: TruthSpec,
    /// What the camera sees of it.
    pub camera: CameraSpec,
    /// Where the camera's frame lies against the preoperative model's (none by default).
    #[serde(default)]
    pub misalignment: Misalignment,
    /// The registration models.
    pub models: ModelsSpec,
    /// The registration loop (`[registration]`, and `[registration.rigid]` for a rigid
    /// pre-alignment); defaults as [`RegistrationOptions::default`].
    #[serde(default)]
    pub registration: RegistrationOptions,
}

/// The ground truth: the built-in liver phantom, meshed finer than the models, fixed on one
/// region and pushed on another.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TruthSpec {
    /// The phantom meshed with about this many tetrahedra.
    pub tets: usize,
    /// Its material (law, Young's modulus, Poisson's ratio; formulation automatic by default).
    pub material: Material,
    /// The phantom region held fixed.
    #[serde(default = "default_fixed")]
    pub fixed: String,
    /// The phantom region the force is spread over.
    #[serde(default = "default_load")]
    pub load: String,
    /// Total force (N)...
    pub force: f64,
    /// ... along this direction (normalised).
    #[serde(default = "default_direction")]
    pub direction: Point,
    /// Moves the phantom's `push` region: a patch of the surface around the boundary point met
    /// from `from` along `direction`. Default: the phantom's own.
    #[serde(default)]
    pub patch: Option<SurfacePatch>,
    /// The phantom region whose nodes are the targets (their rest positions).
    #[serde(default = "default_targets")]
    pub targets: String,
    /// Frames of a press and release: the force rises to `force` at frame m = ⌈n / 2⌉ and falls
    /// back, frame k of n (k = 1…n) pushed by force · sin(π/2 · k / m) up to m and
    /// force · sin(π/2 · (n + 1 − k) / (n + 1 − m)) after it (for odd n, force · sin(π k / (n + 1))
    /// throughout), each seen by the camera with the seed `camera.seed + k − 1`. 1 (the default):
    /// one frame at `force`.
    #[serde(default = "default_frames", skip_serializing_if = "is_one")]
    pub frames: usize,
}

/// The most frames a case may have.
pub const MAX_FRAMES: usize = 1000;

fn default_frames() -> usize {
    1
}

fn is_one(n: &usize) -> bool {
    *n == 1
}

impl TruthSpec {
    /// Its mesh in words: "about 9000 T4", or "about 9000 T10" for quadratic tetrahedra.
    pub fn mesh_words(&self) -> String {
        format!("about {} {}", self.tets, if self.material.order == 2 { "T10" } else { "T4" })
    }

    /// The force of each frame (N), in order ([`TruthSpec::frames`]).
    pub fn frame_forces(&self) -> Vec<f64> {
        let n = self.frames;
        if n == 1 {
            return vec![self.force];
        }
        let peak = n.div_ceil(2);
        let share = |k: usize| match k <= peak {
            true => k as f64 / peak as f64,
            false => (n + 1 - k) as f64 / (n + 1 - peak) as f64,
        };
        (1..=n).map(|k| self.force * (std::f64::consts::FRAC_PI_2 * share(k)).sin()).collect()
    }
}

fn default_fixed() -> String {
    "fixed".into()
}

fn default_load() -> String {
    "push".into()
}

fn default_targets() -> String {
    "markers".into()
}

fn default_direction() -> Point {
    [0.0, 0.0, -1.0]
}

/// The most points a simulated camera gives (a full-HD depth frame has about 2 million).
pub const MAX_CAMERA_POINTS: usize = 5_000_000;

/// The simulated camera and its random seed.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraSpec {
    /// Viewing direction (the camera looks along it).
    pub view: Point,
    /// Points sampled uniformly by area on the visible triangles.
    pub points: usize,
    /// Standard deviation of the Gaussian noise on each point (m).
    pub noise: f64,
    /// Extra points uniform in the bounding box grown by 10 %, as a fraction of `points`.
    pub outliers: f64,
    /// Seed of the sampling and noise.
    #[serde(default = "default_seed")]
    pub seed: u64,
}

fn default_seed() -> u64 {
    1
}

impl CameraSpec {
    /// Refuses a camera no cloud can be drawn from (the field at fault named first).
    pub fn validate(&self) -> std::result::Result<(), String> {
        if !(self.view.iter().all(|x| x.is_finite()) && self.view.iter().any(|&x| x != 0.0)) {
            return Err(format!("view = {:?} must be non-zero and finite", self.view));
        }
        if !(1..=MAX_CAMERA_POINTS).contains(&self.points) {
            return Err(format!(
                "points = {} must be between 1 and {MAX_CAMERA_POINTS} (a full-HD depth frame has ~2 million)",
                self.points
            ));
        }
        if !(self.noise >= 0.0 && self.noise.is_finite()) {
            return Err(format!("noise = {} must be >= 0 (m)", self.noise));
        }
        if !(0.0..=1.0).contains(&self.outliers) {
            return Err(format!("outliers = {} must lie in [0, 1] (a fraction of the points)", self.outliers));
        }
        Ok(())
    }
}

/// A rigid misalignment of the camera's frame: cloud and truth are moved by
/// `x ↦ R x + t`, R the rotation by `rotation_deg` about `axis` (through the origin of the
/// model's frame, inside the phantom), t of length `translation` along `direction`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Misalignment {
    /// Rotation angle (degrees, in [-180, 180]).
    pub rotation_deg: f64,
    /// Rotation axis.
    pub axis: Point,
    /// Translation length (in the file: metres, or a text with its unit, "10 mm").
    pub translation: Length,
    /// Translation direction.
    pub direction: Point,
}

impl Default for Misalignment {
    fn default() -> Self {
        Misalignment {
            rotation_deg: 0.0,
            axis: [1.0, 1.0, 1.0],
            translation: Length::default(),
            direction: [-1.0, 1.0, 0.0],
        }
    }
}

impl Misalignment {
    /// The model → camera transform.
    pub fn transform(&self) -> std::result::Result<RigidTransform, String> {
        let len = mesh::dot(self.direction, self.direction).sqrt();
        let translation = self.translation.in_metres();
        if translation != 0.0 && !(len > 0.0 && len.is_finite()) {
            return Err(format!("misalignment direction {:?} must be non-zero and finite", self.direction));
        }
        let shift = if translation == 0.0 { 0.0 } else { translation / len };
        RigidTransform::from_axis_angle(self.axis, self.rotation_deg.to_radians(), self.direction.map(|x| x * shift))
            .map_err(|e| e.to_string())
    }
}

/// The registration models: every method deforms the phantom meshed with `tets` tetrahedra.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelsSpec {
    /// The phantom meshed with about this many tetrahedra.
    pub tets: usize,
    /// The methods compared, in order (`[[models.method]]`).
    pub method: Vec<CaseMethod>,
}

/// A registration method of the comparison.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CaseMethod {
    /// Name in the table (its output directory is made of its letters and digits).
    pub name: String,
    /// What deforms the organ.
    pub kind: MethodKind,
    /// The finite-element model's material (`kind = "fem"` only).
    #[serde(default)]
    pub material: Option<Material>,
    /// Most match-and-deform iterations of a frame from rest for this method, in place of its
    /// kind's default: `[registration] iterations` for a FEM, a network's real-time budget
    /// ([`register::NetworkDeformer::ITERATIONS`]), a hybrid's `network_iterations` and 2 of the
    /// FEM.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub iterations: Option<usize>,
    /// Most iterations of a frame warm-started from the previous one, in place of its kind's
    /// default: `[registration] warm_iterations`, a network's
    /// ([`register::NetworkDeformer::WARM_ITERATIONS`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub warm_iterations: Option<usize>,
    /// The network's iterations before the finite-element ones (`kind = "hybrid"` only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub network_iterations: Option<usize>,
}

/// The kinds of registration method.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MethodKind {
    /// The finite-element model of the method's `material`, fixed on the truth's fixed region,
    /// pulled by data springs of the default stiffness ([`register::FemDeformer::default_stiffness`]).
    Fem,
    /// The U-Net given to the comparison (`augsim register --model`), trained on this phantom
    /// with the normal displacement of its `visible` region as input; left out when none is given.
    Network,
    /// A learned model for the first `network_iterations` of a frame from rest, then the
    /// finite-element model of `material` from its estimate: the first reduced-order model given
    /// (its shape fit, on the FEM's mesh, alone on a stream's next frames), else the U-Net (which
    /// must have been trained on the FEM's mesh; the FEM alone on a stream's next frames); left out
    /// when no learned model is given.
    Hybrid,
}

impl CaseScenario {
    /// Parses and checks scenario text.
    pub fn from_text(source: &ScenarioText) -> Result<CaseScenario> {
        let scenario: CaseScenario = source.parse_as(Kind::RegistrationCase)?;
        scenario.validate().map_err(|m| ScenarioError::invalid(&source.origin, m))?;
        Ok(scenario)
    }

    /// Parses and checks the text of a scenario; `origin` names it in errors.
    pub fn parse(text: &str, origin: &Path) -> Result<CaseScenario> {
        Self::from_text(&ScenarioText::new(text, origin))
    }

    /// Reads a scenario file (or a built-in scenario).
    pub fn load(path: &Path) -> Result<CaseScenario> {
        Self::from_text(&ScenarioText::read(path)?)
    }

    /// The built-in case of `augsim register --demo` ([`BUILTIN_CASE`]).
    pub fn builtin() -> CaseScenario {
        crate::builtin_with(BUILTIN_CASE, Self::from_text)
    }

    /// A case scenario given as a file, or the built-in one, with `overrides`, checked; errors
    /// name where it came from.
    pub fn with_overrides(path: Option<&Path>, overrides: &CaseOverrides) -> Result<CaseScenario> {
        let mut scenario = match path {
            Some(path) => CaseScenario::load(path)?,
            None => CaseScenario::builtin(),
        };
        let o = overrides;
        o.force.into_iter().for_each(|f| scenario.truth.force = f);
        o.frames.into_iter().for_each(|n| scenario.truth.frames = n);
        o.misalign_deg.into_iter().for_each(|d| scenario.misalignment.rotation_deg = d);
        o.misalign_shift.into_iter().for_each(|m| scenario.misalignment.translation = m);
        if let Some(iterations) = o.iterations {
            // Given beside the file, it holds for every method.
            scenario.registration.iterations = iterations;
            scenario.models.method.iter_mut().for_each(|m| m.iterations = Some(iterations));
        }
        if o.rigid && scenario.registration.rigid.is_none() {
            scenario.registration.rigid = Some(register::RigidOptions::default());
        }
        let origin = path.map_or_else(|| format!("{BUILTIN_CASE} (built-in scenario)"), |p| p.display().to_string());
        let origin = format!("{origin} with the settings given");
        scenario.validate().map_err(|message| ScenarioError::Invalid { origin, message })?;
        Ok(scenario)
    }

    /// Checks the values (what parsing cannot).
    pub fn validate(&self) -> std::result::Result<(), String> {
        let bad = |m: String| Err(m);
        let finite = |p: Point| p.iter().all(|x| x.is_finite());
        let nonzero = |p: Point| finite(p) && p.iter().any(|&x| x != 0.0);
        let t = &self.truth;
        if t.tets < 100 || self.models.tets < 100 {
            return bad(format!("truth.tets = {} and models.tets = {} must be at least 100", t.tets, self.models.tets));
        }
        t.material.validate().map_err(|e| format!("truth.material: {e}"))?;
        if !t.force.is_finite() {
            return bad(format!("truth.force = {} must be finite", t.force));
        }
        if !(1..=MAX_FRAMES).contains(&t.frames) {
            return bad(format!("truth.frames = {} must be between 1 and {MAX_FRAMES}", t.frames));
        }
        if !nonzero(t.direction) {
            return bad(format!("truth.direction = {:?} must be non-zero and finite", t.direction));
        }
        if let Some(p) = &t.patch {
            if !(finite(p.from) && nonzero(p.direction) && p.radius > 0.0 && p.radius.is_finite()) {
                return bad(format!("truth.patch = {p:?}: finite `from`, non-zero `direction`, positive `radius`"));
            }
        }
        self.camera.validate().map_err(|e| format!("camera.{e}"))?;
        let m = &self.misalignment;
        let values = [
            ("rotation_deg", m.rotation_deg.is_finite(), m.rotation_deg.to_string()),
            ("axis", finite(m.axis), format!("{:?}", m.axis)),
            ("direction", finite(m.direction), format!("{:?}", m.direction)),
        ];
        if let Some((name, _, value)) = values.iter().find(|(_, ok, _)| !ok) {
            return bad(format!("misalignment.{name} = {value} must be finite"));
        }
        if m.rotation_deg.abs() > 180.0 {
            return bad(format!("misalignment.rotation_deg = {} must lie in [-180, 180]", m.rotation_deg));
        }
        m.transform().map_err(|e| format!("misalignment: {e}"))?;
        // The loop's settings first: a budget given beside the case holds for every method too.
        self.registration.validate().map_err(|e| format!("registration: {e}"))?;
        if self.models.method.is_empty() {
            return bad("models.method: no method to compare (add [[models.method]] tables)".into());
        }
        let mut slugs = Vec::new();
        for method in &self.models.method {
            let name = &method.name;
            match (method.kind, &method.material) {
                (MethodKind::Fem | MethodKind::Hybrid, Some(material)) => {
                    material.validate().map_err(|e| format!("method {name:?}: material: {e}"))?
                }
                (MethodKind::Fem | MethodKind::Hybrid, None) => {
                    return bad(format!(
                        "method {name:?}: kind = \"fem\" or \"hybrid\" needs a `material` (law, young, poisson)"
                    ))
                }
                (MethodKind::Network, Some(_)) => {
                    return bad(format!("method {name:?}: kind = \"network\" takes no `material`"))
                }
                (MethodKind::Network, None) => {}
            }
            match (method.kind, method.network_iterations) {
                (MethodKind::Hybrid, None | Some(0)) => {
                    return bad(format!("method {name:?}: kind = \"hybrid\" needs `network_iterations` of at least 1"))
                }
                (MethodKind::Fem | MethodKind::Network, Some(_)) => {
                    return bad(format!("method {name:?}: only kind = \"hybrid\" takes `network_iterations`"))
                }
                _ => {}
            }
            if method.iterations == Some(0) || method.warm_iterations == Some(0) {
                return bad(format!("method {name:?}: iterations and warm_iterations must be at least 1"));
            }
            let slug = slug(name);
            if slug.is_empty() {
                return bad(format!("method name {name:?} has no letter or digit"));
            }
            if slugs.contains(&slug) {
                return bad(format!("method name {name:?} is not distinct from another's ({slug})"));
            }
            slugs.push(slug);
        }
        Ok(())
    }
}

/// A file name for a method: its lowercase letters and digits, other runs as one `_`.
pub fn slug(name: &str) -> String {
    let lower = name.to_ascii_lowercase();
    let words: Vec<&str> = lower.split(|c: char| !c.is_ascii_alphanumeric()).filter(|w| !w.is_empty()).collect();
    words.join("_")
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Settings given beside the case override its own; iterations hold for every method; a
    /// value the case cannot take is refused naming where the case came from.
    #[test]
    fn overrides_reach_the_case_and_are_checked() {
        let overrides = CaseOverrides {
            force: Some(2.5),
            frames: Some(4),
            misalign_deg: Some(3.0),
            misalign_shift: Some(Length::metres(0.007)),
            iterations: Some(9),
            rigid: true,
        };
        let case = CaseScenario::with_overrides(None, &overrides).unwrap();
        assert_eq!((case.truth.force, case.truth.frames, case.registration.iterations), (2.5, 4, 9));
        assert_eq!((case.misalignment.rotation_deg, case.misalignment.translation.in_metres()), (3.0, 0.007));
        assert!(case.models.method.iter().all(|m| m.iterations == Some(9)));
        assert_eq!(case.registration.rigid, Some(register::RigidOptions::default()));
        assert_eq!(CaseScenario::with_overrides(None, &CaseOverrides::default()).unwrap(), CaseScenario::builtin());
        let e = CaseScenario::with_overrides(None, &CaseOverrides { frames: Some(0), ..overrides }).unwrap_err();
        let e = e.to_string();
        assert!(e.contains("(built-in scenario) with the settings given: truth.frames = 0"), "{e}");
    }

    /// A simulated camera asked for more points than memory holds, or for outliers beyond the
    /// fraction of its points they are, is refused by its field.
    #[test]
    fn a_camera_beyond_its_bounds_is_refused() {
        let mut case = CaseScenario::builtin();
        case.camera.points = 1_000_000_000_000_000_000;
        assert!(case.validate().unwrap_err().starts_with("camera.points = 1000000000000000000 must be between 1"));
        case.camera.points = MAX_CAMERA_POINTS;
        case.camera.outliers = 1.5;
        assert!(case.validate().unwrap_err().starts_with("camera.outliers = 1.5 must lie in [0, 1]"));
        case.camera.outliers = 1.0;
        assert_eq!(case.validate(), Ok(()));
    }
}
