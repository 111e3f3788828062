//! Scenario files: every kind of TOML file that augsim runs, parsed in one place.
//!
//! A scenario file names its kind on its first key, `kind = "..."`:
//!
//! | kind | type | what it describes | command |
//! | --- | --- | --- | --- |
//! | `static` | [`StaticScenario`] | one boundary-value problem: mesh, material, constraints, loads | `augsim solve` |
//! | `dataset` | [`DatasetScenario`] | a FEM model and how random samples are drawn for learning | `augsim generate` |
//! | `assimilation` | [`AssimilationScenario`] | a ROUKF identification: model, unknowns, observations | `augsim assimilate` |
//! | `registration_case` | [`CaseScenario`] | a synthetic registration case: truth, camera, methods | `augsim register --case` |
//!
//! Every parser rejects unknown keys and names the file, line and key at fault. The scenarios that
//! ship with augsim are built into this crate ([`builtin`], [`BUILTIN`]); a command given a name
//! instead of a path (e.g. `augsim solve beam`) reads the built-in one.
//!
//! ```
//! use augsim_scenario::StaticScenario;
//!
//! let text = r#"
//! kind = "static"
//! name = "cube"
//! [mesh.box]
//! min = [0.0, 0.0, 0.0]
//! max = [1.0, 1.0, 1.0]
//! cells = [2, 2, 2]
//! element = "hex"
//! [material]
//! law = "linear"
//! young = 1000.0
//! poisson = 0.3
//! [[fixed]]
//! select = { box = { min = [-0.1, -0.1, -0.1], max = [1.1, 1.1, 0.1] } }
//! [[force]]
//! select = { box = { min = [-0.1, -0.1, 0.9], max = [1.1, 1.1, 1.1] } }
//! total = [0.0, 0.0, -1.0]
//! "#;
//! let scenario = StaticScenario::parse(text, "cube.toml".as_ref())?;
//! let problem = scenario.build_problem(".".as_ref())?;
//! assert_eq!(problem.mesh.cells.len(), 8);
//! # Ok::<(), augsim_scenario::ScenarioError>(())
//! ```

pub mod assimilation;
pub mod dataset;
mod error;
pub mod problem;
pub mod registration;
pub mod source;

use std::path::{Path, PathBuf};

pub use assimilation::AssimilationScenario;
pub use dataset::DatasetScenario;
pub use error::{Result, ScenarioError};
pub use problem::StaticScenario;
pub use registration::CaseScenario;
pub use source::{build_mesh, fixed_problem, ElementKind, Fixed, MeshSource};

/// The kinds of scenario file, as written in their `kind` key.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// A static boundary-value problem ([`StaticScenario`]).
    Static,
    /// A learning dataset ([`DatasetScenario`]).
    Dataset,
    /// A ROUKF identification ([`AssimilationScenario`]).
    Assimilation,
    /// A synthetic registration case ([`CaseScenario`]).
    RegistrationCase,
}

impl Kind {
    /// Every kind.
    pub const ALL: [Kind; 4] = [Kind::Static, Kind::Dataset, Kind::Assimilation, Kind::RegistrationCase];

    /// The value of the `kind` key.
    pub fn key(self) -> &'static str {
        match self {
            Kind::Static => "static",
            Kind::Dataset => "dataset",
            Kind::Assimilation => "assimilation",
            Kind::RegistrationCase => "registration_case",
        }
    }

    fn from_key(key: &str) -> Option<Kind> {
        Kind::ALL.into_iter().find(|k| k.key() == key)
    }
}

/// Scenario text with where it came from.
#[derive(Clone, Debug)]
pub struct ScenarioText {
    /// The TOML text.
    pub text: String,
    /// The name errors are reported under (the file's path, or the built-in's name).
    pub origin: PathBuf,
    /// The directory relative paths in the scenario (meshes, surfaces) start from.
    pub dir: PathBuf,
}

impl ScenarioText {
    /// Reads the file at `path`; when there is none and `path` is a bare name (`beam`, no folder,
    /// no extension), the built-in scenario of that name. A missing file (`beam.toml`) is an
    /// error, which names the built-in of its stem's name if there is one.
    pub fn read(path: &Path) -> Result<ScenarioText> {
        match std::fs::read_to_string(path) {
            Ok(text) => Ok(ScenarioText::new(&text, path)),
            Err(error) => {
                let bare = path.parent().is_none_or(|p| p.as_os_str().is_empty()) && path.extension().is_none();
                let name = path.file_stem().and_then(|s| s.to_str()).unwrap_or_default();
                let path = path.to_path_buf();
                match (builtin(name), bare) {
                    (Some(text), true) => Ok(ScenarioText::builtin(name, text)),
                    (None, true) => Err(ScenarioError::Unknown { path, error }),
                    (Some(_), false) => Err(ScenarioError::MissingFile { path, error, name: name.to_string() }),
                    (None, false) => Err(ScenarioError::Io { path, error }),
                }
            }
        }
    }

