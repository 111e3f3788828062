//! `examples/make.sh` remakes every shipped file of `examples/`: run on a copy of the folder with
//! the built `augsim`, it writes the same files, to the last digit they are rounded to (a value
//! computed a hair away from a rounding boundary may round the other way).
#![cfg(unix)]

use std::path::Path;
use std::process::Command;

const EXAMPLES: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../examples");

/// The places after the decimal point of a number as written (`12.345` → 3).
fn decimals(token: &str) -> i32 {
    token.split_once('.').map_or(0, |(_, fraction)| fraction.len() as i32)
}

/// Where `made` differs from `shipped` by more than one unit of the shipped value's last digit,
/// or in any word that is not a number.
fn difference(shipped: &str, made: &str) -> Option<String> {
    let tokens =
        |s: &str| s.split([',', ' ', '\n', '\t']).filter(|t| !t.is_empty()).map(str::to_owned).collect::<Vec<_>>();
    let (a, b) = (tokens(shipped), tokens(made));
    if a.len() != b.len() {
        return Some(format!("{} words shipped, {} made", a.len(), b.len()));
    }
    a.iter().zip(&b).enumerate().find_map(|(i, (x, y))| {
        let same = match (x.parse::<f64>(), y.parse::<f64>()) {
            (Ok(u), Ok(v)) => (u - v).abs() <= 1.001 * 10f64.powi(-decimals(x)),
            _ => x == y,
        };
        (!same).then(|| format!("word {i}: {x} shipped, {y} made"))
    })
}

#[test]
fn make_sh_remakes_the_shipped_examples() {
    let dir = tempfile::tempdir().unwrap();
    let copy = dir.path().join("examples");
    std::fs::create_dir(&copy).unwrap();
    std::fs::copy(Path::new(EXAMPLES).join("make.sh"), copy.join("make.sh")).unwrap();
    let output = Command::new("sh")
        .arg(copy.join("make.sh"))
        .env("AUGSIM", env!("CARGO_BIN_EXE_augsim"))
        .current_dir(dir.path())
        .output()
        .unwrap();
    assert!(output.status.success(), "make.sh failed: {}", String::from_utf8_lossy(&output.stderr));
    let mut compared = 0;
    for entry in std::fs::read_dir(EXAMPLES).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        if name == "make.sh" || name == "README.md" {
            continue;
        }
        let made =
            std::fs::read_to_string(copy.join(&name)).unwrap_or_else(|e| panic!("make.sh did not write {name}: {e}"));
        if let Some(difference) = difference(&std::fs::read_to_string(&path).unwrap(), &made) {
            panic!("examples/{name} is not what make.sh makes: {difference}");
        }
        compared += 1;
    }
    assert!(compared >= 9, "examples/ holds {compared} files");
}
