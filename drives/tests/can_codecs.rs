//! MIT / ODrive codec tests: hand-computed byte vectors, round trips, saturation, proptest, units,
//! serde config, bus-load numbers.

use frictionless_drives::can::busload::*;
use frictionless_drives::can::mit::{self, *};
use frictionless_drives::can::odrive::{self, OdriveMsg};
use frictionless_drives::can::units::*;
use frictionless_drives::can::{CanCodecError, WireFrame};
use proptest::prelude::*;

/// Ranges where x_int == x: min 0, max 2^bits − 1 (so byte vectors follow from the layout alone).
const IDENTITY: MitRanges = MitRanges {
    p_min_rad: 0.0,
    p_max_rad: 65535.0,
    v_min_rad_s: 0.0,
    v_max_rad_s: 4095.0,
    kp_min_nm_rad: 0.0,
    kp_max_nm_rad: 4095.0,
    kd_min_nm_s_rad: 0.0,
    kd_max_nm_s_rad: 4095.0,
    t_min_nm: 0.0,
    t_max_nm: 4095.0,
    i_min_a: 0.0,
    i_max_a: 4095.0,
};

#[test]
fn mit_command_bytes_follow_the_reference_layout() {
    // p = 0x1234, v = 0xABC, kp = 0x123, kd = 0x456, t = 0x789:
    // 12 34 | AB | C·1 | 23 | 45 | 6·7 | 89
    let cmd = MitCommand {
        p_des_rad: 0x1234 as f64,
        v_des_rad_s: 0xABC as f64,
        kp_nm_rad: 0x123 as f64,
        kd_nm_s_rad: 0x456 as f64,
        t_ff_nm: 0x789 as f64,
    };
    let (f, sat) = mit::encode_command(0x141, &cmd, &IDENTITY).unwrap();
    assert_eq!((f.id, f.extended, f.rtr, f.len), (0x141, false, false, 8));
    assert_eq!(f.data, [0x12, 0x34, 0xAB, 0xC1, 0x23, 0x45, 0x67, 0x89]);
    assert!(!sat.any());
    assert_eq!(
        mit::decode_command(&f, &IDENTITY).unwrap(),
        MitRx::Command(cmd)
    );
}

#[test]
fn mit_pure_torque_bytes_with_mini_cheetah_ranges() {
    let r = MitRanges::MINI_CHEETAH;
    // p = −12.5 → 0, v = −65 → 0, kp = kd = 0 → 0, t = +18 → 0xFFF.
    let cmd = MitCommand {
        p_des_rad: -12.5,
        v_des_rad_s: -65.0,
        ..MitCommand::torque(18.0)
    };
    let (f, _) = mit::encode_command(1, &cmd, &r).unwrap();
    assert_eq!(f.data, [0, 0, 0, 0, 0, 0, 0x0F, 0xFF]);
    let (f, _) = mit::encode_command(
        1,
        &MitCommand {
            t_ff_nm: -18.0,
            ..cmd
        },
        &r,
    )
    .unwrap();
    assert_eq!(f.data, [0; 8]);
    // torque() really has kp = kd = 0.
    let t = MitCommand::torque(3.0);
    assert_eq!((t.kp_nm_rad, t.kd_nm_s_rad), (0.0, 0.0));
}

#[test]
fn mit_reply_bytes_follow_the_reference_layout() {
    // id 3, p = 0xBEEF, v = 0x123, i = 0x456 → 03 BE EF 12 3·4 56
    let rep = MitReply {
        motor_id: 3,
        p_rad: 0xBEEF as f64,
        v_rad_s: 0x123 as f64,
        i_a: 0x456 as f64,
    };
    let (f, sat) = mit::encode_reply(0, &rep, &IDENTITY).unwrap();
    assert_eq!(f.len, 6);
    assert_eq!(f.payload(), &[0x03, 0xBE, 0xEF, 0x12, 0x34, 0x56]);
    assert!(!sat.any());
    assert_eq!(mit::decode_reply(&f, &IDENTITY).unwrap(), rep);
    // An 8-byte CubeMars-style reply (temperature, error) decodes the first 6 bytes.
    let long = WireFrame::standard(0, &[0x03, 0xBE, 0xEF, 0x12, 0x34, 0x56, 40, 0]).unwrap();
    assert_eq!(mit::decode_reply(&long, &IDENTITY).unwrap(), rep);
}