    /// Text named `origin` (a path: relative paths in it start from its directory), without the
    /// byte-order mark some editors put first.
    pub fn new(text: &str, origin: &Path) -> ScenarioText {
        let dir = origin.parent().map(Path::to_path_buf).unwrap_or_default();
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        ScenarioText { text: text.to_string(), origin: origin.to_path_buf(), dir }
    }

    /// A built-in scenario's text.
    pub fn builtin(name: &str, text: &str) -> ScenarioText {
        ScenarioText {
            text: text.to_string(),
            origin: PathBuf::from(format!("{name} (built-in scenario)")),
            dir: PathBuf::from("."),
        }
    }

    /// The kind the text declares.
    pub fn kind(&self) -> Result<Kind> {
        split_kind(&self.text, &self.origin).map(|(kind, _)| kind)
    }

    /// Parses the text as a scenario of kind `expected` into `T`.
    pub fn parse_as<T: serde::de::DeserializeOwned>(&self, expected: Kind) -> Result<T> {
        let (kind, body) = split_kind(&self.text, &self.origin)?;
        if kind != expected {
            return Err(ScenarioError::invalid(
                &self.origin,
                format!("this is a scenario of kind `{}`; one of kind `{}` is needed here", kind.key(), expected.key()),
            ));
        }
        let invalid = |e: &dyn std::fmt::Display| {
            let mut message = e.to_string();
            if message.contains("wanted exactly 1 element, more than 1 element") {
                message += "(a table that is one of several kinds, as [mesh.box] or [mesh.file], or a selection's \
                            box or ball, is given more than one of them here: keep one)";
            }
            ScenarioError::invalid(&self.origin, message)
        };
        let mut table: toml::Table = toml::from_str(&body).map_err(|e| invalid(&e))?;
        anchor_landmark_files(&mut table, &self.dir);
        // The table, its landmark files now starting at the scenario's directory; an error is
        // said as the text gives it, with its line (a table has none).
        toml::Value::Table(table).try_into().map_err(|e| match toml::from_str::<T>(&body) {
            Err(with_line) => invalid(&with_line),
            Ok(_) => invalid(&e),
        })
    }
}

/// Makes the relative `file` of every `near` selection (landmarks, [`mesh::Near`]) start at
/// `dir`, the scenario's directory.
fn anchor_landmark_files(table: &mut toml::Table, dir: &Path) {
    for (key, value) in table.iter_mut() {
        if key == "near" {
            if let Some(toml::Value::String(file)) = value.as_table_mut().and_then(|t| t.get_mut("file")) {
                if Path::new(file.as_str()).is_relative() {
                    *file = dir.join(file.as_str()).to_string_lossy().into_owned();
                }
            }
        }
        anchor_in_value(value, dir);
    }
}

fn anchor_in_value(value: &mut toml::Value, dir: &Path) {
    match value {
        toml::Value::Table(t) => anchor_landmark_files(t, dir),
        toml::Value::Array(items) => items.iter_mut().for_each(|v| anchor_in_value(v, dir)),
        _ => {}
    }
}

/// Any scenario file.
#[derive(Clone, Debug)]
pub enum Scenario {
    /// `kind = "static"`.
    Static(StaticScenario),
    /// `kind = "dataset"`.
    Dataset(DatasetScenario),
    /// `kind = "assimilation"`.
    Assimilation(Box<AssimilationScenario>),
    /// `kind = "registration_case"`.
    RegistrationCase(CaseScenario),
}

impl Scenario {
    /// Reads a scenario file (or a built-in scenario, see [`ScenarioText::read`]) of any kind.
    pub fn load(path: &Path) -> Result<(Scenario, PathBuf)> {
        let source = ScenarioText::read(path)?;
        let scenario = match source.kind()? {
            Kind::Static => Scenario::Static(StaticScenario::from_text(&source)?),
            Kind::Dataset => Scenario::Dataset(DatasetScenario::from_text(&source)?),
            Kind::Assimilation => Scenario::Assimilation(Box::new(AssimilationScenario::from_text(&source)?)),
            Kind::RegistrationCase => Scenario::RegistrationCase(CaseScenario::from_text(&source)?),
        };
        Ok((scenario, source.dir))
    }
}

