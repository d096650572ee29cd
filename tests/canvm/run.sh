#!/usr/bin/env bash
# Real-kernel SocketCAN tests inside a small QEMU VM.
#
# This machine's kernel has no CAN. The script boots Debian's stock kernel (`linux-image-amd64`, which
# carries can.ko, can-raw.ko, vcan.ko, can-gw.ko; NOT the cloud flavour) from a tiny initramfs holding
# busybox, those modules (loaded in dependency order), the project's statically linked (musl) binaries
# and the test harnesses that hold a `vcan` test. Inside, /init creates vcan0 (classic MTU 16) and vcan1, then runs each with
# `--include-ignored --test-threads=1 --show-output vcan` (tests named `vcan…` and marked
# #[ignore = "needs vcan"] on the host). The optimised binaries (cargo profile `canvm`: release without LTO
# or debug info, half the build time) of the built packages (frictiond, frictl) are
# in the VM's /bin (on PATH; FRICTIONLESS_IN_CANVM=1 tells tests to look there). Lines a test prints that
# start with `bench:` (the in-VM benchmarks) are echoed here and saved to $CANVM_WORK/bench.txt.
# Everything comes from apt, rustup and crates.io.
#
# Usage: bash tests/canvm/run.sh
# Knobs (env): CANVM_WORK (default target/canvm), CANVM_TIMEOUT seconds (default 600), CANVM_SKIP_APT=1,
#              CANVM_PACKAGES (cargo packages whose test harnesses run in the VM; default "frictionless frictionless-drives frictiond frictionless-canlog frictl"),
#              CANVM_FILTER (libtest name filter, default "vcan"), CANVM_ACCEL (auto|kvm|tcg, default auto),
#              CANVM_MEM_MB (VM memory, default 2048: the initramfs is unpacked into it),
#              CANVM_TESTS (only these integration-test targets, e.g. "drives_tests frictiond_e2e"; default:
#              every harness of the packages that has a test matching CANVM_FILTER, found with `--list`).
#              CANVM_BUILD (musl | host, default musl): `host` runs the host target's (glibc) binaries and
#              harnesses instead of building a static musl set: built in the normal target dir with cargo
#              profile CANVM_PROFILE (default dev), CANVM_CARGO_ARGS (e.g. the features the test run
#              used) and --workspace (CANVM_PACKAGES then only says which binaries must be there), so after
#              `bash tests/run.sh` nothing is rebuilt; the ELF interpreter and every shared
#              library `ldd` lists for them are copied into the initramfs at their host paths. CI uses it.
#              CANVM_PYTHON (default python3): the CPython (with AF_CAN in its socket module) put into the
#              VM, with a trimmed stdlib and tests/canvm/requirements.txt (python-canopen) installed into
#              $CANVM_WORK/python (the wheels cached there), when a selected harness has a test matching
#              CANVM_FILTER whose name holds `canopen`; inside, FRICTIONLESS_CANVM_PYTHON names it.
# Last line: "canvm: N passed, N failed"; exit code non-zero on any failure or timeout.
set -euo pipefail
cd "$(dirname "$0")/../.."
ROOT=$(pwd)
WORK=${CANVM_WORK:-$ROOT/target/canvm}
TIMEOUT=${CANVM_TIMEOUT:-600}
PACKAGES=${CANVM_PACKAGES:-"frictionless frictionless-drives frictiond frictionless-canlog frictl"}
FILTER=${CANVM_FILTER:-vcan}
TARGET=x86_64-unknown-linux-musl
mkdir -p "$WORK"
log() { echo "canvm: [${SECONDS} s] $*" >&2; }

# 1. Host packages.
if [ -z "${CANVM_SKIP_APT:-}" ]; then
  need=""
  command -v qemu-system-x86_64 >/dev/null || need="$need qemu-system-x86"
  [ -x /bin/busybox ] && /bin/busybox --list 2>/dev/null | grep -q '^insmod$' || need="$need busybox-static"
  command -v cpio >/dev/null || need="$need cpio"
  command -v musl-gcc >/dev/null || need="$need musl-tools"   # C parts of some crates (e.g. alloca) for musl
  if [ -n "$need" ]; then
    log "installing$need"
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends $need >/dev/null
  fi