#[test]
fn mit_special_frames() {
    for (s, last) in [
        (MitSpecial::EnterMotorMode, 0xFC),
        (MitSpecial::ExitMotorMode, 0xFD),
        (MitSpecial::ZeroPosition, 0xFE),
    ] {
        let f = mit::encode_special(7, s).unwrap();
        assert_eq!(f.data, [0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, last]);
        assert_eq!(
            mit::decode_command(&f, &MitRanges::MINI_CHEETAH).unwrap(),
            MitRx::Special(s)
        );
    }
    // A command at every maximum would alias "zero position": it is nudged and flagged instead.
    let max = MitCommand {
        p_des_rad: 12.5,
        v_des_rad_s: 65.0,
        kp_nm_rad: 500.0,
        kd_nm_s_rad: 5.0,
        t_ff_nm: 17.99,
    };
    let (f, sat) = mit::encode_command(7, &max, &MitRanges::MINI_CHEETAH).unwrap();
    assert!(sat.has(MitSaturation::T));
    assert!(matches!(
        mit::decode_command(&f, &MitRanges::MINI_CHEETAH).unwrap(),
        MitRx::Command(_)
    ));
}

#[test]
fn mit_saturation_is_reported_and_clamped() {
    let r = MitRanges::MINI_CHEETAH;
    let cmd = MitCommand {
        p_des_rad: 100.0,
        v_des_rad_s: -1000.0,
        kp_nm_rad: -1.0,
        kd_nm_s_rad: 1.0,
        t_ff_nm: 25.0,
    };
    let (f, sat) = mit::encode_command(1, &cmd, &r).unwrap();
    assert!(sat.has(MitSaturation::P) && sat.has(MitSaturation::V) && sat.has(MitSaturation::KP));
    assert!(sat.has(MitSaturation::T) && !sat.has(MitSaturation::KD));
    let MitRx::Command(d) = mit::decode_command(&f, &r).unwrap() else {
        panic!("special")
    };
    assert_eq!(d.p_des_rad, 12.5);
    assert_eq!(d.v_des_rad_s, -65.0);
    assert_eq!(d.kp_nm_rad, 0.0);
    assert_eq!(d.t_ff_nm, 18.0);
    assert!((d.kd_nm_s_rad - 1.0).abs() <= r.steps()[3] / 2.0 + 1e-12);
}

#[test]
fn mit_bad_inputs_are_typed_errors() {
    let r = MitRanges::MINI_CHEETAH;
    assert_eq!(
        mit::encode_command(1, &MitCommand::torque(f64::NAN), &r).unwrap_err(),
        CanCodecError::NonFinite { field: "t_ff_nm" }
    );
    assert!(matches!(
        mit::encode_command(0x800, &MitCommand::torque(0.0), &r),
        Err(CanCodecError::IdOutOfRange { id: 0x800, .. })
    ));
    let bad = MitRanges {
        kd_min_nm_s_rad: 5.0,
        kd_max_nm_s_rad: 5.0,
        ..r
    };
    let e = mit::encode_command(1, &MitCommand::torque(0.0), &bad).unwrap_err();
    assert!(e.to_string().contains("kd_nm_s_rad"), "{e}");
    let short = WireFrame::standard(1, &[0; 7]).unwrap();
    assert_eq!(
        mit::decode_command(&short, &r).unwrap_err(),
        CanCodecError::WrongLength {
            id: 1,
            expected: 8,
            got: 7
        }
    );
    let ext = WireFrame::extended(1, &[0; 8]).unwrap();
    assert!(matches!(
        mit::decode_command(&ext, &r),
        Err(CanCodecError::WrongIdKind { .. })
    ));
    let rtr = WireFrame::remote(1, false, 6).unwrap();
    assert!(matches!(
        mit::decode_reply(&rtr, &r),
        Err(CanCodecError::WrongRtr { .. })
    ));
    assert!(mit::decode_reply(&WireFrame::standard(0, &[1, 2, 3, 4, 5]).unwrap(), &r).is_err());
}