/// The built-in scenarios: `(name, text)`, the files of this crate's `scenarios/` directory.
pub const BUILTIN: [(&str, &str); 20] = [
    ("beam", include_str!("../scenarios/beam.toml")),
    ("beam_bc1", include_str!("../scenarios/beam_bc1.toml")),
    ("beam_bc4", include_str!("../scenarios/beam_bc4.toml")),
    ("beam_bc8", include_str!("../scenarios/beam_bc8.toml")),
    ("beam_linear", include_str!("../scenarios/beam_linear.toml")),
    ("beam_sparse", include_str!("../scenarios/beam_sparse.toml")),
    ("beam_target", include_str!("../scenarios/beam_target.toml")),
    ("liver", include_str!("../scenarios/liver.toml")),
    ("liver_ar", include_str!("../scenarios/liver_ar.toml")),
    ("liver_ar_grid", include_str!("../scenarios/liver_ar_grid.toml")),
    ("liver_ar_t10", include_str!("../scenarios/liver_ar_t10.toml")),
    ("liver_corotational", include_str!("../scenarios/liver_corotational.toml")),
    ("liver_forces", include_str!("../scenarios/liver_forces.toml")),
    ("liver_forces_large", include_str!("../scenarios/liver_forces_large.toml")),
    ("liver_large", include_str!("../scenarios/liver_large.toml")),
    ("liver_tool", include_str!("../scenarios/liver_tool.toml")),
    ("register_case", include_str!("../scenarios/register_case.toml")),
    ("register_case_test", include_str!("../scenarios/register_case_test.toml")),
    ("roukf_springs", include_str!("../scenarios/roukf_springs.toml")),
    ("roukf_young", include_str!("../scenarios/roukf_young.toml")),
];

/// The text of the built-in scenario `name` (see [`BUILTIN`]).
pub fn builtin(name: &str) -> Option<&'static str> {
    BUILTIN.iter().find(|(n, _)| *n == name).map(|(_, text)| *text)
}

/// The built-in scenario `name` parsed with `from_text`; panics when there is none or it does
/// not parse (a defect of this crate, tested).
fn builtin_with<T>(name: &str, from_text: impl Fn(&ScenarioText) -> Result<T>) -> T {
    let text = builtin(name).unwrap_or_else(|| panic!("no built-in scenario {name}"));
    from_text(&ScenarioText::builtin(name, text)).unwrap_or_else(|e| panic!("{e}"))
}

/// Reads `path` (or the built-in scenario of that name) and parses it with `from_text`; returns
/// it with the directory its relative paths start from.
fn load_with<T>(path: &Path, from_text: impl Fn(&ScenarioText) -> Result<T>) -> Result<(T, PathBuf)> {
    let source = ScenarioText::read(path)?;
    Ok((from_text(&source)?, source.dir))
}

