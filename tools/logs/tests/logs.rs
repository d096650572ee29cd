//! `frictionless-logs` tests: CSV logs written here (jittered time, deg and mA, NaN rows, a gap, bad
//! inputs), MCAP and `.mat` fixtures written by independent tools (Python `mcap` + `mcap-ros2-support`,
//! h5py) through `fixtures/make_fixtures.py` with the interpreter in `FRICTIONLESS_PY` (those tests are
//! `#[ignore]`d; `tests/run.sh` sets the variable and runs them with `--include-ignored`).

use std::path::{Path, PathBuf};
use std::time::Instant;

use frictionless_dataset::LabelSource;
use frictionless_ident::preprocess::{PreprocessConfig, SignalsLabel, preprocess_signals};
use frictionless_logs::csv_log::{self, CsvSpec};
use frictionless_logs::mcap_log::{self, McapSpec};
use frictionless_logs::{LogsError, Role};

fn tmp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("frictionless_logs_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

fn no_progress() -> impl FnMut(u64, u64) {
    |_, _| {}
}

fn spec(cols: &[&str], units: &[&str]) -> CsvSpec {
    let c: Vec<String> = cols.iter().map(|s| s.to_string()).collect();
    let u: Vec<String> = units.iter().map(|s| s.to_string()).collect();
    CsvSpec::parse(&c, &u, &[]).unwrap()
}

const DEG: f64 = std::f64::consts::PI / 180.0;

/// A jittered (2–3 ms) log in ms, deg and mA with `nan_rows` blank s fields and a 0.5 s gap at 2 s.
fn jittered_csv(path: &Path, nan_rows: &[usize]) -> usize {
    let mut text = String::from("t_ms,q_deg,i_mA,friction\n");
    let (mut t, mut k, mut rows) = (0.0f64, 0u64, 0usize);
    while t < 4.0 {
        if !(2.0..2.5).contains(&t) {
            let q = 30.0 * (std::f64::consts::PI * t).sin();
            let i = 500.0 + 100.0 * t;
            let f = 2.0 * (std::f64::consts::PI * t).cos();
            if nan_rows.contains(&rows) {
                text += &format!("{},,{i},{f}\n", t * 1e3);
            } else {
                text += &format!("{},{q},{i},{f}\n", t * 1e3);
            }
            rows += 1;
        }
        k += 1;
        t += 0.002 + 0.001 * ((k * 7919) % 11) as f64 / 10.0;
    }
    std::fs::write(path, text).unwrap();
    rows
}

#[test]
fn csv_in_deg_ms_ma_with_nan_rows_and_a_gap_lands_on_the_1khz_grid() {
    let path = tmp("jitter.csv");
    let rows = jittered_csv(&path, &[10, 11, 500]);
    let sp = spec(
        &["time=t_ms", "s=q_deg", "current=i_mA", "tau_f=friction"],
        &["time=ms", "s=deg", "current=mA"],
    );
    let run = csv_log::read(&path, &sp, &mut no_progress()).unwrap();
    assert_eq!(run.name, "jitter");
    assert_eq!(run.report.rows_read, rows as u64);
    assert_eq!(run.report.rows_used, rows as u64 - 3);
    assert_eq!(run.report.non_finite.get("s"), Some(&3));
    assert_eq!(run.report.time_not_increasing, 0);
    assert!(
        run.report
            .conversions
            .iter()
            .any(|c| c.starts_with("s: deg x")),
        "{:?}",
        run.report.conversions
    );
    let sig = &run.signals;
    let i = sig.current_a.as_ref().unwrap();
    for (t, i) in sig.time_s.iter().zip(i) {
        assert!((i - (0.5 + 0.1 * t)).abs() < 1e-12, "mA -> A at {t}");
    }
    let label = SignalsLabel {
        source: LabelSource::Given,
        gear_ratio_signed: None,
        kt_nm_per_a: None,
    };
    let mut cfg = PreprocessConfig::for_joint("j");
    cfg.gap_s = 0.1;
    let (ds, sum) = preprocess_signals(&[run.signals], &label, None, &cfg).unwrap();
    assert_eq!(sum.run_chunks, [vec![0, 1]], "the 0.5 s gap splits the run");
    assert!(ds.len() > 3400 && ds.len() < 3510, "{} samples", ds.len());
    for k in 0..ds.len() {
        let t = ds.time_s[k];
        let truth = 30.0 * DEG * (std::f64::consts::PI * t).sin();
        // Linear interpolation of a 0.52 rad sine over ≤ 3 ms (≤ 6 ms across the NaN rows).
        assert!(
            (ds.s_rad[k] - truth).abs() < 1e-4,
            "t = {t}: {} vs {truth}",
            ds.s_rad[k]
        );
        assert!((ds.i_meas_a[k] - (0.5 + 0.1 * t)).abs() < 1e-9);
        assert!(
            !(2.01..2.49).contains(&t),
            "no sample inside the gap (t = {t})"
        );
    }
    assert!(ds.theta_motor_rad.iter().all(|v| v.is_nan()));
    assert!(frictionless_logs::label_sign_warning(&ds).is_none());
    // The same label negated reads as the opposite convention.
    let mut neg = ds.clone();
    neg.tau_f_label_nm.iter_mut().for_each(|v| *v = -*v);
    // sign(sdot) and cos(pi t) agree, so the given label correlates positively; negated it does not.
    assert!(frictionless_logs::label_sign_warning(&neg).is_some());
}

#[test]
fn bad_csv_inputs_are_clear_errors_or_counted() {
    let path = tmp("bad.csv");
    std::fs::write(&path, "time,pos\n0,1\n0.001,2\n").unwrap();
    let e = csv_log::read(
        &path,
        &spec(&["time=time", "s=angle"], &[]),
        &mut no_progress(),
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("`angle`") && e.contains("time, pos"), "{e}");

    let e = CsvSpec::parse(&["time=t".into(), "speed=v".into()], &[], &[])
        .unwrap_err()
        .to_string();
    assert!(e.contains("speed") && e.contains("sdot"), "{e}");
    let e = CsvSpec::parse(&["time=t".into(), "s=q".into()], &["s=furlong".into()], &[])
        .unwrap_err()
        .to_string();
    assert!(e.contains("furlong") && e.contains("rad, deg"), "{e}");
    let e = CsvSpec::parse(&["time=t".into(), "s=q".into(), "s=q2".into()], &[], &[]).unwrap_err();
    assert!(
        matches!(e, LogsError::DuplicateRole { role: Role::S, .. }),
        "{e}"
    );
    let e = CsvSpec::parse(&["s=q".into()], &[], &[])
        .unwrap_err()
        .to_string();
    assert!(e.contains("time"), "{e}");

    // Text that is not a number: file, line, column and value.
    std::fs::write(&path, "time,pos\n0,1\n0.001,abc\n").unwrap();
    let e = csv_log::read(
        &path,
        &spec(&["time=time", "s=pos"], &[]),
        &mut no_progress(),
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("line 3") && e.contains("`pos`") && e.contains("abc"),
        "{e}"
    );

    // Empty file, header only.
    std::fs::write(&path, "").unwrap();
    let e = csv_log::read(&path, &spec(&["time=time"], &[]), &mut no_progress()).unwrap_err();
    assert!(e.to_string().contains("empty file"), "{e}");
    std::fs::write(&path, "time,pos\n").unwrap();
    let e = csv_log::read(
        &path,
        &spec(&["time=time", "s=pos"], &[]),
        &mut no_progress(),
    )
    .unwrap_err();
    assert!(e.to_string().contains("no data rows"), "{e}");

    // All rows non-finite: an error that counts them.
    std::fs::write(&path, "time,pos\n0,nan\n0.001,\n0.002,inf\n").unwrap();
    let e = csv_log::read(
        &path,
        &spec(&["time=time", "s=pos"], &[]),
        &mut no_progress(),
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("s: 3"), "{e}");
}

#[test]
fn time_going_back_is_counted_below_one_percent_and_an_error_above() {
    let path = tmp("back.csv");
    let mut text = String::from("t,q\n");
    for k in 0..1000 {
        let t = if k == 500 { 0.1 } else { k as f64 * 0.002 };
        text += &format!("{t},{}\n", k as f64 * 1e-3);
    }
    std::fs::write(&path, &text).unwrap();
    let sp = spec(&["time=t", "s=q"], &[]);
    let run = csv_log::read(&path, &sp, &mut no_progress()).unwrap();
    assert_eq!(run.report.time_not_increasing, 1);
    assert_eq!(run.report.rows_used, 999);
    assert!(run.signals.time_s.windows(2).all(|w| w[1] > w[0]));

    let mut text = String::from("t,q\n");
    for k in 0..100 {
        let t = if k % 20 == 7 { 0.0 } else { k as f64 * 0.002 };
        text += &format!("{t},0\n");
    }
    std::fs::write(&path, &text).unwrap();
    let e = csv_log::read(&path, &sp, &mut no_progress())
        .unwrap_err()
        .to_string();
    assert!(e.contains("time goes back") && e.contains("line 9"), "{e}");
}

#[test]
fn a_2gb_sparse_file_and_a_fifo_are_refused_quickly() {
    let path = tmp("sparse.csv");
    let f = std::fs::File::create(&path).unwrap();
    f.set_len(2 << 30).unwrap();
    drop(f);
    let started = Instant::now();
    let e = csv_log::read(&path, &spec(&["time=t"], &[]), &mut no_progress()).unwrap_err();
    assert!(e.to_string().contains("NUL"), "{e}");
    let mspec = McapSpec {
        topic: "/joint_states".into(),
        joints: vec!["j".into()],
        all_joints: false,
        state_joints: None,
        effort_role: None,
        negate: vec![],
    };
    let e = mcap_log::read(&path, &mspec, &mut no_progress()).unwrap_err();
    assert!(e.to_string().contains("not an MCAP file"), "{e}");
    #[cfg(feature = "mat")]
    {
        let ms = frictionless_logs::mat_log::MatSpec {
            joints: vec!["j".into()],
            all_joints: false,
            state_joints: None,
            negate: vec![],
            desired_gap_s: 1.0,
        };
        let e = frictionless_logs::mat_log::read(&path, &ms, &mut no_progress()).unwrap_err();
        assert!(e.to_string().contains("MATLAB 7.3"), "{e}");
    }
    assert!(
        started.elapsed().as_secs() < 20,
        "refused without scanning 2 GB"
    );
    std::fs::remove_file(&path).unwrap();

    let fifo = tmp("fifo.csv");
    let _ = std::fs::remove_file(&fifo);
    let ok = std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .map(|s| s.success())
        .unwrap_or(false);
    if ok {
        let e = csv_log::read(&fifo, &spec(&["time=t"], &[]), &mut no_progress()).unwrap_err();
        assert!(matches!(e, LogsError::NotRegular { .. }), "{e}");
    } else {
        eprintln!("mkfifo unavailable: FIFO case skipped");
    }
}

#[test]
fn cdr_decoder_rejects_truncated_and_oversized_messages() {
    assert!(mcap_log::decode_joint_state(&[0, 1]).is_err());
    // Header, stamp, empty frame id, then a name count of 2^31.
    let mut m = vec![0, 1, 0, 0];
    m.extend(5i32.to_le_bytes());
    m.extend(7u32.to_le_bytes());
    m.extend(1u32.to_le_bytes());
    m.extend([0, 0, 0, 0]);
    m.extend((1u32 << 31).to_le_bytes());
    let e = mcap_log::decode_joint_state(&m).unwrap_err();
    assert!(e.contains("exceeds"), "{e}");
    for cut in 0..m.len() {
        let _ = mcap_log::decode_joint_state(&m[..cut]);
    }
}

#[test]
fn imu_orientation_decodes_and_a_missing_one_is_none() {
    // Header, stamp, frame id "imu" (4 bytes with its NUL: the f64s start aligned), x y z w,
    // covariance[0], the rest.
    let imu = |cov0: f64| {
        let mut m = vec![0, 1, 0, 0];
        m.extend(5i32.to_le_bytes());
        m.extend(7u32.to_le_bytes());
        m.extend(4u32.to_le_bytes());
        m.extend(b"imu\0");
        for v in [0.1f64, -0.2, 0.3, 0.9, cov0] {
            m.extend(v.to_le_bytes());
        }
        m.extend([0u8; 8 * 8 + 8 * (3 + 9) * 2]);
        m
    };
    assert_eq!(
        mcap_log::decode_imu_orientation(&imu(0.01)).unwrap(),
        Some([0.1, -0.2, 0.3, 0.9])
    );
    // orientation_covariance[0] = -1: the message has no orientation.
    assert_eq!(mcap_log::decode_imu_orientation(&imu(-1.0)).unwrap(), None);
    let m = imu(0.0);
    for cut in 0..44 {
        assert!(
            mcap_log::decode_imu_orientation(&m[..cut]).is_err(),
            "{cut}"
        );
    }
}

#[test]
fn wrench_stamped_decodes_its_frame_force_and_torque() {
    // Header, stamp, frame id "l_f" (4 bytes with its NUL: the f64s start aligned), force, torque.
    let mut m = vec![0, 1, 0, 0];
    m.extend(5i32.to_le_bytes());
    m.extend(7u32.to_le_bytes());
    m.extend(4u32.to_le_bytes());
    m.extend(b"l_f\0");
    for v in [1.0f64, -2.0, 300.0, 4.0, -5.0, 6.0] {
        m.extend(v.to_le_bytes());
    }
    assert_eq!(
        mcap_log::decode_wrench(&m).unwrap(),
        ("l_f".to_string(), [1.0, -2.0, 300.0, 4.0, -5.0, 6.0])
    );
    for cut in 0..m.len() {
        assert!(mcap_log::decode_wrench(&m[..cut]).is_err(), "{cut}");
    }
}

/// The uncompressed bag of the `log_importers` fuzz seed (written by `fixtures/make_fixtures.py
/// mcap-seed`: 24 `JointState` messages on `/joint_states`, joints `a`, `wrist`, `b`), with the fuzz
/// target's spec and 0xFF separator stripped, copied to a temporary file.
fn seed_bag() -> PathBuf {
    seed_bag_named("mcap_plain")
}

/// [`seed_bag`] of the seed `name` (`mcap_plain`: uncompressed 1 KB chunks; `mcap_zstd`: one
/// zstd chunk).
fn seed_bag_named(name: &str) -> PathBuf {
    let seed = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fuzz/seeds/log_importers")
        .join(name);
    let data = std::fs::read(&seed).unwrap();
    let cut = data.iter().position(|&b| b == 0xFF).unwrap();
    let path = tmp(&format!("{name}.mcap"));
    std::fs::write(&path, &data[cut + 1..]).unwrap();
    path
}

#[test]
fn mcap_effort_read_as_time_or_a_position_is_refused_not_a_panic() {
    // `McapSpec`'s fields are public: an effort role of time, s or sdot would index past the row (a
    // panic; the `log_importers` fuzz target reads its effort as any role) and theta would take the
    // effort as the motor position. `read` refuses every role but a torque or a current.
    let path = seed_bag();
    let sp = |effort_role| McapSpec {
        topic: "/joint_states".into(),
        joints: vec!["wrist".into()],
        all_joints: false,
        state_joints: None,
        effort_role,
        negate: vec![],
    };
    for role in [
        Role::Time,
        Role::S,
        Role::Sdot,
        Role::Theta,
        Role::Temperature,
    ] {
        let e = mcap_log::read(&path, &sp(Some(role)), &mut no_progress())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(&format!("effort role {role}"))
                && e.contains("tau_joint, tau_motor, tau_f, current"),
            "{e}"
        );
    }
    for (text, want) in [
        ("none", None),
        ("tau-f", Some(Role::TauF)),
        ("current", Some(Role::Current)),
    ] {
        assert_eq!(mcap_log::parse_effort(text).unwrap(), want, "{text}");
    }
    assert!(mcap_log::parse_effort("sdot").is_err());
    assert!(mcap_log::parse_effort("speed").is_err());
    // Every accepted role reads the seed: 24 messages, effort = 1.5 sin(2 t) + 0.2 with position
    // 0.3 sin(2 t) at the same t.
    for role in mcap_log::EFFORT_ROLES {
        let run = mcap_log::read(&path, &sp(Some(role)), &mut no_progress()).unwrap();
        assert_eq!(run.report.rows_used, 24, "{role}");
        let s = &run.signals;
        let eff = match role {
            Role::TauJoint => s.tau_joint_nm.as_ref(),
            Role::TauMotor => s.tau_motor_nm.as_ref(),
            Role::TauF => s.tau_f_nm.as_ref(),
            _ => s.current_a.as_ref(),
        }
        .unwrap();
        let pos = s.s_rad.as_ref().unwrap();
        for k in 0..24 {
            let t = (pos[k] / 0.3).asin() / 2.0;
            assert!(
                (eff[k] - (1.5 * (2.0 * t).sin() + 0.2)).abs() < 1e-9,
                "{role} k = {k}"
            );
        }
    }
}