fi

# 2. The kernel: resolve the ABI package from the meta-package (never pin an ABI), unpack only what we need.
KDIR="$WORK/kernel"
if [ ! -f "$KDIR/vmlinuz" ]; then
  abi=$(apt-cache depends linux-image-amd64 | awk '/Depends: linux-image-[0-9]/{print $2; exit}')
  [ -n "$abi" ] || { log "cannot resolve linux-image-amd64 (run apt-get update)"; exit 2; }
  log "kernel package $abi"
  rm -rf "$KDIR" && mkdir -p "$KDIR/dl" && chmod 777 "$KDIR/dl"
  (cd "$KDIR/dl" && apt-get download "$abi" >/dev/null 2>&1 || su nobody -s /bin/sh -c "apt-get download $abi" >/dev/null)
  deb=$(ls "$KDIR"/dl/*.deb | head -n1)
  dpkg-deb --fsys-tarfile "$deb" | tar -x -C "$KDIR" --wildcards './boot/vmlinuz-*' './boot/config-*' \
    './lib/modules/*/kernel/net/can/*' './lib/modules/*/kernel/drivers/net/can/*'
  grep -q '^CONFIG_CAN_VCAN=m' "$KDIR"/boot/config-* || { log "kernel lacks CONFIG_CAN_VCAN=m"; exit 2; }
  cp "$KDIR"/boot/vmlinuz-* "$KDIR/vmlinuz"
  rm -rf "$KDIR/dl"
fi
MODS=$(ls -d "$KDIR"/lib/modules/*/kernel)

# 3. Binaries and test harnesses: static musl ones in a separate target dir (keeps the host build
#    untouched), or the host build's own (CANVM_BUILD=host).
BUILD=${CANVM_BUILD:-musl}
case "$BUILD" in
  musl)
    rustup target list --installed 2>/dev/null | grep -q "^$TARGET\$" || rustup target add "$TARGET" >/dev/null
    export CARGO_TARGET_DIR="$WORK/cargo"
    # The VM's TCG CPU has no AVX-512; build for the portable baseline so nothing depends on host
    # features (the kernel's runtime dispatch still picks the best available path).
    export RUSTFLAGS="-C target-cpu=x86-64-v2"
    cargoargs=(--profile canvm --target "$TARGET")
    BINDIR="$CARGO_TARGET_DIR/$TARGET/canvm" ;;
  host)
    # The host build as it is (x86-64-v3 from .cargo/config.toml: TCG's `-cpu max` has AVX2 and FMA).
    profile=${CANVM_PROFILE:-dev}
    # shellcheck disable=SC2206
    cargoargs=(${CANVM_CARGO_ARGS:-})
    # Plain `cargo test` builds with the `test` profile (dev's settings, output in debug/), as
    # tests/run.sh did; `--profile dev` would name a different profile and rebuild everything.
    [ "$profile" = dev ] || cargoargs+=(--profile "$profile")
    dir=$profile; [ "$profile" = dev ] && dir=debug
    BINDIR="${CARGO_TARGET_DIR:-$ROOT/target}/$dir" ;;
  *) log "CANVM_BUILD=$BUILD: expected musl or host"; exit 2 ;;
