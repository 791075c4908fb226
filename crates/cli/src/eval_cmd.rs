//! `irmirror eval`: the Table-1 benchmark (`irmirror_eval::bench`) with a progress bar.

use anyhow::Result;
use irmirror_eval::bench::{BenchProgress, Selection, Set};
use std::path::Path;

/// The runner's progress as an `indicatif` bar.
struct Bar(indicatif::ProgressBar);

impl BenchProgress for Bar {
    fn start(&self, runs: u64) {
        self.0.set_length(runs);
    }
    fn capture(&self, id: &str) {
        self.0.set_message(id.to_string());
    }
    fn runs_done(&self, n: u64) {
        self.0.inc(n);
    }
}

/// Runs the benchmark (the `selection` of it) into `out` and prints its table.
pub fn run(set: Set, out: &Path, selection: &Selection, progress: bool) -> Result<()> {
    let bar = if progress {
        indicatif::ProgressBar::new(0)
    } else {
        indicatif::ProgressBar::hidden()
    };
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "eval {bar:40} {pos}/{len} runs {msg} {elapsed}/{eta}",
        )
        .expect("valid template"),
    );
    let (_, table, dir) = irmirror_eval::bench::run(set, out, selection, &Bar(bar.clone()))?;
    bar.finish_and_clear();
    println!("{table}");
    println!("wrote {} (open report.html)", dir.display());
    Ok(())
}