#[test]
fn mit_ranges_load_from_toml() {
    let text = r#"
        p_min_rad = -95.5
        p_max_rad = 95.5
        v_min_rad_s = -30.0
        v_max_rad_s = 30.0
        kp_min_nm_rad = 0.0
        kp_max_nm_rad = 500.0
        kd_min_nm_s_rad = 0.0
        kd_max_nm_s_rad = 5.0
        t_min_nm = -18.0
        t_max_nm = 18.0
        i_min_a = -18.0
        i_max_a = 18.0
    "#;
    let r: MitRanges = toml::from_str(text).unwrap();
    r.validate().unwrap();
    assert_eq!((r.p_max_rad, r.v_min_rad_s), (95.5, -30.0));
    let typo = format!("{text}\nkp_maxx = 1.0\n");
    let e = toml::from_str::<MitRanges>(&typo).unwrap_err();
    assert!(e.to_string().contains("kp_maxx"), "{e}");
}

#[test]
fn odrive_bytes_follow_the_reference() {
    // node 1, Set_Input_Torque (0x0E): id 0x2E, f32 1.0 = 0x3F800000 little-endian.
    let f = odrive::encode(1, &OdriveMsg::SetInputTorque { torque_nm: 1.0 }).unwrap();
    assert_eq!((f.id, f.len), (0x2E, 4));
    assert_eq!(f.payload(), &[0x00, 0x00, 0x80, 0x3F]);
    assert_eq!(odrive::can_id(1, 0x0C).unwrap(), 0x2C); // reference example
    // node 3, Get_Encoder_Estimates (0x09): id 0x69; 1.5 = 0x3FC00000, −2.0 = 0xC0000000.
    let f = WireFrame::standard(0x69, &[0, 0, 0xC0, 0x3F, 0, 0, 0, 0xC0]).unwrap();
    assert_eq!(
        odrive::decode(&f).unwrap(),
        (
            3,
            OdriveMsg::EncoderEstimates {
                pos_rev: 1.5,
                vel_rev_s: -2.0
            }
        )
    );
    // node 63, Set_Axis_State 8: id 0x7E7.
    let f = odrive::encode(63, &OdriveMsg::SetAxisState { requested_state: 8 }).unwrap();
    assert_eq!(f.id, 0x7E7);
    assert_eq!(f.payload(), &[8, 0, 0, 0]);
    // Set_Controller_Mode torque (1) / passthrough (1) on node 2: id 0x4B.
    let f = odrive::encode(
        2,
        &OdriveMsg::SetControllerMode {
            control_mode: 1,
            input_mode: 1,
        },
    )
    .unwrap();
    assert_eq!((f.id, f.payload()), (0x4B, &[1, 0, 0, 0, 1, 0, 0, 0][..]));
    // Heartbeat node 2 (id 0x41): error 0x00000100, state 8.
    let f = WireFrame::standard(0x41, &[0, 1, 0, 0, 8, 0, 0, 0]).unwrap();
    assert_eq!(
        odrive::decode(&f).unwrap(),
        (
            2,
            OdriveMsg::Heartbeat {
                axis_error: 0x100,
                axis_state: 8,
                status: [0; 3]
            }
        )
    );
    // Estop / Clear_Errors: empty payloads.
    assert_eq!(odrive::encode(5, &OdriveMsg::Estop).unwrap().len, 0);
    assert_eq!(
        odrive::encode(5, &OdriveMsg::ClearErrors).unwrap().id,
        5 << 5 | 0x18
    );
    // RTR request for Get_Iq on node 2 (id 0x54).
    let f = odrive::encode(2, &OdriveMsg::Request { cmd: 0x14 }).unwrap();
    assert!(f.rtr && f.id == 0x54);
    assert_eq!(
        odrive::decode(&f).unwrap(),
        (2, OdriveMsg::Request { cmd: 0x14 })
    );
}

