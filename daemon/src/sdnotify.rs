//! systemd `sd_notify` sender, std only.
//!
//! What this module **is**: one datagram per call to `$NOTIFY_SOCKET`, handling both filesystem paths
//! and Linux abstract sockets (`@name`; the `sd-notify` crate 0.5 does not), plus the watchdog
//! interval from `$WATCHDOG_USEC` (honouring `$WATCHDOG_PID`).
//!
//! What it is **not**: never call this from the RT thread (it opens a socket and formats strings).

use std::os::unix::net::UnixDatagram;
use std::time::Duration;

/// Sends `msg` (e.g. `"READY=1\nSTATUS=running"`). `Ok(false)` when not run under systemd.
pub fn notify(msg: &str) -> std::io::Result<bool> {
    let Some(path) = std::env::var_os("NOTIFY_SOCKET") else {
        return Ok(false);
    };
    let sock = UnixDatagram::unbound()?;
    if let Some(name) = path.as_encoded_bytes().strip_prefix(b"@") {
        use std::os::linux::net::SocketAddrExt;
        let addr = std::os::unix::net::SocketAddr::from_abstract_name(name)?;
        sock.send_to_addr(msg.as_bytes(), &addr)?;
    } else {
        sock.send_to(msg.as_bytes(), &path)?;
    }
    Ok(true)
}

/// Sends and logs failures (notification problems must not stop the daemon).
pub fn notify_logged(msg: &str) {
    if let Err(e) = notify(msg) {
        tracing::warn!("sd_notify({:?}) failed: {e}", msg.replace('\n', " "));
    }
}

/// The watchdog interval systemd expects, if enabled for this process.
pub fn watchdog_interval() -> Option<Duration> {
    let usec: u64 = std::env::var("WATCHDOG_USEC").ok()?.parse().ok()?;
    if let Ok(pid) = std::env::var("WATCHDOG_PID")
        && pid.parse::<u32>().ok() != Some(std::process::id())
    {
        return None;
    }
    (usec > 0).then(|| Duration::from_micros(usec))
}

/// `MONOTONIC_USEC=` value for RELOADING=1.
pub fn monotonic_usec() -> u64 {
    frictionless_shm_types::monotonic_ns() / 1000
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sends_to_path_and_abstract_sockets() {
        // Env vars are process-wide: this is the only test in the crate touching NOTIFY_SOCKET.
        let dir = std::env::temp_dir().join(format!("frictiond_sdn_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("notify.sock");
        let rx = UnixDatagram::bind(&path).unwrap();
        rx.set_read_timeout(Some(Duration::from_secs(2))).unwrap();
        // SAFETY: single-threaded use of this variable within this test binary.
        unsafe { std::env::set_var("NOTIFY_SOCKET", &path) };
        assert!(notify("READY=1").unwrap());
        let mut buf = [0u8; 64];
        let n = rx.recv(&mut buf).unwrap();
        assert_eq!(&buf[..n], b"READY=1");

        use std::os::linux::net::SocketAddrExt;
        let name = format!("frictiond_sdn_abs_{}", std::process::id());
        let addr = std::os::unix::net::SocketAddr::from_abstract_name(name.as_bytes()).unwrap();
        let rx2 = UnixDatagram::bind_addr(&addr).unwrap();
        rx2.set_read_timeout(Some(Duration::from_secs(2))).unwrap();
        unsafe { std::env::set_var("NOTIFY_SOCKET", format!("@{name}")) };
        assert!(notify("WATCHDOG=1").unwrap());
        let n = rx2.recv(&mut buf).unwrap();
        assert_eq!(&buf[..n], b"WATCHDOG=1");
        unsafe { std::env::remove_var("NOTIFY_SOCKET") };
        assert!(!notify("READY=1").unwrap());
        let _ = std::fs::remove_dir_all(dir);
    }
}
