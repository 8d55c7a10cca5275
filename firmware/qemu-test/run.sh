#!/usr/bin/env bash
# Build the firmware's hardware-free logic for thumbv7em-none-eabihf and run its
# tests and measurement loop on QEMU's mps2-an386 (Cortex-M4F) with semihosting.
# Exits non-zero when a test fails, QEMU times out, or the build fails.
# Prints the test results and "instructions per frame: N" (see firmware/README.md).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
cd "$here"

command -v qemu-system-arm >/dev/null || {
  echo "qemu-system-arm is not installed (apt-get install -y qemu-system-arm)" >&2
  exit 2
}

# The repository root's .cargo/config.toml (flip-link, -Tdefmt.x, --nmagic for
# the board image) is merged with this directory's: RUSTFLAGS replaces every
# configured rustflags list, and the linker is set explicitly.
export RUSTFLAGS="-C link-arg=-Tlink.x"
export CARGO_TARGET_THUMBV7EM_NONE_EABIHF_LINKER=rust-lld
export CARGO_TARGET_DIR="${FOIS_QEMU_TARGET_DIR:-${CARGO_TARGET_DIR:-$here/target}}"

cargo build --release --target thumbv7em-none-eabihf
elf="$CARGO_TARGET_DIR/thumbv7em-none-eabihf/release/fois-qemu-test"

set +e
timeout 300 qemu-system-arm -M mps2-an386 -nographic \
  -semihosting-config enable=on,target=native \
  -icount shift=0 -kernel "$elf"
status=$?
set -e
if [ "$status" -eq 124 ]; then
  echo "QEMU timed out" >&2
fi
exit "$status"
