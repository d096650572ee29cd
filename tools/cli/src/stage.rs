//! Typed stage calls: a stage's clap `Args`, built as a Rust value, turned into its command line.
//!
//! The pipelines (`frictl demo`, `frictl demo --sensor torque`, `frictl robot run`) run the other
//! subcommands as child processes, each with its own log and its own signal handling. They build each
//! stage's `Args` struct (so a renamed or retyped field fails to compile) and [`argv`] writes the
//! command line from clap's own description of that struct (so a renamed flag is renamed here too):
//! each field's value is read through serde and emitted under the argument clap declares for it.
//! [`roundtrip`] parses the result back with clap; every stage has a test that it gives the same value.
//!
//! Rules, from clap's metadata: a flag (`SetTrue`) is written when true; an `Option` that is `None`
//! and a value equal to clap's default are left out (so a default never collides with a
//! `conflicts_with`); a list is written once per element (grouped by the argument's number of values per occurrence
//! if that is more than one, else joined by its delimiter if it has one); positional arguments come last, after `--`.
//! Value enums serialise to clap's own value name ([`as_value_enum`]).

use anyhow::Context;
use clap::{ArgAction, FromArgMatches};
use serde::Serialize;
use serde_json::Value;

/// A stage's command line: `subcommand` (e.g. `["import", "csv"]`) then the arguments of `args`.
pub fn argv<A: clap::Args + FromArgMatches + Serialize>(
    subcommand: &[&str],
    args: &A,
) -> anyhow::Result<Vec<String>> {
    let out = words(subcommand, args, &[])?;
    // Refused here, before a child starts, if clap would refuse it there.
    roundtrip::<A>(subcommand.len(), &out)?;
    Ok(out)
}

/// The first part of a stage's command line that its user completes: [`argv`] without the
/// arguments named in `left_out` (clap ids, i.e. field names; the caller appends them, e.g. a
/// search's `--out` chosen per worker). Not checked by clap: it is not complete.
pub fn partial_argv<A: clap::Args + Serialize>(
    subcommand: &[&str],
    args: &A,
    left_out: &[&str],
) -> anyhow::Result<Vec<String>> {
    let cmd = A::augment_args(clap::Command::new("stage"));
    if let Some(id) = left_out
        .iter()
        .find(|id| !cmd.get_arguments().any(|a| a.get_id().as_str() == **id))
    {
        anyhow::bail!("stage argument `{id}` to leave out does not exist");
    }
    words(subcommand, args, left_out)
}

/// The words of [`argv`], leaving out the arguments `left_out`.
fn words<A: clap::Args + Serialize>(
    subcommand: &[&str],
    args: &A,
    left_out: &[&str],
) -> anyhow::Result<Vec<String>> {
    let cmd = A::augment_args(clap::Command::new("stage"));
    let fields = match serde_json::to_value(args).context("stage arguments do not serialise")? {
        Value::Object(m) => m,
        other => anyhow::bail!("stage arguments serialise to {other}, not to a map of fields"),
    };
    let mut out: Vec<String> = subcommand.iter().map(|s| (*s).to_owned()).collect();
    let mut positionals: Vec<(usize, Vec<String>)> = Vec::new();
    for arg in cmd.get_arguments() {
        let id = arg.get_id().as_str();
        if left_out.contains(&id) {
            continue;
        }
        let Some(value) = fields.get(id) else {
            anyhow::bail!(
                "stage argument `{id}`: no field of that name in the serialised arguments"
            )
        };
        let values = scalars(id, value)?;
        let defaults: Vec<String> = arg
            .get_default_values()
            .iter()
            .map(|v| v.to_string_lossy().into_owned())
            .collect();
        if values.iter().any(|v| v.contains(UNSET)) {
            anyhow::bail!("stage argument `{id}` is required and was left unset");
        }
        if arg.is_positional() {
            let index = arg.get_index().unwrap_or(usize::MAX);
            positionals.push((index, values));
            continue;
        }
        let long = match arg.get_long() {
            Some(l) => format!("--{l}"),
            None => match arg.get_short() {
                Some(c) => format!("-{c}"),
                None => anyhow::bail!("stage argument `{id}` has neither a long nor a short name"),
            },
        };
        match arg.get_action() {
            ArgAction::SetTrue => {
                if value
                    .as_bool()
                    .with_context(|| format!("stage flag `{id}` is not a bool"))?
                {
                    out.push(long);
                }
            }
            ArgAction::SetFalse => {
                if !value
                    .as_bool()
                    .with_context(|| format!("stage flag `{id}` is not a bool"))?
                {
                    out.push(long);
                }
            }
            ArgAction::Count => {
                let n = value
                    .as_u64()
                    .with_context(|| format!("stage counter `{id}`"))?;
                out.extend(std::iter::repeat_n(long, n as usize));
            }
            ArgAction::Set | ArgAction::Append => {
                if values.is_empty() || values == defaults || defaults_match(&values, &defaults) {
                    continue;
                }
                let per_occurrence = arg.get_num_args().map_or(1, |r| r.max_values());
                if per_occurrence > 1 {
                    // e.g. `--kalman-q Q0 Q1 Q2`: one occurrence per group of values.
                    for group in values.chunks(per_occurrence.min(values.len())) {
                        out.push(long.clone());
                        out.extend(group.iter().cloned());
                    }
                } else if let Some(d) = arg.get_value_delimiter() {
                    out.push(format!("{long}={}", values.join(&d.to_string())));
                } else {
                    for v in values {
                        out.push(format!("{long}={v}"));
                    }
                }
            }
            other => anyhow::bail!("stage argument `{id}`: action {other:?} is not supported"),
        }
    }
    positionals.sort_by_key(|(i, _)| *i);
    let rest: Vec<String> = positionals.into_iter().flat_map(|(_, v)| v).collect();
    if !rest.is_empty() {
        out.push("--".into());
        out.extend(rest);
    }
    Ok(out)
}