/// Splits off the top-level `kind` key: the kind and the text without it (its line left blank,
/// so that later errors still point at the right line).
fn split_kind(text: &str, origin: &Path) -> Result<(Kind, String)> {
    let table: toml::Table = toml::from_str(text).map_err(|e| ScenarioError::invalid(origin, e.to_string()))?;
    let names = Kind::ALL.map(|k| format!("\"{}\"", k.key())).join(", ");
    let kind = match table.get("kind") {
        Some(toml::Value::String(key)) => Kind::from_key(key).ok_or_else(|| {
            ScenarioError::invalid(origin, format!("unknown scenario kind \"{key}\" (expected one of {names})"))
        })?,
        Some(other) => {
            return Err(ScenarioError::invalid(origin, format!("`kind` must be a string, one of {names}; got {other}")))
        }
        None => {
            return Err(ScenarioError::invalid(
                origin,
                format!("no `kind` key: a scenario file starts with `kind = ...`, one of {names}"),
            ))
        }
    };
    let mut body = String::with_capacity(text.len());
    let mut top_level = true;
    for line in text.lines() {
        let trimmed = line.trim_start();
        top_level &= !trimmed.starts_with('[');
        let is_kind = top_level && trimmed.strip_prefix("kind").is_some_and(|rest| rest.trim_start().starts_with('='));
        if !is_kind {
            body.push_str(line);
        }
        body.push('\n');
    }
    Ok((kind, body))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kind_is_required_and_checked() {
        let origin = Path::new("x.toml");
        let missing = split_kind("name = \"a\"\n", origin).unwrap_err().to_string();
        assert!(missing.contains("no `kind` key") && missing.contains("x.toml"), "{missing}");
        let unknown = split_kind("kind = \"dynamic\"\n", origin).unwrap_err().to_string();
        assert!(unknown.contains("\"dynamic\"") && unknown.contains("\"registration_case\""), "{unknown}");
        let (kind, body) = split_kind("# c\nkind = \"dataset\"\nname = \"a\"\n[t]\nkind = \"fem\"\n", origin).unwrap();
        assert_eq!(kind, Kind::Dataset);
        assert_eq!(body, "# c\n\nname = \"a\"\n[t]\nkind = \"fem\"\n", "only the top-level key is removed");
    }

    #[test]
    fn wrong_kind_and_unknown_keys_are_named_with_their_line() {
        let source = ScenarioText {
            text: "kind = \"dataset\"\nname = \"a\"\n".into(),
            origin: "a.toml".into(),
            dir: ".".into(),
        };
        let err = StaticScenario::from_text(&source).unwrap_err().to_string();
        assert!(err.contains("a scenario of kind `dataset`; one of kind `static` is needed"), "{err}");
        let source = ScenarioText {
            text: "kind = \"static\"\nname = \"x\"\n[mesh.box]\nmin = [0.0, 0.0, 0.0]\nmax = [1.0, 1.0, 1.0]\n\
                   cells = [1, 1, 1]\nelement = \"hex\"\n[material]\nlaw = \"svk\"\nyoung = 1.0\npoisson = 0.3\n\
                   stiffnes = 3\n"
                .into(),
            origin: "b.toml".into(),
            dir: ".".into(),
        };
        let err = StaticScenario::from_text(&source).unwrap_err().to_string();
        assert!(err.contains("stiffnes") && err.contains("line 12"), "{err}");
    }

    /// A scenario with a landmark file is parsed from its text first: an unknown key is named with its line.
    #[test]
    fn an_unknown_key_beside_a_landmark_file_is_named_with_its_line() {
        let text = "kind = \"static\"\nname = \"x\"\n[mesh.box]\nmin = [0.0, 0.0, 0.0]\nmax = [1.0, 1.0, 1.0]\n\
                    cells = [1, 1, 1]\nelement = \"hex\"\n[material]\nlaw = \"svk\"\nyoung = 1.0\npoisson = 0.3\n\
                    [[fixed]]\nselect = { near = { file = \"marks.csv\", distance = 0.1 } }\n";
        let source = |extra: &str| ScenarioText::new(&format!("{text}{extra}"), Path::new("case/c.toml"));
        let scenario = StaticScenario::from_text(&source("")).unwrap();
        let mesh::NodeSelection::Near(near) = &scenario.fixed[0].select else { panic!("not a near selection") };
        assert_eq!(near.file.as_deref(), Some(Path::new("case/marks.csv")), "the file starts at the scenario's");
        let err = StaticScenario::from_text(&source("stiffnes = 3\n")).unwrap_err().to_string();
        assert!(err.contains("stiffnes") && err.contains("line 14"), "{err}");
    }

    /// Every file of `scenarios/` is built in, declares its kind and parses as that kind.
    #[test]
    fn builtin_scenarios_parse_as_their_kind() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios");
        let mut files: Vec<String> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().path().file_stem().unwrap().to_string_lossy().into_owned())
            .collect();
        files.sort();
        let names: Vec<String> = BUILTIN.iter().map(|(n, _)| n.to_string()).collect();
        assert_eq!(files, names, "scenarios/ and BUILTIN list the same files");
        let mut kinds = Vec::new();
        for (name, _) in BUILTIN {
            let (scenario, _) = Scenario::load(Path::new(name)).unwrap_or_else(|e| panic!("{name}: {e}"));
            kinds.push(match scenario {
                Scenario::Static(_) => Kind::Static,
                Scenario::Dataset(_) => Kind::Dataset,
                Scenario::Assimilation(_) => Kind::Assimilation,
                Scenario::RegistrationCase(_) => Kind::RegistrationCase,
            });
        }
        for kind in Kind::ALL {
            assert!(kinds.contains(&kind), "no built-in {kind:?} scenario");
        }
        let (beam, dir) = StaticScenario::load(Path::new("beam")).unwrap();
        let problem = beam.build_problem(&dir).unwrap();
        assert_eq!(problem.mesh.cells.len(), 500);
        assert!(!problem.dirichlet.is_empty() && problem.f_ext.iter().any(|&f| f != 0.0));
    }

    #[test]
    fn a_missing_file_that_is_no_builtin_is_an_error_naming_the_built_in_ones() {
        let err = ScenarioText::read(Path::new("no_such_scenario")).unwrap_err().to_string();
        assert!(err.starts_with("cannot read scenario no_such_scenario: "), "{err}");
        let builtins = "nor is it a built-in scenario's name (beam, beam_bc1, ";
        assert!(err.contains(builtins) && err.ends_with(", roukf_springs, roukf_young)"), "{err}");
        let err = ScenarioText::read(Path::new("dir/beam.toml")).unwrap_err();
        assert!(
            matches!(err, ScenarioError::MissingFile { .. }),
            "a path with a directory never falls back to a built-in"
        );
        // A file name is a file's: one that is not there is not replaced by the built-in `liver`.
        let err = ScenarioText::read(Path::new("liver.toml")).unwrap_err().to_string();
        assert!(err.ends_with("(the built-in scenario of that name is `liver`, without .toml)"), "{err}");
        let err = ScenarioText::read(Path::new("dir/other.toml")).unwrap_err();
        assert!(matches!(err, ScenarioError::Io { .. }), "{err}");
    }
}
