#!/usr/bin/env bash
# Run a command with a virtual SocketCAN interface vcan0 up.
#
#   tools/vcan_bench.sh COMMAND [ARGS...]
#
# * On a host whose kernel has SocketCAN (AF_CAN sockets and the vcan module), vcan0 is
#   set up with tools/setup_vcan.sh and COMMAND runs natively.
# * Otherwise COMMAND runs inside User-Mode Linux (Debian package user-mode-linux: a Linux
#   kernel that runs as an ordinary process, with can.ko, can-raw.ko, can-dev.ko and
#   vcan.ko under /usr/lib/uml/modules/<version>/kernel/). The guest mounts this machine's
#   root file system (hostfs), loads the four modules, brings vcan0 up and runs COMMAND in
#   the caller's working directory with the caller's environment (PATH, the venv, ...);
#   its exit status is handed back through a file on hostfs. The guest has one slow CPU
#   (a Python start takes 10-15 s there): use it to prove function, measure speed natively.
#
# The missing Debian packages (user-mode-linux, can-utils, kmod, iproute2) are installed
# when running as root (tools/system_deps.sh). Set VCAN_BENCH=uml to force the guest and
# VCAN_BENCH_MEM (default 1G) for its memory. Exit status: COMMAND's, or 3 when the bench
# itself cannot run (the reason on stderr).
set -euo pipefail
HERE="$(cd "$(dirname "$0")" && pwd)"
if [[ $# -eq 0 ]]; then
  echo "usage: tools/vcan_bench.sh COMMAND [ARGS...]" >&2
  exit 3
fi

have_socketcan() {
  python3 - <<'EOF' 2>/dev/null
import socket, sys
try:
    socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW).close()
except (AttributeError, OSError):
    sys.exit(1)
EOF
}

if [[ "${VCAN_BENCH:-auto}" != "uml" ]] && have_socketcan; then
  if [[ ! -e /sys/class/net/vcan0 ]]; then
    sh "$HERE/setup_vcan.sh" vcan0 >/dev/null || exit 3
  fi
  exec "$@"
fi

bash "$HERE/system_deps.sh" || true
if ! command -v linux.uml >/dev/null 2>&1; then
  echo "error: no SocketCAN in this kernel and no User-Mode Linux (apt-get install user-mode-linux)" >&2
  exit 3
fi
MODDIR=$(ls -d /usr/lib/uml/modules/*/kernel 2>/dev/null | sort -V | tail -n 1)
if [[ -z "$MODDIR" ]]; then
  echo "error: no User-Mode Linux modules under /usr/lib/uml/modules" >&2
  exit 3
fi

WORK=$(mktemp -d /tmp/vcan-bench.XXXXXX)
GUEST=""
cleanup() {
  # the guest runs in its own process group (setsid): end all its host processes
  if [[ -n "$GUEST" ]]; then kill -9 -- "-$GUEST" 2>/dev/null || true; fi
  rm -rf "$WORK"
}
trap cleanup EXIT
trap 'exit 130' INT TERM
# the caller's environment and command, re-read by the guest (hostfs shares /tmp)
export -p >"$WORK/env.sh"
{
  printf 'cd %q || exit 126\n' "$PWD"
  printf 'exec'
  printf ' %q' "$@"
  printf '\n'
} >"$WORK/cmd.sh"
cat >"$WORK/init.sh" <<EOF
#!/bin/bash
# init of the User-Mode Linux guest (PID 1): kernel modules, vcan0, the command, power off
export PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin
mount -t proc proc /proc
mount -t sysfs sysfs /sys
mount -t tmpfs tmpfs /dev/shm 2>/dev/null
mount -t tmpfs tmpfs /run 2>/dev/null
ip link set lo up
# finit_module(2) (x86_64 system call 313) from perl: kmod's insmod refuses these files
# inside the guest ("Invalid parameters") before it reaches the system call
cd "$MODDIR" && perl -e 'for (@ARGV) { open(my \$f, "<", \$_) or die "\$_: \$!\\n"; my \$p = "\\0";
  syscall(313, fileno(\$f), \$p, 0) == 0 or die "finit_module \$_: \$!\\n" }' \
  net/can/can.ko net/can/can-raw.ko drivers/net/can/dev/can-dev.ko drivers/net/can/vcan.ko
ok=\$?
if [ \$ok = 0 ] && ip link add dev vcan0 type vcan && ip link set up vcan0; then
  # The guest saves and restores user FP state only in the legacy FXSAVE layout (see
  # NOXSTATE below): code using AVX/AVX-512 registers would lose their upper parts at
  # every guest kernel entry (Python then spins at start). glibc, NumPy and OpenBLAS are
  # told to use their SSE code paths, which that layout covers completely.
  ( . "$WORK/env.sh"
    export GLIBC_TUNABLES=glibc.cpu.hwcaps=-AVX512F,-AVX512VL,-AVX512BW,-AVX512DQ,-AVX2,-AVX,-AVX_Fast_Unaligned_Load,-XSAVEC,-XSAVE
    export NPY_DISABLE_CPU_FEATURES="X86_V3 X86_V4 AVX512_ICL AVX512_SPR" OPENBLAS_CORETYPE=Nehalem
    . "$WORK/cmd.sh" ) >"$WORK/out" 2>&1
  echo \$? >"$WORK/status"
else
  echo "error: vcan0 could not be set up in the User-Mode Linux guest" >&2
  echo 3 >"$WORK/status"
fi
sync
poweroff -f
EOF
chmod +x "$WORK/init.sh"
# The host kernel refuses User-Mode Linux 6.1's PTRACE_SETREGSET of the x86 xstate when the
# host CPU's xstate is larger than the guest's buffer (AVX-512, AMX: "userspace - ptrace set
# fp regs failed, errno = 14" and a guest panic). A seccomp filter makes its probe
# PTRACE_GETREGSET(NT_X86_XSTATE) fail, so the guest uses PTRACE_GETFPREGS/SETFPREGS.
NOXSTATE='
import ctypes, os, struct, sys
def ins(code, jt, jf, k):
    return struct.pack("HBBI", code, jt, jf, k)
LD, JEQ, RET = 0x20, 0x15, 0x06
prog = b"".join([
    ins(LD, 0, 0, 4), ins(JEQ, 0, 7, 0xC000003E),      # arch x86_64, else allow
    ins(LD, 0, 0, 0), ins(JEQ, 0, 5, 101),             # ptrace, else allow
    ins(LD, 0, 0, 16), ins(JEQ, 1, 0, 0x4204), ins(JEQ, 0, 2, 0x4205),  # GET/SETREGSET
    ins(LD, 0, 0, 32), ins(JEQ, 1, 0, 0x202),          # NT_X86_XSTATE
    ins(RET, 0, 0, 0x7FFF0000), ins(RET, 0, 0, 0x00050000 | 5)])  # allow / EIO
buf = ctypes.create_string_buffer(prog)
class Fprog(ctypes.Structure):
    _fields_ = [("len", ctypes.c_ushort), ("filter", ctypes.c_void_p)]
fp = Fprog(len(prog) // 8, ctypes.addressof(buf))
libc = ctypes.CDLL(None, use_errno=True)
if libc.prctl(38, 1, 0, 0, 0) != 0 or libc.prctl(22, 2, ctypes.byref(fp), 0, 0) != 0:
    sys.exit("error: cannot install the seccomp filter for User-Mode Linux")
os.execvp(sys.argv[1], sys.argv[1:])
'
# the guest console (kernel messages) goes to a file, shown only when the guest fails
setsid python3 -c "$NOXSTATE" linux.uml mem="${VCAN_BENCH_MEM:-1G}" root=/dev/root \
  rootfstype=hostfs rootflags=/ rw init="$WORK/init.sh" con=null con0=fd:0,fd:1 quiet \
  </dev/null >"$WORK/console" 2>&1 &
GUEST=$!
wait "$GUEST" || true
GUEST=""
cat "$WORK/out" 2>/dev/null || true
if [[ ! -s "$WORK/status" ]]; then
  tail -n 30 "$WORK/console" >&2
  echo "error: the User-Mode Linux guest ended without an exit status" >&2
  exit 3
fi
exit "$(cat "$WORK/status")"