#[test]
fn odrive_bad_inputs_are_typed_errors() {
    assert!(matches!(
        odrive::encode(64, &OdriveMsg::Estop),
        Err(CanCodecError::NodeOutOfRange { node: 64, max: 63 })
    ));
    assert_eq!(
        odrive::encode(
            1,
            &OdriveMsg::SetInputTorque {
                torque_nm: f32::INFINITY
            }
        )
        .unwrap_err(),
        CanCodecError::NonFinite { field: "torque_nm" }
    );
    let short = WireFrame::standard(0x29, &[0; 7]).unwrap();
    assert!(matches!(
        odrive::decode(&short),
        Err(CanCodecError::WrongLength {
            id: 0x29,
            expected: 8,
            got: 7
        })
    ));
    let unknown = WireFrame::standard(0x3F, &[]).unwrap(); // node 1, cmd 0x1F
    assert!(matches!(
        odrive::decode(&unknown),
        Err(CanCodecError::UnknownCommand { cmd: 0x1F, .. })
    ));
    let ext = WireFrame::extended(0x2E, &[0; 4]).unwrap();
    assert!(odrive::decode(&ext).is_err());
}

#[test]
fn wire_frame_invariants() {
    assert!(matches!(
        WireFrame::standard(0x800, &[]),
        Err(CanCodecError::IdOutOfRange { id: 0x800, .. })
    ));
    assert!(WireFrame::extended(0x1FFF_FFFF, &[]).is_ok());
    assert!(WireFrame::extended(0x2000_0000, &[]).is_err());
    assert!(matches!(
        WireFrame::standard(1, &[0; 9]),
        Err(CanCodecError::DataTooLong { len: 9 })
    ));
    let r = WireFrame::remote(1, false, 8).unwrap();
    assert!(r.payload().is_empty());
}

#[test]
fn unit_mapping_with_signed_gear_ratio() {
    let kt = 0.1;
    let r = -100.0;
    let cur = JointUnits::new(CommandUnit::Current, kt, r, AngleUnit::Rad).unwrap();
    let mt = JointUnits::new(CommandUnit::MotorTorque, kt, r, AngleUnit::Rad).unwrap();
    let jt = JointUnits::new(CommandUnit::JointTorque, kt, r, AngleUnit::Rev).unwrap();
    assert_eq!(cur.command_from_current(2.0), 2.0);
    assert!((mt.command_from_current(2.0) - 0.2).abs() < 1e-15);
    assert!((jt.command_from_current(2.0) + 20.0).abs() < 1e-12);
    for u in [cur, mt, jt] {
        assert!((u.current_from_command(u.command_from_current(1.7)) - 1.7).abs() < 1e-12);
    }
    // Motor turned +1 rev with r = −100 → joint −2π/100 rad.
    assert!((jt.joint_position_rad(1.0) + std::f64::consts::TAU / 100.0).abs() < 1e-15);
    assert!((mt.joint_velocity_rad_s(-50.0) - 0.5).abs() < 1e-15);
    assert!((jt.joint_position_rad(jt.reported_from_joint_rad(0.3)) - 0.3).abs() < 1e-14);
    assert!(matches!(
        JointUnits::new(CommandUnit::Current, 0.0, r, AngleUnit::Rad),
        Err(CanCodecError::BadUnitParameter {
            field: "kt_nm_per_a",
            ..
        })
    ));
    assert!(matches!(
        JointUnits::new(CommandUnit::Current, kt, f64::NAN, AngleUnit::Rad),
        Err(CanCodecError::BadUnitParameter {
            field: "gear_ratio",
            ..
        })
    ));
    #[derive(serde::Deserialize)]
    struct C {
        a: CommandUnit,
        b: CommandUnit,
        c: CommandUnit,
    }
    let c: C =
        toml::from_str("a = \"current\"\nb = \"motor_torque\"\nc = \"joint_torque\"").unwrap();
    assert_eq!(
        (c.a, c.b, c.c),
        (
            CommandUnit::Current,
            CommandUnit::MotorTorque,
            CommandUnit::JointTorque
        )
    );
    assert!(toml::from_str::<C>("a = \"amps\"\nb = \"current\"\nc = \"current\"").is_err());
}

