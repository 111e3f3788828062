//! Names the build for the experiments' results (`AUGSIM_BUILD`): the commit the sources were built
//! from, with a digest of their uncommitted changes where the work tree differs from it; "unknown"
//! outside a git checkout. A result made by another build is not taken for this one's.

use std::hash::{Hash, Hasher};
use std::path::Path;
use std::process::Command;

/// What the results depend on, relative to the workspace's root.
const SOURCES: [&str; 4] = ["crates", "models", "Cargo.toml", "Cargo.lock"];

/// The build's name where it cannot be told (no git, or not a checkout).
const UNKNOWN: &str = "unknown";

fn main() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    // `.git/logs/HEAD` grows at every commit, checkout and reset; the sources at every edit.
    for path in [".git/HEAD", ".git/logs/HEAD"].iter().chain(&SOURCES) {
        println!("cargo:rerun-if-changed={}", root.join(path).display());
    }
    let git = |args: &[&str]| -> Option<String> {
        let out = Command::new("git").arg("-C").arg(&root).args(args).output().ok()?;
        out.status.success().then(|| String::from_utf8_lossy(&out.stdout).into_owned())
    };
    let mut diff_args = vec!["diff", "HEAD", "--"];
    diff_args.extend(SOURCES);
    let build = match (git(&["rev-parse", "--short=12", "HEAD"]), git(&diff_args)) {
        (Some(commit), Some(diff)) if diff.is_empty() => commit.trim().to_string(),
        (Some(commit), Some(diff)) => {
            let mut hasher = std::collections::hash_map::DefaultHasher::new();
            diff.hash(&mut hasher);
            format!("{}+changes-{:08x}", commit.trim(), hasher.finish() as u32)
        }
        _ => UNKNOWN.to_string(),
    };
    println!("cargo:rustc-env=AUGSIM_BUILD={build}");
}
