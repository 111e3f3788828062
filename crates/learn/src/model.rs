//! A learned model of either kind, as a model directory holds it: the U-Net
//! ([`TrainedModel`]) or the reduced-order model ([`ReducedModel`]). Everything that only
//! predicts (evaluation, registration, the viewer, Python) takes a [`Model`].

use std::fmt;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use mesh::embedding::Grid;
use mesh::Mesh;

use crate::data::corrupt::Corruption;
use crate::data::dataset::Samples;
use crate::data::grid::{placed_model_grid, GridPlacement, GridShape, GridToMesh};
use crate::data::split::{Provenance, SampleRole};
use crate::net::predict::Predictor;
use crate::net::unet::TrainedModel;
use crate::rom::ReducedModel;
use crate::FieldUnit;
use crate::{Compute, LearnError, Result};

/// The file of a model directory that describes the model.
pub const MODEL_FILE: &str = "model.json";
/// The file of a U-Net's weights beside its [`MODEL_FILE`], as `augsim train` writes it.
pub const WEIGHTS_FILE: &str = "model.safetensors";

/// A learned model: the U-Net or the reduced-order model.
#[derive(Clone, Debug)]
pub enum Model {
    /// The 3D U-Net.
    UNet(Arc<TrainedModel>),
    /// The reduced-order model (POD basis and Gaussian-process regression).
    Reduced(Arc<ReducedModel>),
}

/// The kind of a learned model.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    /// The 3D U-Net (U-Mesh).
    UNet,
    /// The reduced-order model.
    #[default]
    Rom,
}

impl Method {
    /// The method's name for people: "U-Net" or "ROM".
    pub fn display_name(self) -> &'static str {
        match self {
            Method::UNet => "U-Net",
            Method::Rom => "ROM",
        }
    }
}

impl fmt::Display for Method {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Method::UNet => "unet",
            Method::Rom => "rom",
        })
    }
}

impl std::str::FromStr for Method {
    type Err = LearnError;

    fn from_str(s: &str) -> Result<Method> {
        match s {
            "unet" => Ok(Method::UNet),
            "rom" => Ok(Method::Rom),
            other => Err(LearnError::InvalidInput(format!("unknown method `{other}`: expected `rom` or `unet`"))),
        }
    }
}