/// An MCAP file: the magic, a header record (empty profile and library), then `records` as
/// `(opcode, data)`.
fn mcap_bytes(records: &[(u8, Vec<u8>)]) -> Vec<u8> {
    let mut f = b"\x89MCAP0\r\n".to_vec();
    for (op, data) in [(0x01u8, vec![0u8; 8])].iter().chain(records) {
        f.push(*op);
        f.extend((data.len() as u64).to_le_bytes());
        f.extend(data);
    }
    f
}

#[test]
fn mcap_length_fields_beyond_the_record_are_errors_not_allocations() {
    // Found by the `log_importers` fuzz target: a channel record whose topic length claimed
    // 3.7 GB made the `mcap` crate reserve it (an out-of-memory abort). Every claim here is ~4 GiB
    // in a file of a few dozen bytes.
    let sp = McapSpec {
        topic: "/joint_states".into(),
        joints: vec!["wrist".into()],
        all_joints: false,
        state_joints: None,
        effort_role: None,
        negate: vec![],
    };
    let huge = 0xF000_0000u32.to_le_bytes();
    // Channel: id, schema id, topic length (huge), …
    let mut channel = vec![1, 0, 0, 0];
    channel.extend(huge);
    channel.extend(b"/joint_states");
    // Channel with a sane topic and encoding but a metadata key whose length is huge.
    let mut meta = vec![1, 0, 0, 0];
    for s in ["/joint_states", "cdr"] {
        meta.extend((s.len() as u32).to_le_bytes());
        meta.extend(s.as_bytes());
    }
    meta.extend(8u32.to_le_bytes());
    meta.extend(huge);
    meta.extend([0u8; 4]);
    // Schema: id, name length (huge), …
    let mut schema = vec![1, 0];
    schema.extend(huge);
    schema.extend(b"sensor_msgs/msg/JointState");
    for (what, rec) in [
        ("channel", (0x04, channel)),
        ("channel", (0x04, meta)),
        ("schema", (0x03, schema)),
    ] {
        let path = tmp(&format!("huge_{what}.mcap"));
        std::fs::write(&path, mcap_bytes(&[rec])).unwrap();
        let e = mcap_log::read(&path, &sp, &mut no_progress())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(&format!(
                "a {what} record's length field exceeds the record"
            )),
            "{e}"
        );
    }
    // A chunk whose compression-name length claims ~4 GiB: the reader asks for that many bytes;
    // it is fed what the file holds and ends at its end.
    let mut chunk = vec![0u8; 28];
    chunk.extend(0xFFFF_FFF0u32.to_le_bytes());
    chunk.extend([0u8; 8]);
    let path = tmp("huge_chunk_header.mcap");
    std::fs::write(&path, mcap_bytes(&[(0x06, chunk)])).unwrap();
    let t0 = Instant::now();
    let e = mcap_log::read(&path, &sp, &mut no_progress()).unwrap_err();
    assert!(matches!(e, LogsError::Format { .. }), "{e}");
    eprintln!("huge chunk header: {e} ({:?})", t0.elapsed());
    // An uncompressed chunk (compressed size 9) holding a record that claims 20 bytes, with more
    // bytes after the chunk: found by the fuzz target as an arithmetic overflow in the `mcap` crate.
    let mut chunk = vec![0u8; 24];
    chunk.extend(0u32.to_le_bytes()); // uncompressed CRC
    chunk.extend(0u32.to_le_bytes()); // compression "" (none)
    chunk.extend(9u64.to_le_bytes()); // compressed size
    chunk.push(0x05);
    chunk.extend(20u64.to_le_bytes());
    let mut file = mcap_bytes(&[(0x06, chunk)]);
    file.extend([0u8; 64]);
    let path = tmp("record_past_its_chunk.mcap");
    std::fs::write(&path, file).unwrap();
    let e = mcap_log::read(&path, &sp, &mut no_progress())
        .unwrap_err()
        .to_string();
    assert!(e.contains("malformed chunk"), "{e}");
    // The seed bags still read (their records pass the same checks), uncompressed and zstd.
    for name in ["mcap_plain", "mcap_zstd"] {
        let run = mcap_log::read(&seed_bag_named(name), &sp, &mut no_progress()).unwrap();
        assert_eq!(run.report.rows_used, 24, "{name}");
    }
}