esac
pkgargs=""; for p in $PACKAGES; do pkgargs="$pkgargs -p $p"; done
# The host build is the workspace's (tests/run.sh's `cargo test --workspace`, so it is reused).
[ "$BUILD" = host ] && pkgargs="--workspace"
log "building bins and test harnesses ($BUILD: ${cargoargs[*]}; $PACKAGES)"
# `cargo test --no-run`, not `cargo build --bins`: the binaries come out of the same build as the
# harnesses (the packages' integration tests need them), with the dev-dependencies' features, so the
# dependencies compile once.
# CANVM_TESTS picks harnesses by target name from this one build's list: selecting them with `--test`
# instead changes the unit graph (it leaves out targets whose dependencies shape the proc-macro
# crates' profile) and rebuilds dependencies tests/run.sh had just built (docs/decisions.md).
cargo test "${cargoargs[@]}" $pkgargs --no-run 2>&1 | tail -n 3 >&2
harnesses=$(cargo test "${cargoargs[@]}" $pkgargs --no-run --message-format=json 2>"$WORK/build-tests.log" |
  CANVM_TESTS="${CANVM_TESTS:-}" python3 -c 'import json,os,sys
only=set(os.environ["CANVM_TESTS"].split())
for l in sys.stdin:
    try: m=json.loads(l)
    except Exception: continue
    if m.get("reason")=="compiler-artifact" and m.get("executable") and m.get("profile",{}).get("test"):
        t=m.get("target",{})
        if not only or ("test" in t.get("kind",[]) and t.get("name") in only):
            print(m["executable"])')
[ -n "$harnesses" ] || { tail -n 30 "$WORK/build-tests.log" >&2; log "building the test harnesses failed"; echo "canvm: 0 passed, 1 failed"; exit 1; }
for t in ${CANVM_TESTS:-}; do
  printf '%s\n' $harnesses | grep -q "/${t//-/_}-[0-9a-f]*\$" ||
    { log "CANVM_TESTS: no integration-test target named '$t' in the build"; echo "canvm: 0 passed, 1 failed"; exit 1; }
done
# Only the harnesses that hold a test matching FILTER go into the VM (the static musl harnesses list
# their tests on the host too): the rest would only grow the initramfs the guest unpacks into RAM.
if [ -z "${CANVM_TESTS:-}" ]; then
  selected=""
  for h in $harnesses; do
    if "$h" --list --include-ignored "$FILTER" 2>/dev/null | grep -q ': test$'; then selected="$selected $h"; fi
  done
  log "harnesses with tests matching '$FILTER':$(for h in $selected; do printf ' %s' "$(basename "${h%-*}")"; done)"
  harnesses=$selected
  [ -n "$harnesses" ] || { log "no harness has a test matching '$FILTER'"; echo "canvm: 0 passed, 1 failed"; exit 1; }
fi

# Python with python-canopen, only when a selected test needs it (tests named `…canopen…`).
PY_WANTED=""
for h in $harnesses; do
  if "$h" --list --include-ignored "$FILTER" 2>/dev/null | grep -E ': test$' | grep -q canopen; then PY_WANTED=1; fi
done
if [ -n "$PY_WANTED" ]; then
  pybin=$(command -v "${CANVM_PYTHON:-python3}") || { log "CANVM_PYTHON=${CANVM_PYTHON:-python3} not found"; echo "canvm: 0 passed, 1 failed"; exit 1; }
  # The interpreter itself (pyenv's python3 is a shim), its stdlib and its version.
  read -r PYEXE PYSTD PYVER < <("$pybin" -c 'import os,sys,sysconfig; print(os.path.realpath(sys.executable), sysconfig.get_paths()["stdlib"], "%d.%d" % sys.version_info[:2])')
  "$PYEXE" -c 'import socket; socket.AF_CAN; socket.CAN_RAW; socket.CAN_BCM' ||
    { log "$PYEXE: the socket module has no AF_CAN (python-can's socketcan interface needs it)"; echo "canvm: 0 passed, 1 failed"; exit 1; }
  PYSITE="$WORK/python/site-$PYVER"
  req="$ROOT/tests/canvm/requirements.txt"
  if [ ! -f "$PYSITE/.installed" ] || ! cmp -s "$req" "$PYSITE/.installed"; then
    log "python-canopen for $PYEXE (wheels cached in $WORK/python/wheels)"
    "$PYEXE" -m pip download -q -d "$WORK/python/wheels" -r "$req" ||
      { log "pip download of $req failed"; echo "canvm: 0 passed, 1 failed"; exit 1; }
    rm -rf "$PYSITE"
    "$PYEXE" -m pip install -q --no-index --find-links "$WORK/python/wheels" --target "$PYSITE" -r "$req"
    cp "$req" "$PYSITE/.installed"
  fi
fi

# 4. initramfs.
IR="$WORK/initramfs"
rm -rf "$IR" && mkdir -p "$IR"/{bin,sbin,tests,proc,sys,dev,tmp,mods,dev/shm,run}
cp /bin/busybox "$IR/bin/busybox"
for m in drivers/net/can/dev/can-dev.ko drivers/net/can/vcan.ko drivers/net/can/vxcan.ko net/can/can.ko \
         net/can/can-raw.ko net/can/can-bcm.ko net/can/can-gw.ko; do
  cp "$MODS/$m" "$IR/mods/"
done
for b in "$BINDIR/"*; do
  [ -f "$b" ] && [ -x "$b" ] && cp "$b" "$IR/bin/" || true
done
# The closed-loop tests start these from PATH: make sure they are there when their package is built.
for b in frictiond frictl; do
  case " $PACKAGES " in
    *" $b "*) [ -x "$IR/bin/$b" ] || { log "binary $b missing from the initramfs"; echo "canvm: 0 passed, 1 failed"; exit 1; } ;;
  esac
