//! A patient's registration set-up, the directory `augsim prepare` writes and `--patient DIR`
//! reads: its set-up file ([`PATIENT_FILE`]: the method, model, scenarios, targets, the unit and
//! frame of its inputs, the structures), the organ's own surface ([`SURFACE_FILE`]) and the record
//! of the preparation ([`STATE_FILE`]).

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use mesh::io::Frame;
use mesh::length::{mm, LengthUnit};
use mesh::{Mesh, TriSurface};

/// The file of a patient's registration set-up in the directory `augsim prepare` writes.
pub const PATIENT_FILE: &str = "registration.toml";

/// How a patient's organ is registered: with its learned model, its FEM, or both in turn.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum PatientMethod {
    /// The learned model, on its dataset scenario.
    #[default]
    Learned,
    /// The FEM of the static scenario.
    Fem,
    /// The learned model from rest (a reduced-order model's shape fit, on the FEM's mesh), then
    /// the FEM from its estimate; the shape fit alone on a stream's next frames
    /// ([`crate::registration::MethodSpec::Hybrid`]).
    Hybrid,
}

impl PatientMethod {
    /// The method asked for on a command line: the FEM with `fem`, the learned model with
    /// `learned`, the hybrid with `hybrid`, otherwise (`None`) the set-up's own.
    pub fn asked(fem: bool, learned: bool, hybrid: bool) -> Option<PatientMethod> {
        [(fem, PatientMethod::Fem), (learned, PatientMethod::Learned), (hybrid, PatientMethod::Hybrid)]
            .into_iter()
            .find_map(|(asked, method)| asked.then_some(method))
    }

    /// How the set-up file names it.
    pub fn name(self) -> &'static str {
        match self {
            PatientMethod::Learned => "learned",
            PatientMethod::Fem => "fem",
            PatientMethod::Hybrid => "hybrid",
        }
    }
}

/// A patient's registration set-up ([`PATIENT_FILE`]): the method `augsim prepare` found the
/// best on its validation, the learned model and its dataset scenario, the FEM alternative, the
/// targets and their unit; paths relative to the file. `augsim prepare` writes it, its validation
/// names the method, `--patient` reads it: all through this type.
#[derive(Clone, Debug, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct Patient {
    /// The method registrations use unless another is asked for.
    #[serde(default)]
    pub method: PatientMethod,
    /// The learned model's directory.
    pub model: PathBuf,
    /// The dataset scenario the model was trained on.
    pub scenario: PathBuf,
    /// The FEM's static scenario.
    pub fem: PathBuf,
    /// The targets at rest.
    pub targets: PathBuf,
    /// The unit of the targets' file.
    pub units: LengthUnit,
    /// The unit of the files the set-up was prepared from (set-ups of older versions name none).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub input_units: Option<LengthUnit>,
    /// The frame of the files the set-up was prepared from (set-ups of older versions, and those
    /// prepared from files naming none, name none).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub input_frame: Option<Frame>,
    /// Structures that move with the organ, surfaces in [`STRUCTURES_UNIT`] in the organ's frame.
    #[serde(default)]
    pub structures: Vec<PathBuf>,
    /// The factors on the σ of the methods that give one, calibrated by the validation (set-ups
    /// of older versions name none: 1).
    #[serde(default)]
    pub sigma: SigmaFactors,
}

/// The factor on each method's σ at the targets, calibrated on a set-up's validation registrations
/// ([`crate::registration::RegistrationSpec::sigma_factor`]); the FEM gives no σ.
#[derive(Clone, Copy, Debug, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct SigmaFactors {
    /// The learned model's.
    pub learned: f64,
    /// The hybrid's.
    pub hybrid: f64,
}

impl Default for SigmaFactors {
    fn default() -> Self {
        SigmaFactors { learned: 1.0, hybrid: 1.0 }
    }
}

impl SigmaFactors {
    /// The factor of `method` (1 for the FEM, which gives no σ).
    pub fn of(&self, method: PatientMethod) -> f64 {
        match method {
            PatientMethod::Learned => self.learned,
            PatientMethod::Hybrid => self.hybrid,
            PatientMethod::Fem => 1.0,
        }
    }

    /// Sets the factor of `method` (none for the FEM).
    pub fn set(&mut self, method: PatientMethod, factor: f64) {
        match method {
            PatientMethod::Learned => self.learned = factor,
            PatientMethod::Hybrid => self.hybrid = factor,
            PatientMethod::Fem => {}
        }
    }
}

/// The unit of a set-up's structure surfaces ([`Patient::structures`]).
pub(crate) const STRUCTURES_UNIT: LengthUnit = LengthUnit::Millimetre;

impl Patient {
    /// The set-up of the patient directory `dir`.
    pub(crate) fn read(dir: &Path) -> Result<Patient> {
        let path = dir.join(PATIENT_FILE);
        let text = std::fs::read_to_string(&path).with_context(|| {
            format!("reading {} (is {} a directory made by augsim prepare?)", path.display(), dir.display())
        })?;
        let patient: Patient = toml::from_str(&text).map_err(|e| {
            let newer =
                if e.message().starts_with("unknown field") { " (prepared by a newer augsim? update it)" } else { "" };
            anyhow::anyhow!("reading {}{newer}: {e}", path.display())
        })?;
        // Checked as read, whichever method a run takes.
        let SigmaFactors { learned, hybrid } = patient.sigma;
        if let Some((key, factor)) =
            [("learned", learned), ("hybrid", hybrid)].into_iter().find(|(_, f)| !(f.is_finite() && *f > 0.0))
        {
            anyhow::bail!("{}: [sigma] {key} = {factor} must be positive and finite", path.display());
        }
        Ok(patient)
    }

