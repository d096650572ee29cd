//! `config/cia402_frictionless.eds` (the EDS file of the emulated drive, which python-canopen and
//! other CANopen tools load) describes exactly the object dictionary of
//! `frictionless_drives::can::cia402_node::Cia402Node`: the same objects, data types, access and
//! default values, so the two cannot drift apart.

use std::collections::BTreeMap;

use frictionless_drives::can::cia402_node::{
    Cia402Node, DEVICE_NAME, DataType, NodeParams, Object,
};

const EDS: &str = include_str!("../../config/cia402_frictionless.eds");

/// The node the EDS's joint-dependent defaults describe (0x6076 1000 mNm, 0x6072 1000 ‰,
/// 0x608F:01 16384), on a node id that shows `$NODEID` resolution.
fn node() -> Cia402Node {
    Cia402Node::new(&NodeParams {
        node: 5,
        rated_torque_mnm: 1000,
        max_torque_permille: 1000,
        counts_per_rev: 16384,
    })
    .unwrap()
}

/// Sections of an INI file: name → key → value (in file order of keys irrelevant).
fn sections(text: &str) -> BTreeMap<String, BTreeMap<String, String>> {
    let mut out: BTreeMap<String, BTreeMap<String, String>> = BTreeMap::new();
    let mut cur: Option<String> = None;
    for (k, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with(';') {
            continue;
        }
        if let Some(name) = line.strip_prefix('[').and_then(|l| l.strip_suffix(']')) {
            assert!(
                out.insert(name.to_string(), BTreeMap::new()).is_none(),
                "line {}: section [{name}] twice",
                k + 1
            );
            cur = Some(name.to_string());
            continue;
        }
        let (key, value) = line
            .split_once('=')
            .unwrap_or_else(|| panic!("line {}: not key=value: {line}", k + 1));
        let sec = cur
            .as_ref()
            .unwrap_or_else(|| panic!("line {}: key outside a section", k + 1));
        let prev = out
            .get_mut(sec)
            .unwrap()
            .insert(key.trim().to_string(), value.trim().to_string());
        assert!(prev.is_none(), "line {}: [{sec}] {key} twice", k + 1);
    }
    out
}

fn int(s: &str) -> i64 {
    let (neg, t) = s.strip_prefix('-').map_or((false, s), |t| (true, t));
    let v = match t.strip_prefix("0x").or_else(|| t.strip_prefix("0X")) {
        Some(h) => i64::from_str_radix(h, 16),
        None => t.parse(),
    }
    .unwrap_or_else(|e| panic!("not an integer: {s:?}: {e}"));
    if neg { -v } else { v }
}

/// A DefaultValue as the raw value the node holds: `$NODEID` resolved (CiA 306 `$NODEID+x`),
/// masked to the type's size (two's complement).
fn raw_default(s: &str, node_id: u8, ty: DataType) -> u32 {
    let v = match s.strip_prefix("$NODEID") {
        Some(rest) => i64::from(node_id) + rest.strip_prefix('+').map_or(0, int),
        None => int(s),
    };
    let bits = 8 * u32::from(ty.bytes());
    (v as u64 & ((1u64 << bits) - 1)) as u32
}

fn data_type(code: i64) -> Option<DataType> {
    use DataType::*;
    [
        Unsigned8, Unsigned16, Unsigned32, Integer8, Integer16, Integer32,
    ]
    .into_iter()
    .find(|t| i64::from(t.code()) == code)
}

