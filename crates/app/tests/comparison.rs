//! A comparison case run end to end: its lines in order, its progress over the methods, its files.

use std::path::Path;
use std::sync::Mutex;

use augsim_app::comparison::{run_comparison, LearnedModels};
use augsim_app::printout::case_lines;
use scenario::registration::MethodKind;
use scenario::CaseScenario;

/// Records what a run reports.
#[derive(Default)]
struct Recorder {
    lines: Mutex<Vec<String>>,
    advances: Mutex<Vec<(u64, u64, String)>>,
}

impl learn::Progress for Recorder {
    fn advance(&self, done: u64, total: u64, note: &str) {
        self.advances.lock().unwrap().push((done, total, note.to_string()));
    }

    fn line(&self, text: &str) {
        self.lines.lock().unwrap().push(text.to_string());
    }
}

#[test]
fn a_comparison_reports_its_case_then_each_method_and_writes_its_files() {
    let scenario = CaseScenario::load(Path::new("register_case_test")).unwrap();
    let dir = tempfile::tempdir().unwrap();
    // A network method given a model that is not there is an error naming it.
    let mut with_network = scenario.clone();
    let mut network = scenario.models.method[0].clone();
    (network.name, network.kind, network.material) = ("U-Net".into(), MethodKind::Network, None);
    with_network.models.method.push(network);
    let missing = dir.path().join("no_model");
    let learned = LearnedModels { model: Some(&missing), scenario: None };
    let e = match run_comparison(&with_network, learned, dir.path(), &Recorder::default()) {
        Ok(_) => panic!("a missing model must be an error"),
        Err(e) => format!("{e:#}"),
    };
    assert!(e.contains("no_model"), "{e}");

    let recorder = Recorder::default();
    let rows = run_comparison(&scenario, LearnedModels::default(), dir.path(), &recorder).unwrap();
    let fems = ["FEM co-rotational", "FEM SVK"];
    let names: Vec<&str> = rows.iter().map(|r| r.method.as_str()).collect();
    assert_eq!(names, fems, "the FEM methods, in the case's order");
    assert!(rows.iter().all(|r| r.result.is_ok()));

    let advances = recorder.advances.into_inner().unwrap();
    let expected: Vec<(u64, u64, String)> = vec![(0, 2, fems[0].into()), (1, 2, fems[1].into()), (2, 2, String::new())];
    assert_eq!(advances, expected, "one step per method, then done");

    let lines = recorder.lines.into_inner().unwrap();
    let case = case_lines(&scenario);
    assert_eq!(lines[..case.len()], case[..], "the case is described before it is simulated");
    let position = |start: &str| lines.iter().position(|l| l.starts_with(start));
    let header = position("method ").expect("the table's header");
    for name in fems {
        let row = lines[header..].iter().find(|l| l.starts_with(name)).expect("a table row per method");
        assert!(row.split_whitespace().any(|w| w.parse::<f64>().is_ok_and(f64::is_finite)), "{row}");
    }

    for file in ["case/cloud.csv", "case/truth.csv", "comparison.csv", "summary.json"] {
        assert!(dir.path().join(file).is_file(), "{file} written");
    }
    let csv = std::fs::read_to_string(dir.path().join("comparison.csv")).unwrap();
    assert_eq!(csv.lines().count(), 1 + 1 + fems.len(), "header, no deformation, one row per method:\n{csv}");
}