/// The fixture `name` written by the generator run with `FRICTIONLESS_PY` (a python with numpy,
/// h5py, mcap and mcap-ros2-support; `tests/run.sh` sets it up).
fn fixture(kind: &str, name: &str) -> PathBuf {
    let py = std::env::var_os("FRICTIONLESS_PY").unwrap_or_else(|| {
        panic!("FRICTIONLESS_PY is unset: run bash tests/run.sh (it builds the {kind} fixture)")
    });
    let out = tmp(name);
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/make_fixtures.py");
    let st = std::process::Command::new(py)
        .arg(script)
        .arg(kind)
        .arg(&out)
        .status()
        .expect("run the fixture generator");
    assert!(st.success(), "fixture generator failed for {kind}");
    out
}

#[test]
#[ignore = "needs FRICTIONLESS_PY: bash tests/run.sh"]
fn mcap_joint_state_bag_from_python_mcap() {
    let path = fixture("mcap", "bag.mcap");
    let sp = McapSpec {
        topic: "/joint_states".into(),
        joints: vec!["wrist".into()],
        all_joints: false,
        state_joints: None,
        effort_role: Some(Role::TauF),
        negate: vec![],
    };
    let run = mcap_log::read(&path, &sp, &mut no_progress()).unwrap();
    assert_eq!(run.report.rows_read, 1200);
    assert_eq!(run.report.rows_used, 1200);
    let s = &run.signals;
    let (pos, vel, eff) = (
        s.s_rad.as_ref().unwrap(),
        s.sdot_rad_s.as_ref().unwrap(),
        s.tau_f_nm.as_ref().unwrap(),
    );
    // Stamps are relative to the first message; the generator's t starts one step after 0.
    let t_first = 0.002 + 0.0004; // upper bound of the first step
    for k in 0..s.time_s.len() {
        // Recover the generator's t from the position and check the other fields against it.
        let t = s.time_s[k];
        assert!(t >= 0.0);
        let tt = t + (pos[0] / 0.3).asin() / 2.0; // t0 = first stamp: t_gen = t + t_gen(0)
        assert!((pos[k] - 0.3 * (2.0 * tt).sin()).abs() < 1e-6, "k = {k}");
        assert!((vel[k] - 0.6 * (2.0 * tt).cos()).abs() < 1e-6, "k = {k}");
        assert!(
            (eff[k] - (1.5 * (2.0 * tt).sin() + 0.2)).abs() < 1e-6,
            "k = {k}"
        );
    }
    assert!((pos[0] / 0.3).asin() / 2.0 < t_first);
    let label = SignalsLabel {
        source: LabelSource::Given,
        gear_ratio_signed: None,
        kt_nm_per_a: None,
    };
    let mut cfg = PreprocessConfig::for_joint("wrist");
    cfg.gap_s = 0.1;
    let (ds, sum) = preprocess_signals(&[run.signals], &label, None, &cfg).unwrap();
    assert_eq!(
        sum.run_chunks,
        [vec![0, 1]],
        "the 0.5 s pause splits the bag"
    );
    assert!(ds.sdot_rad_s.iter().all(|v| v.is_finite()));

    let e = mcap_log::read(
        &path,
        &McapSpec {
            joints: vec!["elbow".into()],
            all_joints: false,
            state_joints: None,
            ..sp.clone()
        },
        &mut no_progress(),
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("`elbow` not found") && e.contains("wrist"),
        "{e}"
    );
    let e = mcap_log::read(
        &path,
        &McapSpec {
            topic: "/other".into(),
            ..sp
        },
        &mut no_progress(),
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("/other") && e.contains("/joint_states (sensor_msgs/msg/JointState)"),
        "{e}"
    );
}