#[test]
fn can_cia402_eds_equals_the_emulated_node_dictionary() {
    let eds = sections(EDS);
    let n = node();
    // Every object of the node is in the EDS with the same type, access and default.
    let mut expected_sections = vec!["1008".to_string()];
    for o in n.objects() {
        let Object {
            addr,
            data_type: ty,
            writable,
            value,
        } = *o;
        let record = eds.get(&format!("{:04X}", addr.index)).unwrap_or_else(|| {
            panic!("EDS lacks object 0x{:04X}", addr.index);
        });
        let is_record = record.get("ObjectType").map(|s| int(s)) == Some(0x9);
        let name = if is_record {
            format!("{:04X}sub{:X}", addr.index, addr.sub)
        } else {
            assert_eq!(addr.sub, 0, "0x{:04X} is a VAR in the EDS", addr.index);
            format!("{:04X}", addr.index)
        };
        let s = eds.get(&name).unwrap_or_else(|| {
            panic!("EDS lacks [{name}] (0x{:04X}:{:02X})", addr.index, addr.sub)
        });
        let what = format!("[{name}]");
        assert_eq!(
            s.get("DataType").map(|v| int(v)),
            Some(i64::from(ty.code())),
            "{what} DataType"
        );
        assert_eq!(s.get("ObjectType").map(|v| int(v)), Some(0x7), "{what}");
        let access = s.get("AccessType").map(String::as_str);
        assert_eq!(
            access == Some("rw"),
            writable,
            "{what} AccessType {access:?}, node writable = {writable}"
        );
        assert!(matches!(access, Some("rw" | "ro" | "const")), "{what}");
        let d = s
            .get("DefaultValue")
            .unwrap_or_else(|| panic!("{what} has no DefaultValue"));
        assert_eq!(
            raw_default(d, n.node(), ty),
            value,
            "{what} DefaultValue {d} vs the node's 0x{value:X}"
        );
        expected_sections.push(format!("{:04X}", addr.index));
        if is_record {
            expected_sections.push(name);
        }
    }
    // Records: SubNumber counts the subs; sub 0 is the highest sub-index (of a PDO mapping: the
    // number of mapped objects, at most 8).
    for o in n.objects().iter().filter(|o| o.addr.sub == 0) {
        let idx = format!("{:04X}", o.addr.index);
        if int(&eds[&idx]["ObjectType"]) != 0x9 {
            continue;
        }
        let subs: Vec<u8> = n
            .objects()
            .iter()
            .filter(|p| p.addr.index == o.addr.index)
            .map(|p| p.addr.sub)
            .collect();
        assert_eq!(
            int(&eds[&idx]["SubNumber"]),
            subs.len() as i64,
            "[{idx}] SubNumber"
        );
        let mapping = matches!(o.addr.index, 0x1600..=0x17FF | 0x1A00..=0x1BFF);
        if mapping {
            assert!(o.value <= 8, "0x{idx}:00 mapped objects");
        } else {
            assert_eq!(
                i64::from(o.value),
                i64::from(*subs.iter().max().unwrap()),
                "0x{idx}:00 (highest sub-index)"
            );
        }
    }
    // The device name (served by segmented upload, not a dictionary entry).
    let name = &eds["1008"];
    assert_eq!(int(&name["DataType"]), 0x9, "[1008] VISIBLE_STRING");
    assert_eq!(name["DefaultValue"].as_bytes(), DEVICE_NAME);
    // Nothing else: every object section of the EDS is one of the node's.
    expected_sections.sort();
    expected_sections.dedup();
    let object_sections: Vec<String> = eds
        .keys()
        .filter(|k| k.len() >= 4 && k[..4].chars().all(|c| c.is_ascii_hexdigit()))
        .cloned()
        .collect();
    assert_eq!(object_sections, expected_sections, "EDS object sections");
    // The object lists name every object once.
    let mut listed: Vec<String> = ["MandatoryObjects", "OptionalObjects", "ManufacturerObjects"]
        .iter()
        .flat_map(|l| {
            let s = &eds[*l];
            let n = int(&s["SupportedObjects"]);
            assert_eq!(s.len() as i64, n + 1, "[{l}] SupportedObjects");
            (1..=n).map(move |k| format!("{:04X}", int(&s[&k.to_string()])))
        })
        .collect();
    listed.sort();
    let mut indices: Vec<String> = object_sections
        .into_iter()
        .filter(|k| k.len() == 4)
        .collect();
    indices.sort();
    assert_eq!(listed, indices, "object lists");
    // DeviceInfo agrees with the identity object.
    let info = &eds["DeviceInfo"];
    for (key, sub) in [
        ("VendorNumber", 1),
        ("ProductNumber", 2),
        ("RevisionNumber", 3),
    ] {
        assert_eq!(
            int(&info[key]),
            i64::from(n.get(0x1018, sub).unwrap()),
            "[DeviceInfo] {key}"
        );
    }
    assert_eq!(info["ProductName"].as_bytes(), DEVICE_NAME);
    assert_eq!(int(&info["NrOfRXPDO"]), 4);
    assert_eq!(int(&info["NrOfTXPDO"]), 4);
}

#[test]
fn can_cia402_eds_types_and_defaults_are_checked() {
    // The comparison above can fail: a changed default or type is noticed.
    let n = node();
    let o = n.objects().iter().find(|o| o.addr.index == 0x605A).unwrap();
    assert_eq!(o.data_type, DataType::Integer16);
    assert_eq!(raw_default("2", 5, o.data_type), o.value);
    assert_ne!(raw_default("3", 5, o.data_type), o.value);
    assert_eq!(raw_default("-1", 5, DataType::Integer16), 0xFFFF);
    assert_eq!(
        raw_default("$NODEID+0x80000380", 5, DataType::Unsigned32),
        0x8000_0385
    );
    assert_eq!(data_type(0x3), Some(DataType::Integer16));
    assert_eq!(data_type(0x9), None);
}
