//! `frictl ctl` — runtime control of a running `frictiond` over `<prefix>/control`.
//!
//! What it **is**: one request per `get`, one per `KEY=VALUE` of a `set` (in order; the first
//! refusal stops with the daemon's message, which names the rule), printed as text or JSON.
//!
//! What it is **not**: no checks of its own — the daemon checks every value by its config's rules.

use std::time::Duration;

use anyhow::{Context, bail};
use frictionless_shm_types::control::{
    CONTROL_KEYS, CONTROL_OK, ControlClient, ControlRequest, ControlResponse, access_refusal,
    ood_mode_name,
};
use frictionless_shm_types::{Ipc, IpcConfig, ShmError};

pub use frictl_cli::ctl::*;

fn call(
    c: &ControlClient,
    req: &ControlRequest,
    timeout: Duration,
) -> anyhow::Result<ControlResponse> {
    let r = c.call(req, timeout)?;
    if r.status != CONTROL_OK {
        bail!("frictiond refused: {}", r.message());
    }
    Ok(r)
}

fn kind_name(code: u32) -> &'static str {
    u8::try_from(code)
        .ok()
        .and_then(frictionless::model::ModelKind::from_code)
        .map_or("?", |k| k.name())
}

fn as_json(joint: &str, r: &ControlResponse) -> serde_json::Value {
    let since: serde_json::Map<String, serde_json::Value> = CONTROL_KEYS
        .iter()
        .zip(r.set_since_ns)
        .map(|(k, t)| {
            let v = if t == 0 {
                serde_json::Value::Null
            } else {
                t.into()
            };
            ((*k).to_owned(), v)
        })
        .collect();
    serde_json::json!({
        "joint": joint,
        "index": r.joint_index,
        "generation": r.generation,
        "generation_since_ns": r.generation_since_ns,
        "kfc": r.kfc,
        "max_output_friction": if r.max_output_friction_nm.is_finite() {
            serde_json::Value::from(r.max_output_friction_nm)
        } else {
            serde_json::Value::from("inf")
        },
        "max_curr": r.max_curr_a,
        "compensation": if r.compensation != 0 { "on" } else { "off" },
        "ood": ood_mode_name(r.ood_mode),
        "model": r.model(),
        "model_kind": kind_name(r.model_kind),
        "model_since_tick": r.model_since_tick,
        "models": r.models().collect::<Vec<_>>(),
        "set_since_ns": since,
    })
}

fn as_text(joint: &str, r: &ControlResponse) -> String {
    let since = |k: usize| {
        if r.set_since_ns[k] == 0 {
            "file".to_owned()
        } else {
            format!("set at {} ns", r.set_since_ns[k])
        }
    };
    let model_since = if r.set_since_ns[5] == 0 {
        "file".to_owned()
    } else {
        format!(
            "set at {} ns, active after tick {}",
            r.set_since_ns[5], r.model_since_tick
        )
    };
    format!(
        "joint {joint} (index {}), generation {} (loaded at {} ns)\n\
         model               {} ({}, {}; models: {})\n\
         kfc                 {} ({})\n\
         max_output_friction {} Nm ({})\n\
         max_curr            {} A ({})\n\
         compensation        {} ({})\n\
         ood                 {} ({})\n",
        r.joint_index,
        r.generation,
        r.generation_since_ns,
        r.model(),
        kind_name(r.model_kind),
        model_since,
        r.models().collect::<Vec<_>>().join(", "),
        r.kfc,
        since(0),
        r.max_output_friction_nm,
        since(1),
        r.max_curr_a,
        since(2),
        if r.compensation != 0 { "on" } else { "off" },
        since(3),
        ood_mode_name(r.ood_mode),
        since(4),
    )
}

/// Runs `frictl ctl`.
pub fn run(a: Args) -> anyhow::Result<()> {
    let cfg = IpcConfig::new(a.root_path.as_deref(), &a.prefix);
    let refused = |e: ShmError| match access_refusal(&cfg) {
        Some(why) => anyhow::anyhow!("{why} ({e})"),
        None => anyhow::Error::new(e),
    };
    let ipc = Ipc::open(&cfg, "frictl-ctl")
        .map_err(refused)
        .context("opening iceoryx2")?;
    let client = ipc.control_client().map_err(refused)?;
    let timeout = Duration::from_millis(a.timeout_ms);
    match a.command {
        CtlCommand::Get { joint, json } => {
            let req = ControlRequest::get(&joint)
                .with_context(|| format!("joint name `{joint}` is longer than 64 bytes"))?;
            let r = call(&client, &req, timeout)?;
            if json {
                println!("{}", as_json(&joint, &r));
            } else {
                print!("{}", as_text(&joint, &r));
            }
        }
        CtlCommand::Set { joint, pairs } => {
            for pair in &pairs {
                let Some((key, value)) = pair.split_once('=') else {
                    bail!(
                        "`{pair}`: expected KEY=VALUE (keys: {})",
                        CONTROL_KEYS.join(", ")
                    );
                };
                let req =
                    ControlRequest::set(&joint, key.trim(), value.trim()).with_context(|| {
                        format!("`{pair}`: joint, key and value must each fit 64 bytes")
                    })?;
                let r = call(&client, &req, timeout)?;
                println!("{}", r.message());
            }
        }
    }
    Ok(())
}