#[cfg(feature = "mat")]
#[test]
#[ignore = "needs FRICTIONLESS_PY: bash tests/run.sh"]
fn yarp_mat_file_from_h5py() {
    use frictionless_logs::mat_log::{MatSpec, read};
    let path = fixture("mat", "robot_logger_device_2024_01_01_00_00_00.mat");
    let sp = MatSpec {
        joints: vec![],
        all_joints: false,
        state_joints: None,
        negate: vec![],
        desired_gap_s: 1.0,
    };
    let run = read(&path, &sp, &mut no_progress()).unwrap();
    assert_eq!(
        run.report.sources.get("joint").map(String::as_str),
        Some("l_knee")
    );
    assert_eq!(run.report.rows_read, 3000);
    assert_eq!(
        run.report.rows_used, 2200,
        "ticks 1000..1799 lie in the desired-current gap"
    );
    assert_eq!(
        run.report.skipped.get("outside the desired-current stream"),
        Some(&800)
    );
    let s = &run.signals;
    assert_eq!(s.chunk.iter().filter(|c| **c == 0).count(), 1000);
    assert_eq!(s.chunk.iter().filter(|c| **c == 1).count(), 1200);
    let (q, th, om, i) = (
        s.s_rad.as_ref().unwrap(),
        s.theta_motor_rad.as_ref().unwrap(),
        s.omega_motor_rad_s.as_ref().unwrap(),
        s.current_a.as_ref().unwrap(),
    );
    for k in 0..s.time_s.len() {
        let t = s.time_s[k];
        let sk = 0.5 * (std::f64::consts::PI * t).sin();
        assert!((q[k] - sk).abs() < 1e-6, "t = {t}");
        assert!((th[k] - (-100.0 * sk + 0.01 * (7.0 * t).sin())).abs() < 1e-4);
        assert!(
            (om[k] + 50.0 * std::f64::consts::PI * (std::f64::consts::PI * t).cos()).abs() < 1e-4
        );
        assert!((i[k] - (0.2 + 0.1 * (3.0 * t).sin())).abs() < 1e-6);
    }
    assert!(s.temperature_c.is_none());
    let e = read(
        &path,
        &MatSpec {
            joints: vec!["r_elbow".into()],
            all_joints: false,
            state_joints: None,
            ..sp
        },
        &mut no_progress(),
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("r_elbow") && e.contains("l_knee") && e.contains("torso_roll"),
        "{e}"
    );
}

