//! Fuzz target: the YARP robot logger `.mat` v7.3 importer of `frictionless-logs`
//! (`mat_log::read`, what `frictl import mat` calls; cargo feature `mat`, system HDF5).
//!
//! Structure-aware: the input does not become the file's bytes (a byte-level mutation of an HDF5
//! file tests the C library's own parser, not this importer) but the *plan* of a well-formed HDF5
//! file that the importer must read or refuse: which of the logger's channels exist, as what kind of
//! object (struct group, a dataset where a group belongs, a group without `data`), the
//! `elements_names` cellstr (object references to UTF-16 char arrays, empty `MATLAB_empty` strings,
//! references to groups, a numeric dataset instead of references, up to 2¹⁶ names), the `data` and
//! `timestamps` shapes (right, transposed, one column short or too many, rank 1–4) and element types,
//! datasets that declare 2³⁶ rows in chunks never written (a hang or an unbounded allocation if the
//! importer trusts the declared size), and every value (NaN, ±∞, time going back or standing still,
//! gaps in the desired-current stream), plus the MAT header, the root struct's name, the joint asked
//! for, `--negate` roles and the chunk gap. The file is written with `hdf5-metno` to a scratch file;
//! `mat_log::read` must then return a run that passes the shared invariants
//! (`common/log_import.rs`) or an error — never panic, never hang, never allocate without bound.
#![no_main]

use std::path::Path;

use frictionless_logs::Role;
use frictionless_logs::mat_log::{self, MatSpec};
use hdf5_metno as h5;
use libfuzzer_sys::arbitrary::{Result as AResult, Unstructured};
use libfuzzer_sys::fuzz_target;

#[path = "common/log_import.rs"]
mod log_import;
use log_import::{check, scratch_dir};

/// The channels the importer reads, under `/robot_logger_device`.
const CHANNELS: [&str; 6] = [
    "joints_state/positions",
    "motors_state/positions",
    "motors_state/velocities",
    "motors_state/currents",
    "motors_state/temperatures",
    "current_control/motors/desired/current",
];
/// Joint names the plans draw from (the empty string is written as MATLAB's empty char array).
const NAMES: [&str; 6] = ["l_knee", "r_knee", "torso_roll", "", "l_knee ", "ünï"];
/// Rows a dataset declares when it is "huge" (its chunks are never written).
const HUGE_ROWS: usize = 1 << 36;

fn header(u: &mut Unstructured) -> AResult<[u8; 128]> {
    let mut h = [b' '; 128];
    if u.ratio(7u8, 8)? {
        let text = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Mon Jan  1 00:00:00 2024 HDF5 schema 1.00 .";
        h[..text.len()].copy_from_slice(text);
        h[124..].copy_from_slice(b"\x00\x02IM");
    } else {
        u.fill_buffer(&mut h)?;
    }
    Ok(h)
}

/// A value: mostly ordinary, sometimes non-finite or extreme.
fn value(u: &mut Unstructured) -> AResult<f64> {
    Ok(match u.int_in_range(0u8..=9)? {
        0 => f64::NAN,
        1 => f64::INFINITY * if u.arbitrary()? { 1.0 } else { -1.0 },
        2 => u.arbitrary()?,
        _ => f64::from(u.int_in_range(-1000i16..=1000)?) * 1e-2,
    })
}

/// `n` timestamps: a 1.7e9 s epoch start with increments around 2 ms, sometimes back, still, gapped
/// or arbitrary.
fn stamps(u: &mut Unstructured, n: usize) -> AResult<Vec<f64>> {
    let mut t = if u.ratio(1u8, 8)? {
        u.arbitrary()?
    } else {
        1.7e9
    };
    let mut out = Vec::with_capacity(n);
    for _ in 0..n {
        out.push(t);
        t += match u.int_in_range(0u8..=15)? {
            0 => -0.002,
            1 => 0.0,
            2 => 2.5,
            3 => value(u)?,
            _ => 0.002,
        };
    }
    Ok(out)
}