/// Parses `argv` (as written by [`argv`], without its subcommand words) back into `A`: the check
/// each stage's test makes, and what a pipeline can call to refuse an argument list clap would refuse.
pub fn roundtrip<A: clap::Args + FromArgMatches + Serialize>(
    subcommand_len: usize,
    argv: &[String],
) -> anyhow::Result<A> {
    let cmd = A::augment_args(clap::Command::new("stage").no_binary_name(true));
    let matches = cmd
        .try_get_matches_from(&argv[subcommand_len.min(argv.len())..])
        .with_context(|| format!("clap refuses the stage's command line {argv:?}"))?;
    A::from_arg_matches(&matches)
        .context("the stage's command line does not give its arguments back")
}

/// What [`defaults`] puts in a required argument: a NUL, which no command line can carry.
const UNSET: &str = "\u{0}";

/// A stage's arguments with clap's defaults, and required arguments unset: the base a pipeline
/// overrides field by field (`train::Args { dataset, out, ..stage::defaults()? }`). A required
/// argument left unset is refused by [`argv`], naming it (a required value enum takes its first
/// value, a required number 0, instead).
pub fn defaults<A: clap::Args + FromArgMatches>() -> anyhow::Result<A> {
    let cmd = A::augment_args(clap::Command::new("stage").no_binary_name(true));
    // A value enum cannot hold the marker: a required one is given its first value (the caller
    // sets it), on the command line of this parse.
    let mut words: Vec<String> = Vec::new();
    for a in cmd.get_arguments().filter(|a| a.is_required_set()) {
        if let Some(first) = a.get_possible_values().first() {
            match a.get_long() {
                Some(long) if !a.is_positional() => {
                    words.push(format!("--{long}={}", first.get_name()))
                }
                _ => words.push(first.get_name().to_owned()),
            }
        }
    }
    // A required number cannot hold the marker either: it is 0 in the base (the caller sets it).
    // Whether an argument's parser takes the marker: parse it alone.
    let takes_marker = |a: &clap::Arg| {
        let word = match a.get_long() {
            Some(long) if !a.is_positional() => format!("--{long}={UNSET}"),
            _ => UNSET.to_owned(),
        };
        clap::Command::new("probe")
            .no_binary_name(true)
            .arg(a.clone().required(false))
            .try_get_matches_from([word])
            .is_ok()
    };
    let cmd = cmd.mut_args(|a| {
        if a.is_required_set() && a.get_possible_values().is_empty() {
            let marker = if takes_marker(&a) { UNSET } else { "0" };
            a.required(false).default_value(marker)
        } else {
            a
        }
    });
    // `required_unless_present` and the like: a base is not a complete command line.
    let cmd = cmd.ignore_errors(true);
    let matches = cmd
        .try_get_matches_from(words)
        .context("clap refuses the stage's defaults")?;
    A::from_arg_matches(&matches).context("the stage's defaults do not give its arguments")
}

/// Numbers compare as numbers (clap's default `"0.5"` and serde's `0.5` are one value).
fn defaults_match(values: &[String], defaults: &[String]) -> bool {
    values.len() == defaults.len()
        && values
            .iter()
            .zip(defaults)
            .all(|(v, d)| match (v.parse::<f64>(), d.parse::<f64>()) {
                (Ok(a), Ok(b)) => a == b,
                _ => v == d,
            })
}