    /// Writes the set-up into the patient directory `dir`, under comments that say what it holds.
    pub(crate) fn write(&self, dir: &Path) -> Result<()> {
        let works_in = match self.input_frame {
            Some(_) => format!(" (the set-up works in {})", SET_UP_FRAME),
            None => " (no input named a frame)".into(),
        };
        let text = format!(
            "# The registration set-up of this organ: `augsim register --patient DIR`, `augsim serve\n\
             # --patient DIR`, `augsim.Registration(patient=DIR)`. Paths are relative to this file.\n\
             # method: \"learned\", \"fem\" or \"hybrid\" (the learned model from rest, then the FEM), the one\n\
             # that registered the validation's pushes the best.\n\
             # input_units, input_frame: the unit and frame of the files it was prepared from, in which\n\
             # points whose files name none are read and results given back{works_in}.\n\
             # structures: surfaces that move with the organ ({}, the organ's frame).\n\
             # sigma: the factor on each method's σ at the targets, calibrated on the validation's pushes.\n{}",
            STRUCTURES_UNIT.symbol(),
            toml::to_string(self)?
        );
        mesh::io::write_atomic_bytes(&dir.join(PATIENT_FILE), text.as_bytes())?;
        Ok(())
    }
}

/// The frame a set-up works in whenever its inputs name one: the same organ segmented in RAS or
/// in LPS gives the same mesh, draws and model.
pub const SET_UP_FRAME: Frame = Frame::Lps;

/// The file that records a preparation.
pub const STATE_FILE: &str = "prepare.json";

/// The steps a preparation in `dir` has done, when its record is there and its validation, which
/// chooses the method `registration.toml` names, is not among them (`None` otherwise).
pub fn steps_before_validation(dir: &Path) -> Result<Option<Vec<String>>> {
    let path = dir.join(STATE_FILE);
    if !path.exists() {
        return Ok(None);
    }
    /// What of the record this needs: the names of the steps done.
    #[derive(serde::Deserialize)]
    struct Record {
        steps: Vec<Step>,
    }
    #[derive(serde::Deserialize)]
    struct Step {
        name: String,
    }
    let record: Record = serde_json::from_str(&std::fs::read_to_string(&path)?)
        .with_context(|| format!("reading {}", path.display()))?;
    let done: Vec<String> = record.steps.into_iter().map(|s| s.name).collect();
    Ok((!done.iter().any(|s| s == "validation")).then_some(done))
}

/// The organ's surface in a prepared directory: in millimetres, in the set-up's frame.
pub const SURFACE_FILE: &str = "surface.stl";

/// The organ's surface (`surface.stl` of a set-up: `path`) in metres, the unit it is in (mm, or m) told by the size of
/// the organ's mesh (in m), which it must match within a factor of [`SURFACE_TO_MESH`] (the mesh
/// may leave out parts thinner than its tetrahedra).
pub(crate) fn read_organ_surface(path: &Path, organ: &Mesh) -> Result<TriSurface> {
    let mut surface = mesh::io::read_surface(path)?;
    let (extent, organ_extent) = (mesh::repair::largest_extent(&surface), mesh::longest_side(organ.bounds()));
    let off = |u: &LengthUnit| (extent * u.metres() / organ_extent).ln().abs();
    let unit = LengthUnit::ALL
        .into_iter()
        .filter(|u| off(u) < SURFACE_TO_MESH.ln())
        .min_by(|a, b| off(a).total_cmp(&off(b)))
        .with_context(|| {
            format!(
                "{} (largest extent {extent:.4}, in any length unit) does not match organ.vtu ({} mm): remove {} and \
                 prepare it again",
                path.display(),
                mm(organ_extent),
                path.parent().unwrap_or(path).display()
            )
        })?;
    surface.vertices.iter_mut().for_each(|p| *p = unit.point_to_metres(*p));
    Ok(surface)
}

/// How far the extents of the organ's surface and mesh may differ (as a factor).
const SURFACE_TO_MESH: f64 = 2.0;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_organ_s_surface_is_read_back_in_metres_from_either_unit() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(SURFACE_FILE);
        let organ = mesh::box_tet([0.0; 3], [0.1, 0.05, 0.04], [4, 2, 2]).unwrap();
        let surface = mesh::boundary_surface(&organ).compacted();
        crate::meshing::write_surface_in_mm(&path, &surface, None).unwrap();
        let read = read_organ_surface(&path, &organ).unwrap();
        let off = |s: &mesh::TriSurface| {
            s.vertices.iter().zip(&surface.vertices).map(|(a, b)| mesh::distance(*a, *b)).fold(0.0, f64::max)
        };
        assert!(off(&read) < 1e-8, "read back {} m off (STL holds f32)", off(&read));
        mesh::io::write_surface(&path, &surface).unwrap();
        assert!(off(&read_organ_surface(&path, &organ).unwrap()) < 1e-8, "in metres");
        // A mesh that left out a thin part of its surface (30 % of its length) still matches it.
        let shorter = mesh::box_tet([0.0; 3], [0.07, 0.05, 0.04], [4, 2, 2]).unwrap();
        assert!(off(&read_organ_surface(&path, &shorter).unwrap()) < 1e-8, "a mesh 30 % shorter");
        let thrice = mesh::box_tet([0.0; 3], [0.3, 0.15, 0.12], [4, 2, 2]).unwrap();
        let refused = read_organ_surface(&path, &thrice).unwrap_err().to_string();
        assert!(refused.contains("does not match organ.vtu (300 mm)"), "{refused}");
    }
}