/// A dataset that declares 2³⁶ rows whose chunks were never written (a few KB on disk) is refused
/// before any read, naming the dataset; trusting the declared size read fill values for hours.
#[cfg(feature = "mat")]
#[test]
#[ignore = "needs FRICTIONLESS_PY: bash tests/run.sh"]
fn mat_dataset_declaring_more_than_it_stores_is_refused() {
    use frictionless_logs::mat_log::{MatSpec, read};
    let path = fixture("mat-hollow", "hollow.mat");
    assert!(std::fs::metadata(&path).unwrap().len() < 4 << 20);
    let sp = MatSpec {
        joints: vec![],
        all_joints: false,
        state_joints: None,
        negate: vec![],
        desired_gap_s: 1.0,
    };
    let e = read(&path, &sp, &mut no_progress())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("hollow.mat")
            && e.contains("joints_state/positions/data")
            && e.contains("declares 1030792151040 elements"),
        "{e}"
    );
}

/// The top-level records of an MCAP file as `(offset, opcode, data range)`, after the magic.
fn mcap_records(file: &[u8]) -> Vec<(usize, u8, std::ops::Range<usize>)> {
    let mut out = vec![];
    let mut pos = 8;
    while pos + 9 <= file.len() {
        let op = file[pos];
        let len = u64::from_le_bytes(file[pos + 1..pos + 9].try_into().unwrap()) as usize;
        if pos + 9 + len > file.len() {
            break;
        }
        out.push((pos, op, pos + 9..pos + 9 + len));
        pos += 9 + len;
    }
    out
}

