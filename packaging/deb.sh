#!/usr/bin/env bash
# Builds the Debian package `frictionless` into target/debian/ (docs/packaging.md).
#
# 1. the release build of frictiond, frictl and the C library (libfrictionless.so);
# 2. target/release/deb-assets/: the unit from config/frictiond.service with the package's paths
#    (/usr/bin/frictiond; on a release whose systemd is older than 253 also Type=notify with
#    ExecReload=, as the unit's comment says), frictionless.pc, and the man pages and shell completions
#    that the binaries write from their own clap definitions (FRICTIONLESS_GENERATE_ASSETS=DIR);
# 3. `cargo deb -p frictiond --no-build` with [package.metadata.deb] in daemon/Cargo.toml (cargo-deb
#    from crates.io, installed here if missing).
#
# Usage: bash packaging/deb.sh
# Knobs (env): DEB_SYSTEMD_VERSION (the target release's systemd major version; default: the version
#              apt knows for this machine's release, else the installed one).
# Prints the package's path last.
set -euo pipefail
cd "$(dirname "$0")/.."
log() { echo "deb: $*" >&2; }

command -v cargo-deb >/dev/null || {
  log "installing cargo-deb (cargo install cargo-deb --locked)"
  cargo install cargo-deb --locked
}

log "release build: frictiond, frictl, libfrictionless"
# One package per build: each resolves its dependencies' features as `cargo build -p` of it alone does,
# so frictl's build is the README's `cargo run --release -p frictl` one, reused where that ran before.
for p in frictl frictiond frictionless-capi; do cargo build --release -p "$p"; done
REL=target/release
A=$REL/deb-assets
rm -rf "$A" && mkdir -p "$A"

# The unit, once: config/frictiond.service with the package's paths, named as cargo-deb's
# systemd-units looks it up (<package>.<unit-name>.service; installed as frictiond.service).
U=$A/frictionless.frictiond.service
sdver=${DEB_SYSTEMD_VERSION:-$(apt-cache show --no-all-versions systemd 2>/dev/null | sed -n 's/^Version: \([0-9]*\).*/\1/p' | head -n1)}
[ -n "$sdver" ] || sdver=$(dpkg-query -W -f='${Version}' systemd 2>/dev/null | sed 's/^\([0-9]*\).*/\1/')
[ -n "$sdver" ] || { log "cannot tell the target's systemd version: set DEB_SYSTEMD_VERSION"; exit 2; }
sed 's|/usr/local/bin/frictiond|/usr/bin/frictiond|g' config/frictiond.service > "$U"
if [ "$sdver" -lt 253 ]; then
  log "systemd $sdver < 253: Type=notify with ExecReload= (no Type=notify-reload)"
  sed -i 's|^Type=notify-reload$|Type=notify|; s|^ReloadSignal=SIGHUP$||; s|^# ExecReload=/bin/kill -HUP \$MAINPID$|ExecReload=/bin/kill -HUP $MAINPID|' "$U"
  grep -qx 'ExecReload=/bin/kill -HUP $MAINPID' "$U" || { log "the unit has no ExecReload= line to enable"; exit 1; }
fi
grep -qx 'ExecStart=/usr/bin/frictiond --config /etc/frictionless/frictiond.toml' "$U" ||
  { log "the unit's ExecStart= is not the package's"; exit 1; }

version=$(cargo metadata --no-deps --format-version 1 |
  python3 -c 'import json,sys; print(next(p["version"] for p in json.load(sys.stdin)["packages"] if p["name"]=="frictiond"))')
sed "s|@VERSION@|$version|; s|@MULTIARCH@|x86_64-linux-gnu|" packaging/frictionless.pc.in > "$A/frictionless.pc"

FRICTIONLESS_GENERATE_ASSETS="$A" "$REL/frictiond"
FRICTIONLESS_GENERATE_ASSETS="$A" "$REL/frictl"
for b in frictiond frictl; do mv "$A/bash/$b.bash" "$A/bash/$b"; done
gzip -9nf "$A"/man/*.1
log "$(ls "$A"/man | wc -l) man pages, completions for bash, zsh, fish"

rm -f target/debian/frictionless_*.deb
cargo deb -p frictiond --no-build --strip --output target/debian/ >&2
deb=$(ls -t target/debian/frictionless_*.deb | head -n1)
log "$(du -k "$deb" | cut -f1) KiB, $(dpkg-deb -c "$deb" | wc -l) entries"
echo "$deb"
