//! The README's "A short tour": every shell command of its code block, as written, in a fresh
//! directory where the repository's `examples/` and `models/` are reachable, with the built
//! `augsim` first on the PATH. Each must succeed; `augsim serve`, a server that runs until
//! stopped, is started, answers the example cloud and is stopped with SIGINT.
#![cfg(unix)]

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use live::client::Client;

const REPOSITORY: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../..");

/// The commands of the shell block under the README's "A short tour", without their comments.
fn tour_commands() -> Vec<String> {
    let readme = std::fs::read_to_string(Path::new(REPOSITORY).join("README.md")).unwrap();
    let mut lines = readme.lines().skip_while(|l| *l != "## A short tour").skip(1);
    assert!(lines.by_ref().any(|l| l == "```sh"), "README.md: no ```sh block under \"## A short tour\"");
    let commands: Vec<String> = lines
        .take_while(|l| *l != "```")
        .map(|l| {
            // A comment starts at a `#` after a blank; the commands quote nothing.
            let end = l.char_indices().find(|&(i, c)| c == '#' && (i == 0 || l[..i].ends_with(' '))).map(|(i, _)| i);
            l[..end.unwrap_or(l.len())].trim().to_string()
        })
        .filter(|l| !l.is_empty())
        .collect();
    assert!(commands.len() >= 5, "README.md's tour has {} commands: {commands:?}", commands.len());
    commands
}

/// `sh -c command` in `dir`, the built augsim first on the PATH.
fn shell(command: &str, dir: &Path) -> Command {
    let bin = PathBuf::from(env!("CARGO_BIN_EXE_augsim"));
    let path = std::env::join_paths(
        std::iter::once(bin.parent().unwrap().to_path_buf())
            .chain(std::env::split_paths(&std::env::var_os("PATH").unwrap_or_default())),
    )
    .unwrap();
    let mut c = Command::new("sh");
    c.args(["-c", command]).current_dir(dir).env("PATH", path);
    c
}

/// Rows of a CSV file of numbers after its header.
fn csv_rows(path: &Path) -> Vec<[f64; 3]> {
    let text = std::fs::read_to_string(path).unwrap();
    text.lines().skip(1).map(|l| std::array::from_fn(|d| l.split(',').nth(d).unwrap().parse().unwrap())).collect()
}

/// Runs `augsim serve ...` (the tour's command, on an unused port: the default one may be taken on
/// the machine running the tests), sends it the example cloud in mm and checks that the targets
/// come back; then stops it with SIGINT.
fn serve(command: &str, dir: &Path) {
    let mut server = shell(&format!("exec {command} --port 0"), dir).stdout(Stdio::piped()).spawn().unwrap();
    let mut lines = BufReader::new(server.stdout.take().unwrap()).lines();
    let mut printed = String::new();
    let port: u16 = loop {
        let line = lines.next().unwrap_or_else(|| panic!("`{command}` stopped before listening:\n{printed}")).unwrap();
        printed += &format!("{line}\n");
        if let Some(rest) = line.strip_prefix("listening  ") {
            break rest.split([':', ' ']).nth(1).unwrap().parse().unwrap();
        }
    };
    let targets = command.split_whitespace().skip_while(|w| *w != "--targets").nth(1).expect("--targets");
    let expected = csv_rows(&dir.join(targets)).len();
    assert!(command.contains("--units mm"), "`{command}`: the example cloud is sent in mm");
    let cloud: Vec<[f32; 3]> = csv_rows(&dir.join("examples/cloud.csv")).iter().map(|p| p.map(|x| x as f32)).collect();
    let mut client = Client::connect(("127.0.0.1", port), Duration::from_secs(120)).unwrap();
    client.send_cloud(cloud).unwrap();
    let frame = client.until_status().unwrap();
    assert!(frame.status.get("error").is_none(), "`{command}`: {}", frame.status);
    assert_eq!(frame.targets.map(|t| t.len()), Some(expected), "`{command}`: {}", frame.status);
    drop(client);
    Command::new("kill").args(["-INT", &server.id().to_string()]).status().unwrap();
    let status = server.wait().unwrap();
    printed.extend(lines.map_while(Result::ok).map(|l| l + "\n"));
    assert!(status.success() && printed.contains("stopped"), "`{command}`:\n{printed}");
}

#[test]
fn every_command_of_the_readme_tour_runs_as_written() {
    let dir = tempfile::tempdir().unwrap();
    for name in ["examples", "models"] {
        std::os::unix::fs::symlink(Path::new(REPOSITORY).join(name), dir.path().join(name)).unwrap();
    }
    for command in tour_commands() {
        assert!(command.starts_with("augsim "), "a tour command that is not augsim's: `{command}`");
        // Every points file of the tour is in mm, and says so in its header.
        for file in command.split_whitespace().filter(|w| w.starts_with("examples/") && w.ends_with(".csv")) {
            let text = std::fs::read_to_string(Path::new(REPOSITORY).join(file)).unwrap();
            assert!(text.starts_with("x_mm,y_mm,z_mm\n"), "{file}: its header does not name mm");
        }
        let began = Instant::now();
        if command.starts_with("augsim serve ") {
            serve(&command, dir.path());
        } else {
            let out = shell(&command, dir.path()).output().unwrap();
            assert!(
                out.status.success(),
                "`{command}` failed:\n{}{}",
                String::from_utf8_lossy(&out.stdout),
                String::from_utf8_lossy(&out.stderr)
            );
        }
        println!("{:6.1} s  {command}", began.elapsed().as_secs_f64());
    }
    // Every registered cloud's results for 3D Slicer include the transform of its CT, whichever
    // method registered it (a learned model's prediction may fold a cell).
    let mut runs = vec![dir.path().join("out/register")];
    let mut registered = 0;
    while let Some(folder) = runs.pop() {
        for entry in std::fs::read_dir(&folder).unwrap().map(Result::unwrap).filter(|e| e.path().is_dir()) {
            runs.push(entry.path());
        }
        if folder.join("targets.mrk.json").exists() {
            registered += 1;
            assert!(folder.join("displacement.nrrd").exists(), "{}: no displacement.nrrd", folder.display());
        }
    }
    assert!(registered >= 4, "{registered} registered clouds in out/register");
}