fn wrist(effort_role: Option<Role>) -> McapSpec {
    McapSpec {
        topic: "/joint_states".into(),
        joints: vec!["wrist".into()],
        all_joints: false,
        state_joints: None,
        effort_role,
        negate: vec![],
    }
}

#[test]
fn mcap_chunk_crcs_are_checked() {
    // The uncompressed seed bag (Python `mcap`: every chunk has its CRC). One byte flipped inside a
    // chunk's records: a position changed, the structure intact.
    let path = seed_bag();
    let good = std::fs::read(&path).unwrap();
    let (at, _, data) = mcap_records(&good)
        .into_iter()
        .find(|r| r.1 == 0x06)
        .expect("a chunk");
    let mut bad = good.clone();
    bad[data.end - 20] ^= 0x10;
    let flipped = tmp("flipped.mcap");
    std::fs::write(&flipped, &bad).unwrap();
    let e = mcap_log::read(&flipped, &wrist(None), &mut no_progress())
        .map(|r| format!("imported {} rows", r.report.rows_used))
        .unwrap_or_else(|e| e.to_string());
    assert!(
        e.contains("flipped.mcap")
            && e.contains(&format!("chunk at byte offset {at}"))
            && e.contains("CRC")
            && e.contains("damaged"),
        "{e}"
    );
    // Every chunk's CRC wrong (its stored value changed): refused as well.
    let mut wrong = good.clone();
    for (_, op, data) in mcap_records(&good) {
        if op == 0x06 {
            wrong[data.start + 24] ^= 0xFF;
        }
    }
    std::fs::write(&flipped, &wrong).unwrap();
    let e = mcap_log::read(&flipped, &wrist(None), &mut no_progress()).unwrap_err();
    assert!(e.to_string().contains("CRC"), "{e}");
    // A CRC of 0 is "not computed" (MCAP spec): the chunk is read.
    let mut zero = good.clone();
    zero[data.start + 24..data.start + 28].fill(0);
    std::fs::write(&flipped, &zero).unwrap();
    let run = mcap_log::read(&flipped, &wrist(None), &mut no_progress()).unwrap();
    assert_eq!(run.report.rows_used, 24);
    // The compressed seed still reads.
    let run = mcap_log::read(
        &seed_bag_named("mcap_zstd"),
        &wrist(None),
        &mut no_progress(),
    )
    .unwrap();
    assert_eq!(run.report.rows_used, 24);
}

