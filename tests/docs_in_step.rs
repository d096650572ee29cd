//! The documents that describe the workspace's layout held against the workspace itself, so they
//! cannot go stale: the README's house map names every crate's directory, ARCHITECTURE's dependency
//! block lists every crate with exactly its workspace dependencies (from `cargo metadata`), its crate
//! table names every crate with its directory, and every repository path CONTRIBUTING's recipes name
//! exists.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::Command;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn read(rel: &str) -> String {
    std::fs::read_to_string(root().join(rel)).unwrap_or_else(|e| panic!("{rel}: {e}"))
}

/// One workspace package: its name, its directory relative to the root (`.` for the root crate) and
/// the names of the workspace packages it depends on (normal dependencies only).
struct Package {
    name: String,
    dir: String,
    deps: BTreeSet<String>,
}

fn workspace() -> Vec<Package> {
    let out = Command::new(env!("CARGO"))
        .args([
            "metadata",
            "--format-version",
            "1",
            "--no-deps",
            "--offline",
        ])
        .current_dir(root())
        .output()
        .expect("cargo metadata runs");
    assert!(
        out.status.success(),
        "cargo metadata failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let meta: serde_json::Value = serde_json::from_slice(&out.stdout).expect("cargo metadata JSON");
    let pkgs = meta["packages"].as_array().expect("packages");
    let names: BTreeSet<String> = pkgs
        .iter()
        .map(|p| p["name"].as_str().unwrap().to_owned())
        .collect();
    let root = root();
    pkgs.iter()
        .map(|p| {
            let manifest = Path::new(p["manifest_path"].as_str().unwrap());
            let dir = manifest.parent().unwrap().strip_prefix(&root).unwrap();
            let dir = if dir.as_os_str().is_empty() {
                ".".to_owned()
            } else {
                dir.to_string_lossy().into_owned()
            };
            let deps = p["dependencies"]
                .as_array()
                .unwrap()
                .iter()
                .filter(|d| d["kind"].is_null())
                .map(|d| d["name"].as_str().unwrap().to_owned())
                .filter(|n| names.contains(n))
                .collect();
            Package {
                name: p["name"].as_str().unwrap().to_owned(),
                dir,
                deps,
            }
        })
        .collect()
}

/// The short name ARCHITECTURE's block uses: the package name without `frictionless-`.
fn short(name: &str) -> &str {
    name.strip_prefix("frictionless-").unwrap_or(name)
}

/// The fenced block that follows the first line starting with `header`.
fn block_after<'a>(doc: &'a str, header: &str) -> Vec<&'a str> {
    let mut lines = doc.lines().skip_while(|l| !l.starts_with(header));
    let first = lines
        .next()
        .unwrap_or_else(|| panic!("no line starting with {header:?}"));
    let mut out = vec![first];
    out.extend(lines.take_while(|l| !l.starts_with("```")));
    out
}

#[test]
fn the_readme_house_map_names_every_crate_directory() {
    let readme = read("README.md");
    let house = readme
        .split("## The house")
        .nth(1)
        .and_then(|s| s.split("```").nth(1))
        .expect("README.md has a '## The house' section with a fenced map");
    let mut missing = Vec::new();
    for p in workspace().iter().filter(|p| p.dir != ".") {
        // Each path component appears as `name/` (a nested one under its parent's entry).
        for part in p.dir.split('/') {
            if !house.contains(&format!("{part}/")) {
                missing.push(format!("{} ({})", p.dir, p.name));
            }
        }
    }
    assert!(
        missing.is_empty(),
        "README.md's house map does not name: {missing:?}"
    );
}

#[test]
fn architecture_lists_every_crate_with_its_workspace_dependencies() {
    let doc = read("ARCHITECTURE.md");
    let block = block_after(&doc, "crate ");
    // Rows: `name   dep, dep, …` (or `—`); a line starting with spaces continues the row above.
    let mut rows: BTreeMap<String, String> = BTreeMap::new();
    let mut last = None;
    for line in &block[1..] {
        if line.starts_with(' ') {
            let name: &String = last.as_ref().expect("a continuation line follows a row");
            rows.get_mut(name).unwrap().push_str(line);
        } else if let Some((name, deps)) = line.split_once(' ') {
            rows.insert(name.to_owned(), deps.to_owned());
            last = Some(name.to_owned());
        }
    }
    let ws = workspace();
    let mut wrong = Vec::new();
    for p in &ws {
        let want: BTreeSet<&str> = p.deps.iter().map(|d| short(d)).collect();
        let want_text = if want.is_empty() {
            "—".to_owned()
        } else {
            want.iter().copied().collect::<Vec<_>>().join(", ")
        };
        match rows.remove(&p.name) {
            None => wrong.push(format!("{}: no row (want: {want_text})", p.name)),
            Some(text) => {
                let got: BTreeSet<&str> = text
                    .split(',')
                    .map(str::trim)
                    .filter(|s| !s.is_empty() && *s != "—")
                    .collect();
                if got != want {
                    wrong.push(format!("{}: lists {got:?}, depends on {want_text}", p.name));
                }
            }
        }
    }
    for name in rows.keys() {
        wrong.push(format!("{name}: a row for no workspace crate"));
    }
    assert!(
        wrong.is_empty(),
        "ARCHITECTURE.md's dependency block is out of step with cargo metadata:\n{}",
        wrong.join("\n")
    );

    let mut untabled = Vec::new();
    for p in &ws {
        let dir = if p.dir == "." {
            "src/".to_owned()
        } else {
            format!("{}/", p.dir)
        };
        if !doc.contains(&format!("| `{}` | `{dir}` |", p.name)) {
            untabled.push(format!("{} (`{dir}`)", p.name));
        }
    }
    assert!(
        untabled.is_empty(),
        "ARCHITECTURE.md's crate table has no row for: {untabled:?}"
    );
}

#[test]
fn every_path_contributing_names_exists() {
    let doc = read("CONTRIBUTING.md");
    let roots = [
        "src/",
        "shm_types/",
        "drives/",
        "daemon/",
        "tools/",
        "capi/",
        "python/",
        "config/",
        "tests/",
        "benches/",
        "docs/",
        "fuzz/",
        "examples/",
        ".ci/",
    ];
    let mut checked = 0;
    let mut missing = Vec::new();
    for (n, line) in doc.lines().enumerate() {
        for (i, span) in line.split('`').enumerate() {
            // Odd pieces are inside backticks; keep what looks like one repository path.
            if i % 2 == 0 || span.contains(char::is_whitespace) || span.contains(['*', '<', '{']) {
                continue;
            }
            if !roots.iter().any(|r| span.starts_with(r)) {
                continue;
            }
            // `path:line` or `path::item` name a place inside a file.
            let path = span.split(':').next().unwrap();
            checked += 1;
            if !root().join(path).exists() {
                missing.push(format!("CONTRIBUTING.md:{}: {path}", n + 1));
            }
        }
    }
    assert!(
        checked > 10,
        "only {checked} paths found: is the parser right?"
    );
    assert!(
        missing.is_empty(),
        "paths that do not exist:\n{}",
        missing.join("\n")
    );
}