/// A field's value as command-line words: a list gives one word per element, `None` gives none.
fn scalars(id: &str, value: &Value) -> anyhow::Result<Vec<String>> {
    let one = |v: &Value| -> anyhow::Result<String> {
        Ok(match v {
            Value::String(s) => s.clone(),
            Value::Number(n) => n.to_string(),
            Value::Bool(b) => b.to_string(),
            other => anyhow::bail!("stage argument `{id}`: {other} is not a command-line value"),
        })
    };
    match value {
        Value::Null => Ok(vec![]),
        Value::Array(items) => items.iter().map(one).collect(),
        v => Ok(vec![one(v)?]),
    }
}

/// `#[serde(serialize_with = "…")]` for a clap value enum: clap's own value name, so [`argv`]
/// writes the word clap parses (whatever the type's own serde form, if any).
pub fn as_value_enum<T: clap::ValueEnum, S: serde::Serializer>(
    v: &T,
    s: S,
) -> Result<S::Ok, S::Error> {
    match v.to_possible_value() {
        Some(p) => s.serialize_str(p.get_name()),
        None => Err(serde::ser::Error::custom("a skipped value-enum variant")),
    }
}

/// `#[serde(serialize_with = "…")]` for a library's named enum (`frictionless::named_enum!`): its
/// name, the word [`named`] parses.
pub fn as_name<T: std::fmt::Display, S: serde::Serializer>(v: &T, s: S) -> Result<S::Ok, S::Error> {
    s.collect_str(v)
}

/// The value parser of a library's named enum (`frictionless::named_enum!`): its names are the
/// possible values (listed by `--help`, completed by the shells), parsed with its `FromStr`.
pub fn named<T>(names: &'static [&'static str]) -> impl clap::builder::TypedValueParser<Value = T>
where
    T: std::str::FromStr<Err = String> + Clone + Send + Sync + 'static,
{
    use clap::builder::TypedValueParser;
    clap::builder::PossibleValuesParser::new(names.iter().copied()).try_map(|s| s.parse::<T>())
}

/// A value enum's name on the command line (for messages and file names).
pub fn value_name<T: clap::ValueEnum>(v: &T) -> String {
    v.to_possible_value()
        .map(|p| p.get_name().to_owned())
        .unwrap_or_default()
}

/// [`as_value_enum`] for an optional value.
pub fn as_opt_value_enum<T: clap::ValueEnum, S: serde::Serializer>(
    v: &Option<T>,
    s: S,
) -> Result<S::Ok, S::Error> {
    match v {
        Some(v) => as_value_enum(v, s),
        None => s.serialize_none(),
    }
}

/// [`as_value_enum`] for an optional list.
pub fn as_opt_value_enums<T: clap::ValueEnum, S: serde::Serializer>(
    v: &Option<Vec<T>>,
    s: S,
) -> Result<S::Ok, S::Error> {
    use serde::ser::SerializeSeq;
    match v {
        None => s.serialize_none(),
        Some(items) => {
            let mut seq = s.serialize_seq(Some(items.len()))?;
            for item in items {
                seq.serialize_element(&value_name(item))?;
            }
            seq.end()
        }
    }
}

/// `#[serde(serialize_with = "…")]` for a value clap parses with `FromStr`: its `Display` form.
pub fn as_display<T: std::fmt::Display, S: serde::Serializer>(
    v: &T,
    s: S,
) -> Result<S::Ok, S::Error> {
    s.collect_str(v)
}

#[cfg(test)]
mod tests {
    use std::path::PathBuf;

    use frictionless::features::FeatureSet;
    use frictionless::model::ModelKind;

    use super::*;
    use crate::{acquire, eval, export, fit, preprocess, train};

    /// `args` → [`argv`] → clap → the same serialised value; returns the words.
    fn assert_roundtrip<A: clap::Args + FromArgMatches + Serialize>(
        sub: &[&str],
        args: &A,
    ) -> Vec<String> {
        let words = argv(sub, args).expect("argv");
        assert_eq!(&words[..sub.len()], sub);
        let back: A = roundtrip(sub.len(), &words).expect("roundtrip");
        assert_eq!(
            serde_json::to_value(args).unwrap(),
            serde_json::to_value(&back).unwrap(),
            "{words:?}"
        );
        words
    }