#[test]
fn an_mcap_recording_without_a_footer_imports_its_whole_chunks_with_a_warning() {
    // A recorder killed in its third chunk: no data end, summary or footer.
    let good = std::fs::read(seed_bag()).unwrap();
    let chunks: Vec<_> = mcap_records(&good)
        .into_iter()
        .filter(|r| r.1 == 0x06)
        .collect();
    let cut = chunks[2].2.start + 40;
    let path = tmp("killed.mcap");
    std::fs::write(&path, &good[..cut]).unwrap();
    let run = mcap_log::read(&path, &wrist(None), &mut no_progress()).unwrap();
    assert!(
        run.report.rows_used > 0 && run.report.rows_used < 24,
        "{}",
        run.report.rows_used
    );
    let w = run.report.warnings.join("\n");
    assert!(
        w.contains("no footer")
            && w.contains("not closed")
            && w.contains(&format!("before byte {}", chunks[2].0)),
        "{w}"
    );
}

#[test]
fn negating_a_role_twice_and_a_duplicated_csv_column_are_refused() {
    let c: Vec<String> = ["time=t", "s=q"].iter().map(|s| s.to_string()).collect();
    let n: Vec<String> = ["s", "s"].iter().map(|s| s.to_string()).collect();
    let e = CsvSpec::parse(&c, &[], &n)
        .and_then(|sp| sp.role_map())
        .unwrap_err()
        .to_string();
    assert!(e.contains("--negate s is given twice"), "{e}");
    let path = tmp("dup_header.csv");
    std::fs::write(&path, "t,q,q\n0,1,2\n0.001,1,2\n0.002,1,2\n").unwrap();
    let e = csv_log::read(&path, &spec(&["time=t", "s=q"], &[]), &mut no_progress())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("dup_header.csv") && e.contains("`q`") && e.contains("columns 2, 3"),
        "{e}"
    );
}

/// The fixture `kind` of `make_fixtures.py` (needs `FRICTIONLESS_PY`; fails without it).
fn py_fixture(kind: &str, name: &str) -> PathBuf {
    assert!(
        std::env::var_os("FRICTIONLESS_PY").is_some(),
        "FRICTIONLESS_PY is unset (tests/run.sh sets it)"
    );
    fixture(kind, name)
}

#[test]
#[ignore = "needs FRICTIONLESS_PY (tests/run.sh)"]
fn mcap_empty_effort_and_duplicate_joint_names_are_explained() {
    let path = py_fixture("mcap-empty-effort", "empty_effort.mcap");
    let run = mcap_log::read(&path, &wrist(Some(Role::TauF)), &mut no_progress()).unwrap();
    assert!(run.signals.tau_f_nm.is_none());
    let w = run.report.warnings.join("\n");
    assert!(
        w.contains("`effort` is empty")
            && w.contains("1 of 100 messages")
            && w.contains("message 38")
            && w.contains("tau_f"),
        "{w}"
    );
    let path = py_fixture("mcap-dup-name", "dup_name.mcap");
    let e = mcap_log::read(&path, &wrist(None), &mut no_progress())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("message 21") && e.contains("`wrist` is named more than once"),
        "{e}"
    );
}

/// `mcap_log::read_streamed` of `path` in blocks of `block_rows`: the blocks, and the run (or the
/// error) it returns. (Its tests write their own fixture files: the tests run in parallel.)
fn mcap_blocks(
    path: &Path,
    spec: &McapSpec,
    block_rows: usize,
) -> (
    Vec<frictionless_logs::ImportedRun>,
    Result<frictionless_logs::ImportedRun, LogsError>,
) {
    let mut blocks = Vec::new();
    let mut sink = |b: frictionless_logs::ImportedRun| {
        blocks.push(b);
        Ok(())
    };
    let stream = frictionless_logs::BlockSink {
        block_rows,
        sink: &mut sink,
    };
    let extra = mcap_log::McapState::default();
    let run = mcap_log::read_streamed(path, spec, &extra, &mut no_progress(), Some(stream));
    (blocks, run)
}

#[test]
#[ignore = "needs FRICTIONLESS_PY (tests/run.sh)"]
fn mcap_streamed_read_hands_on_the_whole_reads_rows_in_blocks() {
    let path = fixture("mcap", "bag_streamed.mcap");
    let sp = wrist(Some(Role::TauF));
    let whole = mcap_log::read(&path, &sp, &mut no_progress()).unwrap();
    let (blocks, run) = mcap_blocks(&path, &sp, 250);
    let run = run.unwrap();
    assert_eq!(run.report.rows_used, whole.report.rows_used);
    assert!(run.signals.time_s.is_empty(), "the rows went to the blocks");
    let lens: Vec<usize> = blocks.iter().map(|b| b.signals.time_s.len()).collect();
    assert_eq!(lens, [250, 250, 250, 250, 200]);
    let cat = |f: fn(&frictionless_logs::ImportedRun) -> Option<&Vec<f64>>| -> Vec<f64> {
        blocks.iter().flat_map(|b| f(b).unwrap().clone()).collect()
    };
    assert_eq!(
        cat(|b| Some(&b.signals.time_s)),
        whole.signals.time_s,
        "time"
    );
    assert_eq!(
        cat(|b| b.signals.s_rad.as_ref()),
        *whole.signals.s_rad.as_ref().unwrap()
    );
    assert_eq!(
        cat(|b| b.signals.sdot_rad_s.as_ref()),
        *whole.signals.sdot_rad_s.as_ref().unwrap()
    );
    assert_eq!(
        cat(|b| b.signals.tau_f_nm.as_ref()),
        *whole.signals.tau_f_nm.as_ref().unwrap()
    );
    assert!(
        blocks
            .iter()
            .all(|b| b.report.source == path.display().to_string()),
        "each block names its log"
    );
}