/// Writes `name` as a MATLAB char array (UTF-16 code units, or the empty marker) in `/#refs#` and
/// returns a reference to it; sometimes a reference to a group or to a numeric dataset instead.
fn char_ref(
    u: &mut Unstructured,
    file: &h5::File,
    refs: &h5::Group,
    k: &mut usize,
    name: &str,
) -> h5::Result<h5::ObjectReference1> {
    *k += 1;
    let leaf = format!("s{k}");
    match u.int_in_range(0u8..=15).unwrap_or(0) {
        0 => {
            refs.create_group(&leaf)?;
        }
        1 => {
            let d = refs.new_dataset::<f64>().shape(2).create(leaf.as_str())?;
            d.write_raw(&[1.0, 2.0])?;
        }
        _ if name.is_empty() => {
            let d = refs.new_dataset::<u64>().shape(2).create(leaf.as_str())?;
            d.write_raw(&[1u64, 0])?;
            d.new_attr::<u32>()
                .create("MATLAB_empty")?
                .write_scalar(&1u32)?;
        }
        _ => {
            let units: Vec<u16> = name.encode_utf16().collect();
            let d = refs
                .new_dataset::<u16>()
                .shape((units.len(), 1))
                .create(leaf.as_str())?;
            d.write_raw(&units)?;
        }
    }
    file.reference(&format!("/#refs#/{leaf}"))
}

/// One channel struct group (`data`, `elements_names`, `timestamps`) at `path` under `root`.
fn channel(
    u: &mut Unstructured,
    file: &h5::File,
    root: &h5::Group,
    refs: &h5::Group,
    k: &mut usize,
    path: &str,
) -> h5::Result<()> {
    let kind = u.int_in_range(0u8..=15).unwrap_or(0);
    if kind == 0 {
        return Ok(()); // absent
    }
    let (parent, leaf) = path.rsplit_once('/').unwrap_or(("", path));
    let parent = if parent.is_empty() {
        root.clone()
    } else {
        match root.group(parent) {
            Ok(g) => g,
            Err(_) => root.create_group(parent)?,
        }
    };
    if kind == 1 {
        // A dataset where the struct group belongs.
        let d = parent.new_dataset::<f64>().shape(1).create(leaf)?;
        return d.write_raw(&[0.0]);
    }
    let g = parent.create_group(leaf)?;
    if kind == 2 {
        return Ok(()); // an empty struct: no fields
    }
    // elements_names
    let n_names = match u.int_in_range(0u8..=31).unwrap_or(0) {
        0 => 0,
        1 => 1 << 16,
        x => usize::from(x % 5),
    };
    let names: Vec<&str> = (0..n_names)
        .map(|_| NAMES[usize::from(u.int_in_range(0u8..=5).unwrap_or(0))])
        .collect();
    match u.int_in_range(0u8..=15).unwrap_or(0) {
        0 => {} // no elements_names
        1 => {
            let d = g
                .new_dataset::<f64>()
                .shape((1, n_names))
                .create("elements_names")?;
            d.write_raw(&vec![0.0; n_names])?;
        }
        2 => {
            // Declared, never written: references full of zeros.
            g.new_dataset::<h5::ObjectReference1>()
                .chunk((1, 1))
                .shape((1, HUGE_ROWS))
                .create("elements_names")?;
        }
        _ => {
            let r = if n_names > 8 {
                // Many names share one target (writing 2¹⁶ datasets per input is too slow).
                if refs.dataset("many").is_err() {
                    let d = refs.new_dataset::<u16>().shape((2, 1)).create("many")?;
                    d.write_raw(&[u16::from(b'x'), u16::from(b'y')])?;
                }
                vec![file.reference::<h5::ObjectReference1>("/#refs#/many")?; n_names]
            } else {
                let mut r = Vec::with_capacity(n_names);
                for name in &names {
                    r.push(char_ref(u, file, refs, k, name)?);
                }
                r
            };
            let d = g
                .new_dataset::<h5::ObjectReference1>()
                .shape((1, n_names))
                .create("elements_names")?;
            d.write_raw(&r)?;
        }
    }
    // data: (N, 1, n) of f64 normally.
    let huge = u.ratio(1u8, 16).unwrap_or(false);
    let rows = if huge {
        HUGE_ROWS
    } else {
        usize::from(u.int_in_range(0u8..=48).unwrap_or(0))
    };
    let cols = match u.int_in_range(0u8..=7).unwrap_or(0) {
        0 => n_names + 1,
        1 => n_names.saturating_sub(1),
        _ => n_names,
    };
    if kind != 3 {
        let shape: Vec<usize> = match u.int_in_range(0u8..=11).unwrap_or(0) {
            0 => vec![rows, cols],
            1 => vec![rows, 1, cols, 1],
            2 => vec![cols, 1, rows],
            3 => vec![rows],
            _ => vec![rows, 1, cols],
        };
        let count: usize = shape.iter().product();
        if huge || count > 1 << 16 {
            let chunk: Vec<usize> = shape.iter().map(|&d| d.clamp(1, 1024)).collect();
            if u.ratio(1u8, 2).unwrap_or(false) {
                g.new_dataset::<f64>()
                    .chunk(chunk)
                    .shape(shape)
                    .create("data")?;
            } else {
                g.new_dataset::<u8>()
                    .chunk(chunk)
                    .shape(shape)
                    .create("data")?;
            }
        } else if u.ratio(1u8, 8).unwrap_or(false) {
            let d = g.new_dataset::<i32>().shape(shape).create("data")?;
            d.write_raw(&vec![7i32; count])?;
        } else {
            let v: Vec<f64> = (0..count).map(|_| value(u).unwrap_or(0.0)).collect();
            let d = g.new_dataset::<f64>().shape(shape).create("data")?;
            d.write_raw(&v)?;
        }
    }
    // timestamps: (N, 1) normally.
    let t_rows = match u.int_in_range(0u8..=15).unwrap_or(0) {
        0 => rows + 1,
        1 => rows.saturating_sub(1),
        _ => rows,
    };
    let shape: Vec<usize> = match u.int_in_range(0u8..=15).unwrap_or(0) {
        0 => return Ok(()), // no timestamps
        1 => vec![1, t_rows],
        2 => vec![t_rows],
        _ => vec![t_rows, 1],
    };
    if t_rows > 1 << 16 {
        // Declared, never written.
        let chunk: Vec<usize> = shape.iter().map(|&d| d.clamp(1, 1024)).collect();
        g.new_dataset::<f64>()
            .chunk(chunk)
            .shape(shape)
            .create("timestamps")?;
    } else {
        let v = stamps(u, t_rows).unwrap_or_else(|_| vec![1.7e9; t_rows]);
        let d = g.new_dataset::<f64>().shape(shape).create("timestamps")?;
        d.write_raw(&v)?;
    }
    Ok(())
}

