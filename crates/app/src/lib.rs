//! augsim's application layer, between the algorithm crates (mesh, fem, filter, learn, register,
//! scenario) and the programs (the command line, the streaming server, the Python package):
//!
//! - [`registration`]: a registration set up from the user's choices (a patient's set-up, a FEM
//!   scenario, or a learned model and its dataset scenario; targets in their unit; settings), the
//!   one way `register`, `serve` and Python build it; [`models`]: the models it deforms the organ
//!   with (a FEM, a U-Net, a reduced-order model) and their default loop settings; [`output`]:
//!   what a registration writes (organ.vtu, targets.csv, summary.json) and what a comparison of
//!   methods writes; [`printout`]: the lines printed about a registration run and a comparison.
//! - [`points`]: points read at a command's boundary (CSV, 3D Slicer's `.fcsv` and `.mrk.json`,
//!   clouds as `.npy`, `.ply` and model files) in its working frame (RAS or LPS) and unit.
//! - [`meshing`]: an organ's volume mesh from its surface, a labelmap's label or the phantom.
//! - [`prepare`]: a patient's organ from its segmented surface to a registration set-up (repair,
//!   mesh, regions, scenarios, dataset, model, report), resumable; [`setup`]: that set-up's
//!   directory, its files as `prepare` writes them and a registration reads them.
//! - [`case`], [`simulate`], [`picture`]: synthetic registration cases on the phantom (truth from
//!   a finer mesh and another law, a simulated camera cloud), the comparison of methods,
//!   side-view pictures; [`comparison`]: a comparison case run end to end (`register --demo`).
//! - [`assimilation`]: ROUKF identification from an assimilation scenario (synthetic
//!   observations or track files, traces, plots, the estimated deformation), also one step at a
//!   time for a stream.
//! - [`generation`]: a dataset generated as `augsim generate` asks (uniform draws, then draws
//!   chosen where a reduced-order model is least sure).
//! - [`solve`]: a static scenario solved, with the fields written for ParaView; [`evaluation`]:
//!   a learned model's errors on the samples held out from it, and the files `eval` writes;
//!   [`training`]: a U-Net (with its learning curve) or a reduced-order model trained on a
//!   dataset's split, the one way `train`, `prepare` and the experiments train; [`prediction`]: a
//!   model's prediction from a file, as `predict` makes it.
//! - [`curve`], [`sample_view`], [`file_view`]: the learning curve as PNG; a dataset sample and a
//!   model's prediction in the 3D viewer; a mesh, surface or sequence file in it.

pub mod assimilation;
pub mod case;
pub mod comparison;
pub mod curve;
pub mod evaluation;
pub mod file_view;
pub mod generation;
pub mod meshing;
pub mod models;
pub mod output;
pub mod picture;
pub mod points;
pub mod prediction;
pub mod prepare;
pub mod printout;
pub mod registration;
pub mod sample_view;
#[cfg(feature = "live")]
pub mod serving;
pub mod setup;
pub mod simulate;
pub mod solve;
pub mod training;
pub mod values;