done
n=0
for h in $harnesses; do
  base=$(basename "$h"); name=${base%-*}; n=$((n+1))
  cp "$h" "$IR/tests/$(printf '%02d' $n)-$name"
done
# Line tables are not needed inside the VM; the guest unpacks the initramfs into RAM.
command -v strip >/dev/null && strip --strip-debug "$IR"/bin/frictl* "$IR"/bin/frictiond* "$IR"/tests/* 2>/dev/null || true
PYINIT=""
if [ -n "$PY_WANTED" ]; then
  # The interpreter at its host path (it finds its stdlib from there); the stdlib without what no
  # test imports (tests, GUI, packaging tools, optimised bytecode); python-canopen and its
  # dependencies in /py/site; the scripts and the EDS file at their host paths (the tests name them
  # from CARGO_MANIFEST_DIR).
  mkdir -p "$IR$(dirname "$PYEXE")" "$IR$PYSTD" "$IR/py"
  cp -L "$PYEXE" "$IR$PYEXE"
  (cd "$PYSTD" && tar -c --exclude=./site-packages --exclude=./test --exclude=./idlelib --exclude=./tkinter \
     --exclude=./turtledemo --exclude=./ensurepip --exclude=./lib2to3 --exclude='./config-*' \
     --exclude=./pydoc_data --exclude=./distutils --exclude='*/tests' --exclude='*.opt-1.pyc' \
     --exclude='*.opt-2.pyc' --exclude='./lib-dynload/_test*' --exclude='./lib-dynload/_tkinter*' .) |
    tar -x -C "$IR$PYSTD"
  cp -a "$PYSITE" "$IR/py/site"
  for f in "$ROOT"/tests/canvm/*.py "$ROOT"/config/*.eds; do
    mkdir -p "$IR$(dirname "$f")" && cp "$f" "$IR$f"
  done
  PYINIT="export FRICTIONLESS_CANVM_PYTHON=$PYEXE PYTHONPATH=/py/site PYTHONDONTWRITEBYTECODE=1"
  log "python $PYVER for the VM: $(du -sm "$IR$PYSTD" | cut -f1) MB stdlib, $(du -sm "$IR/py" | cut -f1) MB site-packages"
fi
if [ "$BUILD" = host ] || [ -n "$PY_WANTED" ]; then
  # Dynamically linked: the ELF interpreter and every library the binaries (and Python with its
  # extension modules) need, at their host paths.
  for f in "$IR"/bin/frictl* "$IR"/bin/frictiond* "$IR"/tests/* ${PY_WANTED:+"$IR$PYEXE"} \
           $( [ -n "$PY_WANTED" ] && find "$IR$PYSTD" "$IR/py" -name '*.so' ); do
    [ -f "$f" ] && ldd "$f" 2>/dev/null | grep -oE '/[^ ]+' || true
  done | sort -u | while read -r lib; do
    [ -e "$lib" ] || continue
    mkdir -p "$IR$(dirname "$lib")"
    cp -L "$lib" "$IR$lib"
  done
fi
cat > "$IR/init" <<INIT
#!/bin/busybox sh
/bin/busybox --install -s /bin
mount -t proc proc /proc; mount -t sysfs sys /sys; mount -t devtmpfs dev /dev
mkdir -p /dev/shm; mount -t tmpfs shm /dev/shm; mount -t tmpfs tmp /tmp
for m in can-dev vcan vxcan can can-raw can-bcm can-gw; do insmod /mods/\$m.ko || echo "insmod \$m failed"; done
ip link set lo up
for i in vcan0 vcan1; do ip link add dev \$i type vcan && ip link set \$i mtu 16 && ip link set \$i up; done
export PATH=/bin:/sbin TMPDIR=/tmp HOME=/tmp FRICTIONLESS_IN_CANVM=1
$PYINIT
rc=0
for t in /tests/*; do
  echo "CANVM_HARNESS: \$t"
  (cd /tmp && \$t --include-ignored --test-threads=1 --show-output $FILTER) || rc=1
done
echo "CANVM_EXIT: \$rc"
sync; poweroff -f
INIT
chmod +x "$IR/init"
(cd "$IR" && find . | cpio -o -H newc --quiet | gzip -1 > "$WORK/initrd.img")
log "initramfs $(du -sm "$IR" | cut -f1) MB unpacked, $(du -m "$WORK/initrd.img" | cut -f1) MB compressed; VM memory ${CANVM_MEM_MB:-2048} MB"

# 5. Boot. KVM only if it can really work (PVM hosts advertise /dev/kvm but cannot boot a stock kernel).
accel=${CANVM_ACCEL:-auto}
if [ "$accel" = auto ]; then
  accel=tcg
  if [ -w /dev/kvm ] && grep -qE 'vmx|svm' /proc/cpuinfo && ! grep -q '^kvm_pvm' /proc/modules; then accel=kvm; fi
fi
if [ "$accel" = kvm ]; then acc=(-accel kvm -cpu host); else acc=(-accel tcg,thread=multi -cpu max); fi
log "booting ($accel), timeout ${TIMEOUT}s"
set +e
timeout "$TIMEOUT" qemu-system-x86_64 -machine q35 -m "${CANVM_MEM_MB:-2048}" -smp 1 -nographic -no-reboot -nic none \
  -kernel "$KDIR/vmlinuz" -initrd "$WORK/initrd.img" "${acc[@]}" \
  -append "console=ttyS0 quiet panic=-1 oops=panic" > "$WORK/console.log" 2>&1
qrc=$?
log "VM exited (qemu rc $qrc)"
set -e
tr -d '\r' < "$WORK/console.log" | sed 's/\x1b\[[0-9;?]*[a-zA-Z]//g; s/\x1bc//g' > "$WORK/console.txt"
grep -E '^(test |CANVM_|running|insmod|thread|---- |  left|  right|failures)' "$WORK/console.txt" || true
# Each failing test's own output (its panic message and what it printed), up to 120 lines each.
awk '/^---- .* stdout ----$/ { n = 0; keep = 1 } /^(failures|successes):$/ { keep = 0 }
     keep && /panicked at/ { show = 1 } keep { buf[n++] = $0 }
     /^(failures|successes):$/ && show { for (k = 0; k < n && k < 120; k++) print "| " buf[k]; show = 0; n = 0 }' \
  "$WORK/console.txt" || true
# Benchmarks inside the VM print lines starting with `bench:` (shown by --show-output): echo them.
grep -E '^bench:' "$WORK/console.txt" | tee "$WORK/bench.txt" || true
passed=$(grep -cE '^test .* \.\.\. ok$' "$WORK/console.txt" || true)
failed=$(grep -cE '^test .* \.\.\. FAILED$' "$WORK/console.txt" || true)
status=0
if ! grep -q '^CANVM_EXIT: 0' "$WORK/console.txt"; then
  status=1
  grep -q '^CANVM_EXIT' "$WORK/console.txt" || { log "VM did not finish (qemu rc $qrc); see $WORK/console.txt"; failed=$((failed+1)); }
fi
[ "$passed" -gt 0 ] || { log "no test ran in the VM"; status=1; }
[ "$failed" -eq 0 ] || status=1
echo "canvm: $passed passed, $failed failed"
exit $status
