//! What the pipelines (`frictl demo`, `frictl robot run`) need from this binary: its own path, the
//! in-process distillation and the command line of `frictl import csv`.

use anyhow::Context;
use frictionless_pipeline::{Distilled, Host, ImportCsv, ImportLabel};

use super::import_log::{CommonArgs, CsvArgs, LabelArg};
use super::stage;

/// This `frictl` as the pipelines' host.
pub struct Frictl;

impl Host for Frictl {
    fn frictl(&self) -> anyhow::Result<std::path::PathBuf> {
        std::env::current_exe().context("cannot find the running executable")
    }

    fn distill(&self, args: &frictl_cli::distill::Args) -> anyhow::Result<Distilled> {
        let o = super::distill::distill_file(args)?;
        Ok(Distilled {
            gate: o.gate,
            written: o.written,
            model: o.model,
            teacher_us: o.teacher_us,
            student_us: o.student_us,
        })
    }

    fn import_csv_argv(&self, i: &ImportCsv<'_>) -> anyhow::Result<Vec<String>> {
        let mut common: CommonArgs = stage::defaults()?;
        common.out = i.out.to_path_buf();
        common.label = Some(match i.label {
            ImportLabel::TorqueSensor => LabelArg::TorqueSensor,
            ImportLabel::Given => LabelArg::Given,
        });
        common.gear_ratio = vec![i.gear_ratio_signed.to_string()];
        common.kt = vec![i.kt_nm_per_a.to_string()];
        stage::argv(
            &["import", "csv"],
            &CsvArgs {
                files: i.files.to_vec(),
                joint: vec![i.joint.to_owned()],
                columns: i.columns.to_vec(),
                common,
                ..stage::defaults()?
            },
        )
    }
}