#[test]
#[ignore = "needs FRICTIONLESS_PY (tests/run.sh)"]
fn mcap_streamed_read_refuses_a_field_that_goes_missing_and_drops_one_never_there() {
    // Message 38 lacks the effort the 37 before it had: the rows already handed on had it.
    let path = py_fixture("mcap-empty-effort", "empty_effort_streamed.mcap");
    let (blocks, run) = mcap_blocks(&path, &wrist(Some(Role::TauF)), 10);
    let e = run.unwrap_err().to_string();
    assert!(
        e.contains("message 38") && e.contains("`effort` is empty") && e.contains("first message"),
        "{e}"
    );
    assert_eq!(blocks.len(), 3, "the blocks before message 38 went on");
    // The first message decides: a bag whose velocity is never there streams without it.
    let path = py_fixture("mcap-no-velocity", "no_velocity.mcap");
    let (blocks, run) = mcap_blocks(&path, &wrist(Some(Role::TauF)), 40);
    let run = run.unwrap();
    assert_eq!(run.report.rows_used, 100);
    assert_eq!(
        blocks.iter().map(|b| b.signals.time_s.len()).sum::<usize>(),
        100
    );
    for b in &blocks {
        assert!(b.signals.sdot_rad_s.is_none(), "no velocity in the bag");
        assert!(b.signals.s_rad.is_some() && b.signals.tau_f_nm.is_some());
    }
}

/// A CSV log `t,q,qd,f` of `rows` rows every `dt` (in the file's own time unit, `t_scale` per
/// second) with q = `amp`·sin(2t) in whatever unit `amp` is.
fn unit_log(name: &str, rows: usize, dt: f64, t_scale: f64, amp: f64) -> PathBuf {
    let path = tmp(name);
    let mut text = String::from("t,q,qd,f\n");
    for k in 0..rows {
        let t = k as f64 * dt;
        text += &format!(
            "{},{},{},{}\n",
            t * t_scale,
            amp * (2.0 * t).sin(),
            0.6 * (2.0 * t).cos(),
            0.3 * (2.0 * t).cos()
        );
    }
    std::fs::write(&path, text).unwrap();
    path
}

fn findings(
    path: &Path,
    units: &[&str],
    gap_s: f64,
) -> Vec<frictionless_logs::plausibility::Finding> {
    let sp = spec(&["time=t", "s=q", "sdot=qd", "tau_f=f"], units);
    let run = csv_log::read(path, &sp, &mut no_progress()).unwrap();
    frictionless_logs::plausibility::check(&[run], gap_s, Some(&sp.units))
}

#[test]
fn plausibility_names_the_wrong_unit_or_gap_with_the_numbers() {
    // Seconds declared ms: 5 000 rows at 1 kHz would be 5 ms.
    let f = findings(
        &unit_log("s_as_ms.csv", 5000, 1e-3, 1.0, 0.3),
        &["time=ms"],
        0.1,
    );
    assert!(f[0].refuse, "{f:?}");
    assert!(
        f[0].message
            .contains("looks like s, declared ms: --unit time=s"),
        "{f:?}"
    );
    // Milliseconds declared s: one sample a second, more than --gap-s.
    let f = findings(&unit_log("ms_as_s.csv", 2000, 1e-3, 1e3, 0.3), &[], 0.1);
    assert!(f[0].refuse, "{f:?}");
    assert!(
        f[0].message
            .contains("looks like ms, declared s: --unit time=ms")
            && f[0].message.contains("--gap-s 0.1"),
        "{f:?}"
    );
    // A run sampled every 0.2 s in seconds: slower than --gap-s 0.1, no unit fits better.
    let f = findings(&unit_log("slow.csv", 80, 0.2, 1.0, 0.3), &[], 0.1);
    assert!(f[0].refuse, "{f:?}");
    assert!(
        f[0].message.contains("0.2000 s, longer than --gap-s 0.1")
            && f[0].message.contains("--gap-s 0.600"),
        "{f:?}"
    );
    // Degrees declared rad: a warning naming the span and the fix.
    let f = findings(&unit_log("deg_as_rad.csv", 4000, 1e-3, 1.0, 40.0), &[], 0.1);
    assert_eq!(f.len(), 1, "{f:?}");
    assert!(!f[0].refuse);
    assert!(
        f[0].message.contains("spans 80.0 rad") && f[0].message.contains("--unit s=deg"),
        "{f:?}"
    );
    // A plausible log: nothing.
    assert!(findings(&unit_log("fine.csv", 4000, 1e-3, 1.0, 0.3), &[], 0.1).is_empty());
    // A constant time column is not "time goes back".
    let path = tmp("const_time.csv");
    let mut text = String::from("t,q\n");
    for k in 0..100 {
        text += &format!("5,{}\n", k as f64 * 1e-3);
    }
    std::fs::write(&path, text).unwrap();
    let e = csv_log::read(&path, &spec(&["time=t", "s=q"], &[]), &mut no_progress())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("time does not advance") && e.contains("99 of 100") && !e.contains("goes back"),
        "{e}"
    );
}
