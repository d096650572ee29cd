//! Real-kernel test (run in the VM by tests/canvm/run.sh): replay a log on vcan0 and record what
//! arrives with a second socket.

use std::time::Duration;

use frictionless_canlog::{self as canlog, LogFrame};
use socketcan::{CanSocket, Socket};

#[test]
#[ignore = "needs vcan (run tests/canvm/run.sh)"]
fn vcan_replay_sends_what_the_log_says() {
    let text: String = (0..50)
        .map(|k| {
            format!(
                "(5.{:06}) can9 {:03X}#{:02X}{:02X}\n",
                k * 1000,
                0x100 + k,
                k,
                255 - k
            )
        })
        .collect::<String>()
        + "(5.050000) can9 1ABCDEF0#R4\n";
    let entries = canlog::parse_log(text.as_bytes(), "<t>").unwrap();
    let rx = CanSocket::open("vcan0").unwrap();
    let sender = {
        let e = entries.clone();
        std::thread::spawn(move || canlog::replay_to_iface(&e, Some("vcan0"), 1.0, 1).unwrap())
    };
    let mut got = Vec::new();
    while got.len() < entries.len() {
        let f = rx
            .read_frame_timeout(Duration::from_secs(5))
            .expect("frame within 5 s");
        let any = socketcan::CanAnyFrame::from(f);
        got.push(canlog::from_socketcan(&any).expect("not an error frame"));
    }
    assert_eq!(sender.join().unwrap(), entries.len() as u64);
    let want: Vec<LogFrame> = entries.iter().map(|e| e.frame.clone()).collect();
    assert_eq!(got, want);
}