/// Writes the file the plan describes; `None` when HDF5 refuses to write it (not the importer's
/// concern).
fn write(u: &mut Unstructured, path: &Path) -> Option<()> {
    let head = header(u).ok()?;
    let root_name = if u.ratio(15u8, 16).ok()? {
        "robot_logger_device"
    } else {
        "robot_logger"
    };
    {
        let file = h5::File::with_options()
            .with_fcpl(|p| p.userblock(512))
            .create(path)
            .ok()?;
        let refs = file.create_group("#refs#").ok()?;
        let root = file.create_group(root_name).ok()?;
        let mut k = 0usize;
        for c in CHANNELS {
            channel(u, &file, &root, &refs, &mut k, c).ok()?;
        }
    }
    let mut f = std::fs::OpenOptions::new().write(true).open(path).ok()?;
    use std::io::Write;
    f.write_all(&head).ok()?;
    Some(())
}

fuzz_target!(|data: &[u8]| {
    let mut u = Unstructured::new(data);
    let path = scratch_dir().join("log.mat");
    let _ = std::fs::remove_file(&path);
    if write(&mut u, &path).is_none() {
        return;
    }
    let joint = match u.int_in_range(0u8..=7).unwrap_or(0) {
        0 => None,
        x => Some(NAMES[usize::from(x % 6)].to_string()),
    };
    let mut negate = Vec::new();
    for role in [
        Role::S,
        Role::Theta,
        Role::Omega,
        Role::Current,
        Role::Temperature,
        Role::TauF,
    ] {
        if u.ratio(1u8, 6).unwrap_or(false) {
            negate.push(role);
        }
    }
    let desired_gap_s = match u.int_in_range(0u8..=7).unwrap_or(0) {
        0 => value(&mut u).unwrap_or(1.0),
        _ => 1.0,
    };
    let spec = MatSpec {
        joints: joint.into_iter().collect(),
        all_joints: false,
        state_joints: None,
        negate,
        desired_gap_s,
    };
    let mut no_progress = |_: u64, _: u64| {};
    if let Ok(run) = mat_log::read(&path, &spec, &mut no_progress) {
        check(&run);
    }
});
