//! `augsim serve --assimilate`: the ROUKF on the stream. An OpenIGTLink client sends the
//! scenario's synthetic measurements as POINT `features`, one message per step, in millimetres,
//! and reads each STRING `estimate`; a message with the wrong number of features gets an error
//! estimate, is taken as a step with no feature seen, and the stream goes on at the right loads;
//! the server stops cleanly on SIGINT.

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Duration;

use app::assimilation::Experiment;
use live::client::{Answer, Client};
use scenario::AssimilationScenario;

const SCENARIO: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../app/tests/data/beam_assimilation.toml");

fn estimate(client: &mut Client) -> serde_json::Value {
    loop {
        match client.receive().unwrap() {
            Some(Answer::Estimate(e)) => return e,
            Some(_) => {}
            None => panic!("the server closed the connection"),
        }
    }
}

#[test]
fn the_roukf_steps_with_features_sent_over_openigtlink() {
    let dir = tempfile::tempdir().unwrap();
    let targets = dir.path().join("targets.csv");
    std::fs::write(&targets, "x,y,z\n1000,500,500\n").unwrap();
    let mut server = Command::new(env!("CARGO_BIN_EXE_augsim"))
        .args(["serve", "--fem", "beam", "--targets", targets.to_str().unwrap(), "--port", "0", "--units", "mm"])
        .args(["--assimilate", SCENARIO])
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(server.stdout.take().unwrap()).lines();
    let port: u16 = loop {
        let line = lines.next().expect("the server printed its address").unwrap();
        if let Some(rest) = line.strip_prefix("listening  ") {
            break rest.split([':', ' ']).nth(1).unwrap().parse().unwrap();
        }
    };
    let (sc, sc_dir) = AssimilationScenario::load(Path::new(SCENARIO)).unwrap();
    let experiment = Experiment::prepare(sc, &sc_dir, None).unwrap();
    let truth = experiment.scenario_values()[0];
    let mut client = Client::connect(("127.0.0.1", port), Duration::from_secs(120)).unwrap();
    let mut last = serde_json::Value::Null;
    for (k, (z, available)) in experiment.observations().enumerate() {
        let points: Vec<[f32; 3]> = z
            .as_slice()
            .chunks(3)
            .zip(available.chunks(3))
            .map(|(p, a)| std::array::from_fn(|d| if a[d] { (p[d] * 1e3) as f32 } else { f32::NAN }))
            .collect();
        if k == 1 {
            // Too few features: an error for that step, taken as one with no feature seen; the
            // filter goes on, each later step at its own load.
            client.send_points("features", &points[1..]).unwrap();
            let e = estimate(&mut client);
            assert!(e["step"] == k + 1 && e["error"].as_str().unwrap().contains("features sent"), "{e}");
            continue;
        }
        client.send_points("features", &points).unwrap();
        last = estimate(&mut client);
        assert!(last["step"] == k + 1 && last["iteration"] == k + 1, "{last}");
    }
    assert_eq!((&last["names"][0], &last["gated"]), (&serde_json::json!("young"), &serde_json::json!(0)), "{last}");
    let (mean, std) = (last["mean"][0].as_f64().unwrap(), last["std"][0].as_f64().unwrap());
    assert!((mean - truth).abs() < 0.01 * truth && std < 0.01 * truth, "E = {mean} ± {std} Pa, truth {truth} Pa");
    drop(client);
    // SIGINT: a clean stop.
    Command::new("kill").args(["-INT", &server.id().to_string()]).status().unwrap();
    assert!(server.wait().unwrap().success());
}