#[test]
fn bus_load_numbers() {
    // Standard id, 8 bytes: 34 + 64 + 13 = 111 bits unstuffed; + ⌊97/4⌋ = 24 stuff bits = 135.
    assert_eq!(frame_bits_unstuffed(8, false), 111);
    assert_eq!(frame_bits_worst(8, false), 135);
    assert_eq!(frame_bits_worst(8, true), 160); // 54 + 64 + 13 + ⌊117/4⌋
    assert_eq!(frame_bits_worst(0, false), 34 + 13 + 8);
    // MIT: 135 + (34 + 48 + 13 + ⌊81/4⌋ = 115) = 250 bits per joint per ms → 25 % of 1 Mbit.
    assert_eq!(mit_bits_per_joint_tick(), 250);
    let per = load_fraction(1, mit_bits_per_joint_tick(), 1000.0, 1e6);
    assert!((per - 0.25).abs() < 1e-12);
    assert_eq!(max_joints(mit_bits_per_joint_tick(), 1000.0, 1e6, 0.75), 3);
    assert_eq!(max_joints(mit_bits_per_joint_tick(), 1000.0, 1e6, 1.0), 4);
    // ODrive: 95 + 2·135 = 365 bits → 2 joints (73 %).
    assert_eq!(odrive_bits_per_joint_tick(), 365);
    assert_eq!(
        max_joints(odrive_bits_per_joint_tick(), 1000.0, 1e6, 0.75),
        2
    );
    assert_eq!(
        max_joints(odrive_bits_per_joint_tick(), 1000.0, 1e6, 1.0),
        2
    );
    assert!(check_load(3, 250, 1000.0, 1e6, 0.75).is_ok());
    let e = check_load(4, 250, 1000.0, 1e6, 0.75).unwrap_err();
    assert!((e.load - 1.0).abs() < 1e-12);
    assert!(e.to_string().contains("4 joints"), "{e}");
    assert!(check_load(1, 250, 1000.0, 0.0, 0.75).is_err());
}

fn odrive_msg() -> impl Strategy<Value = OdriveMsg> {
    let f = -1e6f32..1e6f32;
    prop_oneof![
        Just(OdriveMsg::Estop),
        Just(OdriveMsg::ClearErrors),
        any::<u32>().prop_map(|s| OdriveMsg::SetAxisState { requested_state: s }),
        (any::<i32>(), any::<i32>()).prop_map(|(c, i)| OdriveMsg::SetControllerMode {
            control_mode: c,
            input_mode: i
        }),
        f.clone()
            .prop_map(|t| OdriveMsg::SetInputTorque { torque_nm: t }),
        (any::<u32>(), any::<u8>(), any::<[u8; 3]>()).prop_map(|(e, s, st)| {
            OdriveMsg::Heartbeat {
                axis_error: e,
                axis_state: s,
                status: st,
            }
        }),
        (f.clone(), f.clone()).prop_map(|(p, v)| OdriveMsg::EncoderEstimates {
            pos_rev: p,
            vel_rev_s: v
        }),
        (f.clone(), f).prop_map(|(a, b)| OdriveMsg::Iq {
            iq_setpoint_a: a,
            iq_measured_a: b
        }),
        prop::sample::select(vec![0x01u8, 0x09, 0x14, 0x17])
            .prop_map(|c| OdriveMsg::Request { cmd: c }),
    ]
}