    #[test]
    fn every_pipeline_stage_gives_its_arguments_back() {
        let p = |s: &str| PathBuf::from(s);
        let words = assert_roundtrip(
            &["acquire"],
            &acquire::Args {
                preset: "knee".into(),
                out: p("data dir"),
                seed: 7,
                name: Some("slow".into()),
                sensor: acquire::Sensor::Torque,
                log_period_ms: 2.0,
                jitter_ms: 0.2,
                sets: vec!["protocol.tracking.train.amplitudes_rad=[0.2, -0.4]".into()],
                ..defaults().unwrap()
            },
        );
        // Defaults are left out; what was set is there under clap's names.
        assert!(words.contains(&"--sensor=torque".to_owned()), "{words:?}");
        assert!(
            !words.iter().any(|w| w.starts_with("--prefix")),
            "{words:?}"
        );

        assert_roundtrip(
            &["fit"],
            &fit::Args {
                model: fit::FitModel(ModelKind::Lugre),
                dataset: p("ds.csv"),
                test_runs: vec!["mid".into()],
                sigma0: Some(1.5e4),
                json: Some(p("m.json")),
                ..defaults().unwrap()
            },
        );

        let mut t = train::Args {
            datasets: vec![p("a.csv"), p("b.csv")],
            scv: p("scv.json"),
            out: p("pinn.fwt"),
            features: train::Features(FeatureSet::JointPosJointVel),
            hidden: vec![16, 8, 4],
            lr: 3e-4,
            test_chunks: Some(vec!["1".into(), "b.csv:2".into()]),
            dtype: train::Dtype::Bf16,
            quiet: true,
            ..defaults().unwrap()
        };
        t.held_out.test_runs = vec!["mid".into()];
        t.delta_theta_offset = "-1.25".parse().unwrap();
        assert_roundtrip(&["train"], &t);

        assert_roundtrip(
            &["eval"],
            &eval::Args {
                datasets: vec![p("ds.csv")],
                band_edges: vec![0.0, 0.5],
                lugre: Some(p("lugre.json")),
                pinns: vec![p("a.fwt"), p("b.fwt")],
                warmup: eval::Warmup::ZeroPad,
                ..defaults().unwrap()
            },
        );
    }

    #[test]
    fn the_demo_s_other_stages_give_their_arguments_back() {
        let mut pre = preprocess::Args {
            log: "raw.csv".into(),
            out: "ds.csv".into(),
            subtract_reflected_inertia: Some("sidecar".into()),
            link: preprocess::LinkSource::Urdf,
            fixed_joints: vec!["l_hip_pitch=-0.2".into()],
            ..defaults().unwrap()
        };
        pre.pipeline.causal = true;
        pre.pipeline.kalman_q = vec![1e-6, 2e-3, 0.5];
        assert_roundtrip(&["preprocess"], &pre);
        assert_roundtrip(
            &["export"],
            &export::Args {
                format: export::Format::Onnx,
                input: "m.fwt".into(),
                output: "m.onnx".into(),
                norm: export::Norm::DiagonalGemm,
            },
        );
    }

    #[test]
    fn the_experiment_stage_gives_its_arguments_back() {
        use crate::experiment::{self, ControllerInertia, Kind, ModelSel, RobotSel};
        let words = assert_roundtrip(
            &["experiment"],
            &experiment::Args {
                kind: Kind::MinKp,
                robot: RobotSel::Leg,
                model: Some(vec![ModelSel::None, ModelSel::Oracle]),
                leg_config: vec!["SCV=a.toml".into(), "PINN=b.toml".into()],
                rest_sine_rad: Some(0.05),
                pinn_delta_theta_offset: "knee=-1.5,ankle_roll=enable".into(),
                controller_inertia: ControllerInertia::LinkRotor,
                no_plots: true,
                sets: vec!["knee:plant.t0_min_c=31.5".into()],
                ..defaults().unwrap()
            },
        );
        assert_eq!(
            words[words.len() - 2..],
            ["--", "min-kp"],
            "the kind is positional, last"
        );
    }

    #[test]
    fn the_search_stage_gives_its_arguments_back() {
        use crate::search;
        assert_roundtrip(
            &["search"],
            &search::Args {
                datasets: vec!["a.csv".into()],
                scv: "scv.json".into(),
                out: "search".into(),
                trials: 6,
                threads: Some(4),
                hidden_range: Some(vec![16, 64]),
                lr_range: Some(vec![1e-4, 3e-3]),
                temperature: true,
                max_epochs_without_improvement: Some(5),
                ..defaults().unwrap()
            },
        );
    }

    #[test]
    fn a_required_argument_left_empty_is_refused_naming_it() {
        let e = argv(&["train"], &defaults::<train::Args>().unwrap()).unwrap_err();
        assert!(format!("{e:#}").contains("`datasets`"), "{e:#}");
    }
}