impl Model {
    /// The `model.json` of `path`: `path/model.json` for a model directory or for one of its
    /// other files (its `.safetensors` weights), else `path` itself.
    pub fn json_path(path: &Path) -> PathBuf {
        let weights = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("safetensors"));
        match (path.is_dir(), weights, path.parent()) {
            (true, _, _) => path.join(MODEL_FILE),
            (false, true, Some(directory)) => directory.join(MODEL_FILE),
            _ => path.to_path_buf(),
        }
    }

    /// Loads the model of a model directory (or of its `model.json`), whichever kind it is.
    pub fn load(path: &Path) -> Result<Model> {
        let json = Model::json_path(path);
        match Model::kind(&json)? {
            Method::Rom => Ok(Model::Reduced(Arc::new(ReducedModel::load(&json)?))),
            Method::UNet => Ok(Model::UNet(Arc::new(TrainedModel::load(&json)?))),
        }
    }

    /// The kind of model a `model.json` describes, from its `format`; an error names a file that
    /// is no JSON (with the place of the fault) or no model's.
    pub fn kind(json: &Path) -> Result<Method> {
        let text = std::fs::read_to_string(json).map_err(|e| LearnError::io(json, e))?;
        let value: serde_json::Value =
            serde_json::from_str(&text).map_err(|e| LearnError::model(json, format!("invalid model JSON: {e}")))?;
        match value.get("format").and_then(|f| f.as_str()) {
            Some(crate::rom::ROM_FORMAT) => Ok(Method::Rom),
            Some(crate::net::unet::MODEL_FORMAT) => Ok(Method::UNet),
            other => Err(LearnError::model(
                json,
                format!(
                    "its format {} is no model's: {:?} (a U-Net) or {:?} (a reduced-order model) was expected",
                    other.map_or("(none)".to_string(), |f| format!("{f:?}")),
                    crate::net::unet::MODEL_FORMAT,
                    crate::rom::ROM_FORMAT
                ),
            )),
        }
    }

    /// Which kind of model this is.
    pub fn method(&self) -> Method {
        match self {
            Model::UNet(_) => Method::UNet,
            Model::Reduced(_) => Method::Rom,
        }
    }

    /// The grid of its training data.
    pub fn grid(&self) -> GridShape {
        match self {
            Model::UNet(m) => m.grid,
            Model::Reduced(m) => m.grid,
        }
    }

    /// Where that grid lies, when known.
    pub fn placement(&self) -> Option<GridPlacement> {
        match self {
            Model::UNet(m) => m.placement,
            Model::Reduced(m) => m.placement,
        }
    }

    /// The input unit (forces or displacements).
    pub fn input_unit(&self) -> FieldUnit {
        match self {
            Model::UNet(m) => m.input_unit,
            Model::Reduced(m) => m.input_unit,
        }
    }

    /// The corruption its training inputs had.
    pub fn training_corruption(&self) -> Corruption {
        match self {
            Model::UNet(m) => m.training.as_ref().map(|t| t.corruption.clone()).unwrap_or_default(),
            Model::Reduced(m) => m.info.corruption.clone(),
        }
    }

    /// The splits behind the model, when recorded.
    pub fn provenance(&self) -> Option<Provenance<'_>> {
        match self {
            Model::UNet(m) => m.provenance(),
            Model::Reduced(m) => Some(Provenance { own: &m.info.split, earlier: &[] }),
        }
    }

    /// The model's grid placed in space; an error when the placement was not recorded.
    pub fn placed_grid(&self) -> Result<Grid> {
        placed_model_grid(self.placement(), self.grid())
    }

    /// Whether the model takes nodal forces (N) rather than displacements (m).
    pub fn takes_forces(&self) -> bool {
        self.input_unit().is_force()
    }

    /// The interpolation of fields on the model's grid (a displacement, a standard deviation) to
    /// the nodes of `organ` ([`GridToMesh`]).
    pub fn to_mesh(&self, organ: &Mesh) -> Result<GridToMesh> {
        GridToMesh::new(organ, &self.placed_grid()?)
    }

    /// A predictor of this model on `compute` (the reduced-order model runs on the CPU only).
    pub fn predictor(&self, compute: Compute) -> Result<ModelPredictor> {
        match self {
            Model::UNet(m) => m.as_ref().predictor(compute),
            Model::Reduced(m) if compute == Compute::Cpu => Ok(ModelPredictor::Reduced(Arc::clone(m))),
            Model::Reduced(_) => Err(LearnError::InvalidInput(format!(
                "the reduced-order model runs on the CPU only (asked: {compute})"
            ))),
        }
    }
}

/// What evaluation and point inputs need of a learned model, whichever kind: the U-Net as
/// training returns it ([`TrainedModel`]) or a loaded [`Model`].
pub trait LearnedModel {
    /// The grid of its training data.
    fn grid_shape(&self) -> GridShape;
    /// The grid placed in space.
    fn placed_grid(&self) -> Result<Grid>;
    /// Whether it takes forces (N) rather than displacements (m).
    fn takes_forces(&self) -> bool;
    /// The splits behind it, when its training recorded them.
    fn provenance(&self) -> Option<Provenance<'_>>;
    /// A predictor on `compute`.
    fn predictor(&self, compute: Compute) -> Result<ModelPredictor>;
    /// The RMS norm of its training inputs (in its input unit), where it records one (the
    /// U-Net's input normalisation).
    fn training_input_scale(&self) -> Option<f64> {
        None
    }

    /// How far an input `field` lies from its training inputs as its regression sees it, where
    /// it can tell ([`ReducedModel::feature_ratio`]: the reduced-order model).
    fn input_feature_ratio(&self, _field: &[f32]) -> Result<Option<f64>> {
        Ok(None)
    }

    /// The field entries its input is read at, where it reads only some (the reduced-order
    /// model's visible surface); `None`: everywhere.
    fn input_entries(&self) -> Option<&[usize]> {
        None
    }