proptest! {
    #[test]
    fn mit_command_round_trip_within_half_step(
        p in -12.5f64..=12.5, v in -65.0f64..=65.0, kp in 0.0f64..=500.0,
        kd in 0.0f64..=5.0, t in -18.0f64..=17.9, id in 0u32..=0x7FF,
    ) {
        let r = MitRanges::MINI_CHEETAH;
        let cmd = MitCommand { p_des_rad: p, v_des_rad_s: v, kp_nm_rad: kp, kd_nm_s_rad: kd, t_ff_nm: t };
        let (f, sat) = mit::encode_command(id, &cmd, &r).unwrap();
        prop_assert!(!sat.any());
        let MitRx::Command(d) = mit::decode_command(&f, &r).unwrap() else { panic!("special") };
        let s = r.steps();
        let tol = |k: usize| s[k] / 2.0 + 1e-9;
        prop_assert!((d.p_des_rad - p).abs() <= tol(0));
        prop_assert!((d.v_des_rad_s - v).abs() <= tol(1));
        prop_assert!((d.kp_nm_rad - kp).abs() <= tol(2));
        prop_assert!((d.kd_nm_s_rad - kd).abs() <= tol(3));
        prop_assert!((d.t_ff_nm - t).abs() <= tol(4));
    }

    #[test]
    fn mit_decoded_bytes_re_encode_identically(b in any::<[u8; 8]>()) {
        let r = MitRanges::MINI_CHEETAH;
        let f = WireFrame::standard(9, &b).unwrap();
        match mit::decode_command(&f, &r).unwrap() {
            MitRx::Command(c) => {
                let (g, sat) = mit::encode_command(9, &c, &r).unwrap();
                prop_assert!(!sat.any());
                prop_assert_eq!(g.data, b);
            }
            MitRx::Special(s) => prop_assert_eq!(mit::encode_special(9, s).unwrap().data, b),
        }
    }

    #[test]
    fn mit_reply_round_trip(
        id in any::<u8>(), p in -12.5f64..=12.5, v in -65.0f64..=65.0, i in -40.0f64..=40.0,
        over in 1.0f64..1e6,
    ) {
        let r = MitRanges::MINI_CHEETAH;
        let (f, sat) = mit::encode_reply(0, &MitReply { motor_id: id, p_rad: p, v_rad_s: v, i_a: i }, &r).unwrap();
        prop_assert!(!sat.any());
        let d = mit::decode_reply(&f, &r).unwrap();
        let s = r.steps();
        prop_assert_eq!(d.motor_id, id);
        prop_assert!((d.p_rad - p).abs() <= s[0] / 2.0 + 1e-9);
        prop_assert!((d.v_rad_s - v).abs() <= s[1] / 2.0 + 1e-9);
        prop_assert!((d.i_a - i).abs() <= s[5] / 2.0 + 1e-9);
        // Out of range: clamped to the range end and flagged.
        let (f, sat) = mit::encode_reply(0, &MitReply { motor_id: id, p_rad: p, v_rad_s: v, i_a: -40.0 - over }, &r).unwrap();
        prop_assert!(sat.has(MitSaturation::I));
        prop_assert_eq!(mit::decode_reply(&f, &r).unwrap().i_a, -40.0);
    }

    #[test]
    fn odrive_round_trip(node in 0u8..=63, msg in odrive_msg()) {
        let f = odrive::encode(node, &msg).unwrap();
        f.validate().unwrap();
        prop_assert_eq!(odrive::split_id(f.id), (node, msg.cmd_id()));
        prop_assert_eq!(odrive::decode(&f).unwrap(), (node, msg));
    }

    #[test]
    fn odrive_decode_never_panics(id in 0u32..=0x7FF, len in 0u8..=8, data in any::<[u8; 8]>(), rtr in any::<bool>()) {
        let f = if rtr {
            WireFrame::remote(id, false, len).unwrap()
        } else {
            WireFrame::standard(id, &data[..len as usize]).unwrap()
        };
        if let Ok((node, msg)) = odrive::decode(&f) {
            prop_assert_eq!(node as u32, id >> 5);
            // Whatever decodes with finite floats re-encodes to a frame that decodes the same.
            if let Ok(g) = odrive::encode(node, &msg) {
                prop_assert_eq!(odrive::decode(&g).unwrap(), (node, msg));
            }
        }
    }
}
