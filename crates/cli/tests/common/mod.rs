//! Helpers shared by the CLI's test binaries: running the binary, scratch paths, reading a
//! directory tree back. Each binary uses a subset.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// Runs `irmirror` with `args` and `--quiet`.
pub fn irmirror(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_irmirror"))
        .args(args)
        .arg("--quiet")
        .output()
        .expect("binary runs")
}

/// A fresh scratch path for this process.
pub fn tmp(name: &str) -> PathBuf {
    let p = std::env::temp_dir().join(format!("irmirror-cli-{}-{name}", std::process::id()));
    std::fs::remove_dir_all(&p).ok();
    p
}

/// The run's stderr as text.
pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Every file under `dir` (relative path, bytes), sorted.
pub fn read_tree(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).unwrap() {
        let e = e.unwrap();
        if e.metadata().unwrap().is_dir() {
            out.extend(
                read_tree(&e.path())
                    .into_iter()
                    .map(|(n, b)| (format!("{}/{n}", e.file_name().to_string_lossy()), b)),
            );
        } else {
            out.push((
                e.file_name().to_string_lossy().into_owned(),
                std::fs::read(e.path()).unwrap(),
            ));
        }
    }
    out.sort();
    out
}