    /// Fails when `samples` include samples it (or a model it was fine-tuned from) was trained or
    /// validated on; a model without a recorded split passes.
    fn check_unseen(&self, samples: &Samples) -> Result<()> {
        self.provenance().map_or(Ok(()), |p| p.check_unseen(samples))
    }

    /// Whether `samples` come from the data its own run was trained on (then its recorded test
    /// split is what [`held_out`](Self::held_out) gives).
    fn trained_on(&self, samples: &Samples) -> bool {
        self.provenance().is_some_and(|p| p.trained_on(samples))
    }

    /// What a sample was to it ([`Provenance::role`]).
    fn role(&self, source: Option<&str>, index: u64) -> SampleRole {
        self.provenance().map_or(SampleRole::Unseen, |p| p.role(source, index))
    }

    /// The samples held out from it ([`Provenance::held_out`]; all of them without a recorded
    /// split).
    fn held_out(&self, samples: &Samples) -> Result<Samples> {
        self.provenance().map_or_else(|| Ok(samples.clone()), |p| p.held_out(samples))
    }
}

impl LearnedModel for TrainedModel {
    fn grid_shape(&self) -> GridShape {
        self.grid
    }
    fn placed_grid(&self) -> Result<Grid> {
        TrainedModel::placed_grid(self)
    }
    fn takes_forces(&self) -> bool {
        TrainedModel::takes_forces(self)
    }
    fn provenance(&self) -> Option<Provenance<'_>> {
        TrainedModel::provenance(self)
    }
    fn predictor(&self, compute: Compute) -> Result<ModelPredictor> {
        Ok(ModelPredictor::UNet(Box::new(Predictor::new(self, compute)?)))
    }
    fn training_input_scale(&self) -> Option<f64> {
        Some(self.normalization.input_scale)
    }
}

impl LearnedModel for Model {
    fn grid_shape(&self) -> GridShape {
        self.grid()
    }
    fn placed_grid(&self) -> Result<Grid> {
        Model::placed_grid(self)
    }
    fn takes_forces(&self) -> bool {
        Model::takes_forces(self)
    }
    fn provenance(&self) -> Option<Provenance<'_>> {
        Model::provenance(self)
    }
    fn predictor(&self, compute: Compute) -> Result<ModelPredictor> {
        Model::predictor(self, compute)
    }
    fn training_input_scale(&self) -> Option<f64> {
        match self {
            Model::UNet(m) => m.training_input_scale(),
            Model::Reduced(_) => None,
        }
    }
    fn input_feature_ratio(&self, field: &[f32]) -> Result<Option<f64>> {
        match self {
            Model::UNet(_) => Ok(None),
            Model::Reduced(rom) => rom.feature_ratio(field).map(Some),
        }
    }
    fn input_entries(&self) -> Option<&[usize]> {
        match self {
            Model::UNet(_) => None,
            Model::Reduced(rom) => Some(rom.input_entries()),
        }
    }
}

/// A model ready for repeated predictions.
pub enum ModelPredictor {
    /// The U-Net's predictor (boxed: it holds the repacked network's buffers).
    UNet(Box<Predictor>),
    /// The reduced-order model.
    Reduced(Arc<ReducedModel>),
    /// A model's predictions projected on a reduced-order model's basis ([`Projected`]).
    Projected(Box<ModelPredictor>, Arc<ReducedModel>),
}

impl ModelPredictor {
    /// Predicts the displacement field (m, `[3, nx, ny, nz]`) for one input field on the
    /// model's grid.
    pub fn predict(&self, input: &[f32]) -> Result<Vec<f32>> {
        match self {
            ModelPredictor::UNet(p) => p.predict(input),
            ModelPredictor::Reduced(m) => m.predict(input),
            ModelPredictor::Projected(p, basis) => basis.project(&p.predict(input)?),
        }
    }

    /// Whether it predicts a standard deviation with its fields (the reduced-order model does),
    /// known without predicting.
    pub fn predicts_std(&self) -> bool {
        matches!(self, ModelPredictor::Reduced(_))
    }

