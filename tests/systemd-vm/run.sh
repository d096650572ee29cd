#!/usr/bin/env bash
# The Debian package's unit under a real systemd: boots a minimal Debian root (this machine's release,
# debootstrap, systemd-sysv as PID 1, Debian's stock kernel and its own initramfs) in QEMU, installs the
# package built by packaging/deb.sh with dpkg inside, and lets tests/systemd-vm/driver.sh (started by a
# oneshot unit in the root, output on the serial console) check it: dpkg's files and conffile, the
# sysusers user, the tmpfiles directory, `systemd-analyze verify` and `security`, start → READY, reload →
# RELOADING → READY with a changed value active, the watchdog killing and restarting a stalled
# (SIGSTOPped) daemon, stop → zero currents and exit status 0.
#
# The root is built once into an ext4 image (`mkfs.ext4 -d`, no mount) and cached under
# $SVM_WORK/base.img, keyed by the release, the package list and the driver unit; each run boots it with
# `snapshot=on` (never written) and gives the package and the driver on a second small disk. Delete
# $SVM_WORK to rebuild.
#
# Usage: bash tests/systemd-vm/run.sh [PATH.deb]   (default: the newest target/debian/frictionless_*.deb;
#        none there → bash packaging/deb.sh builds it)
# Knobs (env): SVM_WORK (default target/systemd-vm), SVM_TIMEOUT seconds for the VM (default 600),
#              SVM_ACCEL (auto|kvm|tcg), SVM_MEM_MB (default 2048), SVM_MIRROR (default: deb.debian.org),
#              SVM_IMAGE_ONLY=1 (build or check the cached root image and stop: CI builds it in the
#              background while cargo works).
# Last line: "systemd-vm: N passed, N failed"; exit code non-zero on any failure or timeout.
set -euo pipefail
cd "$(dirname "$0")/../.."
ROOT=$(pwd)
WORK=${SVM_WORK:-$ROOT/target/systemd-vm}
TIMEOUT=${SVM_TIMEOUT:-600}
MIRROR=${SVM_MIRROR:-http://deb.debian.org/debian}
mkdir -p "$WORK"
log() { echo "systemd-vm: [${SECONDS} s] $*" >&2; }
fail() { log "$*"; echo "systemd-vm: 0 passed, 1 failed"; exit 1; }

# 2. Host tools.
need=""
command -v debootstrap >/dev/null || need="$need debootstrap"
command -v qemu-system-x86_64 >/dev/null || need="$need qemu-system-x86"
command -v mkfs.ext4 >/dev/null || need="$need e2fsprogs"
if [ -n "$need" ]; then
  log "installing$need"
  apt-get update -qq
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends $need >/dev/null
fi

# 3. The cached root image: Debian minbase + systemd as PID 1 + the stock kernel with its initramfs
#    (virtio_blk and ext4 are modules there) + the driver unit.
. /etc/os-release
SUITE=${VERSION_CODENAME:?no VERSION_CODENAME in /etc/os-release}
PKGS=systemd-sysv,udev,dbus,kmod,linux-image-amd64,initramfs-tools,procps
DRIVER_UNIT='[Unit]
Description=systemd-vm test driver (tests/systemd-vm/driver.sh from the second disk)
After=multi-user.target
SuccessAction=poweroff-force
FailureAction=poweroff-force

[Service]
Type=oneshot
ExecStart=/bin/sh -c "mount -o ro /dev/vdb /payload && exec /bin/bash /payload/driver.sh"
StandardOutput=tty
StandardError=tty
TTYPath=/dev/ttyS0

[Install]
WantedBy=multi-user.target'
key=$(printf '%s\n' "$SUITE" "$MIRROR" "$PKGS" "$DRIVER_UNIT" | sha256sum | cut -c1-16)
if [ ! -f "$WORK/base.img" ] || [ "$(cat "$WORK/base.key" 2>/dev/null)" != "$key" ]; then
  log "building the root ($SUITE minbase + $PKGS) with debootstrap"
  rm -rf "$WORK/rootfs" "$WORK/base.img" "$WORK/base.key" "$WORK/vmlinuz" "$WORK/initrd.img"
  debootstrap --variant=minbase --include="$PKGS" "$SUITE" "$WORK/rootfs" "$MIRROR" > "$WORK/debootstrap.log" 2>&1 ||
    { tail -n 20 "$WORK/debootstrap.log" >&2; fail "debootstrap failed (log: $WORK/debootstrap.log)"; }
  R=$WORK/rootfs
  echo svm > "$R/etc/hostname"
  printf '/dev/vda / ext4 rw,errors=remount-ro 0 1\n' > "$R/etc/fstab"
  mkdir -p "$R/payload"
  printf '%s\n' "$DRIVER_UNIT" > "$R/etc/systemd/system/systemd-vm-driver.service"
  ln -sf /etc/systemd/system/systemd-vm-driver.service "$R/etc/systemd/system/multi-user.target.wants/systemd-vm-driver.service"
  # No login prompt on the console the driver writes to.
  ln -sf /dev/null "$R/etc/systemd/system/serial-getty@ttyS0.service"
  ln -sf /dev/null "$R/etc/systemd/system/getty@tty1.service"
  rm -rf "$R"/var/cache/apt/archives/*.deb "$R"/var/lib/apt/lists/*
  kver=$(ls "$R/lib/modules" | sort -V | tail -n1)
  [ -f "$R/boot/vmlinuz-$kver" ] && [ -f "$R/boot/initrd.img-$kver" ] || fail "no kernel/initramfs $kver in the root"
  cp "$R/boot/vmlinuz-$kver" "$WORK/vmlinuz"
  cp "$R/boot/initrd.img-$kver" "$WORK/initrd.img"
  size_mb=$(( $(du -sm "$R" | cut -f1) + 512 ))
  mkfs.ext4 -q -F -L svmroot -d "$R" "$WORK/base.img" "${size_mb}M"
  rm -rf "$R"
  echo "$key" > "$WORK/base.key"
  log "root image $(du -m --apparent-size "$WORK/base.img" | cut -f1) MB (cached in $WORK/base.img)"
else
  log "cached root image $WORK/base.img"
fi

if [ -n "${SVM_IMAGE_ONLY:-}" ]; then
  log "root image ready (SVM_IMAGE_ONLY: no package, no boot)"
  exit 0
fi

# 4. The package.
deb=${1:-}
if [ -z "$deb" ]; then
  deb=$(ls -t target/debian/frictionless_*.deb 2>/dev/null | head -n1 || true)
  if [ -z "$deb" ]; then
    log "no package in target/debian: building it (bash packaging/deb.sh)"
    bash packaging/deb.sh >&2
    deb=$(ls -t target/debian/frictionless_*.deb | head -n1)
  fi
fi
[ -f "$deb" ] || fail "no package at $deb"
log "package $deb ($(du -k "$deb" | cut -f1) KiB)"

# 5. The second disk: the package and the driver.
P=$WORK/payload
rm -rf "$P" && mkdir -p "$P"
cp "$deb" "$P/"
cp tests/systemd-vm/driver.sh "$P/driver.sh"
mkfs.ext4 -q -F -L svmpayload -d "$P" "$WORK/payload.img" "$(( $(du -sm "$P" | cut -f1) + 16 ))M"

# 6. Boot. KVM only if it can really work (as tests/canvm/run.sh decides).
accel=${SVM_ACCEL:-auto}
if [ "$accel" = auto ]; then
  accel=tcg
  if [ -w /dev/kvm ] && grep -qE 'vmx|svm' /proc/cpuinfo && ! grep -qs '^kvm_pvm' /proc/modules; then accel=kvm; fi
fi
if [ "$accel" = kvm ]; then acc=(-accel kvm -cpu host); else acc=(-accel tcg,thread=multi -cpu max); fi
log "booting ($accel, 2 CPUs), timeout ${TIMEOUT}s"
set +e
timeout "$TIMEOUT" qemu-system-x86_64 -machine q35 -m "${SVM_MEM_MB:-2048}" -smp 2 -display none -no-reboot -nic none \
  -serial "file:$WORK/console.log" -monitor none \
  -drive "file=$WORK/base.img,format=raw,if=virtio,snapshot=on" \
  -drive "file=$WORK/payload.img,format=raw,if=virtio,readonly=on" \
  -kernel "$WORK/vmlinuz" -initrd "$WORK/initrd.img" "${acc[@]}" \
  -append "root=/dev/vda rw console=ttyS0 quiet systemd.show_status=0 panic=-1" > "$WORK/qemu.log" 2>&1
qrc=$?
set -e
log "VM exited (qemu rc $qrc)"
tr -d '\r' < "$WORK/console.log" | sed 's/\x1b\[[0-9;?]*[a-zA-Z]//g' > "$WORK/console.txt"

# 7. The driver's verdicts: "svm: PASS name: detail" / "svm: FAIL name: detail", then "svm: DONE".
grep -E '^svm: ' "$WORK/console.txt" >&2 || true
passed=$(grep -cE '^svm: PASS ' "$WORK/console.txt" || true)
failed=$(grep -cE '^svm: FAIL ' "$WORK/console.txt" || true)
status=0
if ! grep -q '^svm: DONE' "$WORK/console.txt"; then
  log "the driver did not finish (qemu rc $qrc); console: $WORK/console.txt"
  tail -n 30 "$WORK/console.txt" >&2
  failed=$((failed + 1))
fi
[ "$passed" -gt 0 ] || { log "no check ran in the VM"; status=1; }
[ "$failed" -eq 0 ] || status=1
echo "systemd-vm: $passed passed, $failed failed"
exit $status