    /// [`predict`](Self::predict) with the predicted standard deviation at each grid node
    /// (`[nx, ny, nz]`, m), for a model that predicts one (the reduced-order model).
    pub fn predict_with_std(&self, input: &[f32]) -> Result<(Vec<f32>, Option<Vec<f32>>)> {
        match self {
            ModelPredictor::UNet(p) => Ok((p.predict(input)?, None)),
            ModelPredictor::Reduced(m) => m.predict_with_std(input).map(|p| (p.field, Some(p.std))),
            ModelPredictor::Projected(..) => Ok((self.predict(input)?, None)),
        }
    }

    /// The predicted standard deviation alone at each grid node (`[nx, ny, nz]`, m) for one input
    /// field, for a model that predicts one: a registration asks for it once per frame, after the
    /// iterations that needed the displacement only.
    pub fn predict_std(&self, input: &[f32]) -> Result<Option<Vec<f32>>> {
        match self {
            ModelPredictor::Reduced(m) => m.predict_std(input).map(Some),
            ModelPredictor::UNet(_) | ModelPredictor::Projected(..) => Ok(None),
        }
    }
}

/// A model whose predictions are projected on the basis of a reduced-order model trained on the
/// same data (e.g. the U-Net's): what the basis cannot hold, the training targets never held.
#[derive(Clone, Debug)]
pub struct Projected {
    /// The model.
    pub model: Model,
    /// The reduced-order model whose basis (and mean) the predictions are projected on.
    pub basis: Arc<ReducedModel>,
}

impl Projected {
    /// `model` projected on `basis`'s basis; both must be on one grid.
    pub fn new(model: Model, basis: &Model) -> Result<Projected> {
        let Model::Reduced(basis) = basis else {
            return Err(LearnError::InvalidInput("the projection basis must be a reduced-order model's".into()));
        };
        if basis.grid != model.grid() {
            return Err(LearnError::InvalidInput(format!(
                "the model is on grid {}, the basis on grid {}",
                model.grid(),
                basis.grid
            )));
        }
        Ok(Projected { model, basis: Arc::clone(basis) })
    }
}

impl LearnedModel for Projected {
    fn grid_shape(&self) -> GridShape {
        self.model.grid()
    }
    fn placed_grid(&self) -> Result<Grid> {
        self.model.placed_grid()
    }
    fn takes_forces(&self) -> bool {
        self.model.takes_forces()
    }
    fn provenance(&self) -> Option<Provenance<'_>> {
        self.model.provenance()
    }
    fn predictor(&self, compute: Compute) -> Result<ModelPredictor> {
        Ok(ModelPredictor::Projected(Box::new(self.model.predictor(compute)?), Arc::clone(&self.basis)))
    }
    fn training_input_scale(&self) -> Option<f64> {
        self.model.training_input_scale()
    }
    fn input_feature_ratio(&self, field: &[f32]) -> Result<Option<f64>> {
        self.model.input_feature_ratio(field)
    }
    fn input_entries(&self) -> Option<&[usize]> {
        self.model.input_entries()
    }
    /// The model's held-out samples, which the basis must not have been fitted or chosen on
    /// either: its basis would hold them.
    fn held_out(&self, samples: &Samples) -> Result<Samples> {
        let test = self.model.held_out(samples)?;
        self.check_basis_unseen(&test)?;
        Ok(test)
    }
    fn check_unseen(&self, samples: &Samples) -> Result<()> {
        self.model.check_unseen(samples)?;
        self.check_basis_unseen(samples)
    }
}

impl Projected {
    /// Fails when `samples` include samples the basis was fitted or chosen on.
    fn check_basis_unseen(&self, samples: &Samples) -> Result<()> {
        match self.basis.info.split.first_seen(samples) {
            Some((i, role)) => Err(LearnError::InvalidInput(format!(
                "sample {i} of {} was used to {role} the projection's basis (a reduced-order model), which would \
                 hold it: project on a basis fitted and chosen on none of the samples evaluated (one trained on the \
                 model's split)",
                samples.source.as_deref().unwrap_or_default()
            ))),
            None => Ok(()),
        }
    }
}
