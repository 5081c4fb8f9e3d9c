"""A real SocketCAN stack for the vcan tests: the host's kernel when it has CAN, else a
throw-away emulated machine.

The machine is a stock Debian kernel (``linux-image-amd64``) booted by
``qemu-system-x86_64`` in software emulation (TCG), with a tiny initramfs (busybox
from ``busybox-static`` and the kernel's own virtio, 9p and CAN modules).  The host's
root file system is shared read-only over 9p and the guest chroots into it, so it runs
this checkout with the host's Python, virtualenv and can-utils; a writable 9p share
(``out``) brings results back.  Packages: ``scripts/debian-packages.txt``.

Used by ``tests/vcan/conftest.py`` and ``benchmarks/bench_can.py``; run directly
(``python tests/vcan/vm.py [--timeout S] [--cpus N] -- COMMAND``) it runs one shell
command on vcan0 (170 s and one virtual CPU unless told otherwise).
"""

from __future__ import annotations

import gzip
import hashlib
import io
import os
import shlex
import shutil
import socket
import stat
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
CACHE = ROOT / "build" / "vcan-vm"

#: Load order matters: insmod does not resolve dependencies.
MODULES = ("virtio_ring", "virtio", "virtio_pci_legacy_dev", "virtio_pci_modern_dev", "virtio_pci",
           "9pnet", "9pnet_virtio", "netfs", "fscache", "9p", "can", "can-raw", "can-dev", "vcan")
TOOLS = ("candump", "cansend", "canplayer")

INIT = r"""#!/bin/busybox sh
/bin/busybox --install -s /bin
export PATH=/bin
mount -t proc proc /proc
mount -t sysfs sys /sys
mount -t devtmpfs dev /dev
for m in $(cat /modules.txt); do insmod /lib/$m.ko || echo "init: insmod $m failed"; done
out=$(sed -n 's/.*eskin_out=\([^ ]*\).*/\1/p' /proc/cmdline)
mount -t 9p -o trans=virtio,version=9p2000.L,ro,msize=512000,cache=loose hostroot /mnt || echo "init: no hostroot"
mount -t 9p -o trans=virtio,version=9p2000.L,msize=512000 out /mnt$out || echo "init: no out share"
mount -t proc proc /mnt/proc
mount -t sysfs sys /mnt/sys
mount -t devtmpfs dev /mnt/dev
mount -t tmpfs run /mnt/run
mkdir -p /mnt/run/tmp
mount -t tmpfs shm /mnt/dev/shm 2>/dev/null
ip link set lo up
ip link add dev vcan0 type vcan && ip link set vcan0 up && echo "init: vcan0 up"
chroot /mnt /bin/sh $out/guest.sh > /mnt$out/console.txt 2>&1
echo $? > /mnt$out/rc
sync
poweroff -f
"""


@dataclass(frozen=True)
class Kernel:
    vmlinuz: Path
    modules: Path  # /usr/lib/modules/VERSION


def find_kernel() -> Kernel | None:
    for vmlinuz in sorted(Path("/boot").glob("vmlinuz-*"), reverse=True):
        version = vmlinuz.name.removeprefix("vmlinuz-")
        mods = Path("/usr/lib/modules") / version
        if mods.is_dir() and os.access(vmlinuz, os.R_OK):
            return Kernel(vmlinuz, mods)
    return None


def native_can() -> bool:
    """True when this kernel speaks SocketCAN (a raw CAN socket can be made)."""
    if not hasattr(socket, "AF_CAN"):
        return False
    try:
        socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW).close()
    except OSError:
        return False
    return True


def native_vcan(channel: str = "vcan0") -> str | None:
    """Make ``channel`` exist and be up on this kernel: "" when it is ready, else the
    reason it cannot be, as text."""
    if not native_can():
        return "this kernel has no SocketCAN"
    net = Path("/sys/class/net") / channel
    if not net.exists():
        for cmd in (["modprobe", "vcan"], ["ip", "link", "add", "dev", channel, "type", "vcan"]):
            try:
                subprocess.run(cmd, capture_output=True, timeout=10)
            except (OSError, subprocess.SubprocessError):
                pass
    if not net.exists():
        return f"{channel} does not exist and cannot be created (needs root and the vcan module)"
    try:
        subprocess.run(["ip", "link", "set", channel, "up"], capture_output=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        pass
    return ""


def missing_prerequisites() -> list[str]:
    missing = [tool for tool in ("qemu-system-x86_64", *TOOLS) if shutil.which(tool) is None]
    if not Path("/bin/busybox").exists() or not _is_static(Path("/bin/busybox")):
        missing.append("busybox-static (/bin/busybox)")
    kernel = find_kernel()
    if kernel is None:
        missing.append("linux-image-amd64 (a readable /boot/vmlinuz-* with its modules)")
    else:
        missing += [f"module {m}" for m in MODULES if _module(kernel, m) is None]
    return missing


def _is_static(path: Path) -> bool:
    try:
        out = subprocess.run(["file", "-L", str(path)], capture_output=True, text=True, timeout=10).stdout
    except (OSError, subprocess.SubprocessError):
        return True  # no `file`: trust the package
    return "statically linked" in out or "static-pie" in out or not out


def _module(kernel: Kernel, name: str) -> Path | None:
    for candidate in (name, name.replace("-", "_")):
        hits = sorted(kernel.modules.glob(f"kernel/**/{candidate}.ko"))
        if hits:
            return hits[0]
    return None


def _cpio(entries: list[tuple[str, int, bytes]]) -> bytes:
    """A newc cpio archive of (name, mode, data); directories have no data."""
    out = io.BytesIO()
    for ino, (name, mode, data) in enumerate([*entries, ("TRAILER!!!", 0, b"")], start=1):
        nlink = 2 if stat.S_ISDIR(mode) else 1
        fields = [ino, mode, 0, 0, nlink, 0, len(data), 0, 0, 0, 0, len(name) + 1, 0]
        head = b"070701" + b"".join(b"%08X" % f for f in fields)
        out.write(head + name.encode() + b"\0")
        out.write(b"\0" * ((-out.tell()) % 4))
        out.write(data)
        out.write(b"\0" * ((-out.tell()) % 4))
    return out.getvalue()


def build_initramfs(cache: Path = CACHE) -> tuple[Kernel, Path]:
    """The initramfs for this host's kernel, built once into ``cache``."""
    kernel = find_kernel()
    if kernel is None:
        raise RuntimeError("no kernel in /boot")
    mods = [(m, _module(kernel, m)) for m in MODULES]
    key = hashlib.sha1((INIT + str(kernel.vmlinuz) + "".join(str(p) for _, p in mods)).encode()).hexdigest()[:12]
    target = cache / f"initramfs-{key}.cpio.gz"
    if target.exists():
        return kernel, target
    cache.mkdir(parents=True, exist_ok=True)
    d, f = stat.S_IFDIR | 0o755, stat.S_IFREG
    entries = [(n, d, b"") for n in ("bin", "dev", "proc", "sys", "mnt", "lib", "tmp")]
    entries.append(("bin/busybox", f | 0o755, Path("/bin/busybox").read_bytes()))
    entries.append(("init", f | 0o755, INIT.encode()))
    entries.append(("modules.txt", f | 0o644, "\n".join(m for m, _ in mods).encode() + b"\n"))
    for name, path in mods:
        assert path is not None
        entries.append((f"lib/{name}.ko", f | 0o644, path.read_bytes()))
    tmp = target.with_suffix(f".{os.getpid()}.tmp")
    tmp.write_bytes(gzip.compress(_cpio(entries), compresslevel=1))
    tmp.replace(target)
    return kernel, target


@dataclass
class GuestRun:
    rc: int | None  #: the guest script's exit code, None if it never finished
    console: str  #: what the guest script printed
    boot_log: str  #: the machine's serial console
    out: Path  #: the writable share, with the script's files
    seconds: float


def run_in_vm(script: str, out: Path, timeout_s: float = 170.0, memory_mb: int = 1024, cpus: int = 1) -> GuestRun:
    """Boot, run ``script`` (sh, in the checkout, vcan0 up) in the host's root, power off.

    ``out`` is shared writable at the same path.  The guest's scratch space is a
    tmpfs at /run/tmp (``TMPDIR``); the host's /tmp stays visible (read-only), so a
    checkout under /tmp works too.
    """
    kernel, initrd = build_initramfs()
    out = out.resolve()
    out.mkdir(parents=True, exist_ok=True)
    for name in ("rc", "console.txt"):
        (out / name).unlink(missing_ok=True)
    env = {
        "PATH": f"{ROOT}/.venv/bin:/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin",
        "HOME": "/run/tmp", "TMPDIR": "/run/tmp", "LANG": "C.UTF-8", "PYTHONDONTWRITEBYTECODE": "1", "ESKIN_VCAN_CHANNEL": "vcan0",
        "ESKIN_VCAN_OUT": str(out), "CI": os.environ.get("CI", ""),
    }
    exports = "".join(f"export {k}={shlex.quote(v)}\n" for k, v in env.items())
    (out / "guest.sh").write_text(f"{exports}cd {shlex.quote(str(ROOT))}\n{script}\n")
    cmd = [
        "qemu-system-x86_64", "-machine", "q35,accel=tcg", "-cpu", "max", "-smp", str(cpus), "-m", str(memory_mb),
        "-nographic", "-no-reboot", "-kernel", str(kernel.vmlinuz), "-initrd", str(initrd),
        "-append", f"console=ttyS0 quiet panic=-1 eskin_out={out}",
        "-virtfs", "local,path=/,mount_tag=hostroot,security_model=none,readonly=on,multidevs=remap",
        "-virtfs", f"local,path={out},mount_tag=out,security_model=none,multidevs=remap",
    ]
    start = time.monotonic()
    try:
        proc = subprocess.run(cmd, capture_output=True, timeout=timeout_s, stdin=subprocess.DEVNULL)
        boot = proc.stdout.decode(errors="replace") + proc.stderr.decode(errors="replace")
    except subprocess.TimeoutExpired as exc:
        boot = (exc.stdout or b"").decode(errors="replace") + f"\n[timed out after {timeout_s:.0f} s]"
    seconds = time.monotonic() - start
    rc_file = out / "rc"
    rc = int(rc_file.read_text().strip()) if rc_file.exists() and rc_file.read_text().strip() else None
    console = (out / "console.txt").read_text(errors="replace") if (out / "console.txt").exists() else ""
    return GuestRun(rc, console, boot, out, seconds)


def main(argv: list[str]) -> int:
    timeout_s, cpus = 170.0, 1
    opts = argv[: argv.index("--") if "--" in argv else len(argv)]
    if "--timeout" in opts:
        timeout_s = float(opts[opts.index("--timeout") + 1])
    if "--cpus" in opts:
        cpus = int(opts[opts.index("--cpus") + 1])
    if "--" in argv:
        argv = argv[argv.index("--") + 1:]
    script = " ".join(shlex.quote(a) for a in argv) or "ip -details link show vcan0"
    missing = missing_prerequisites()
    if missing:
        print(f"vm: missing: {', '.join(missing)}", file=sys.stderr)
        return 2
    run = run_in_vm(script, CACHE / "manual", timeout_s=timeout_s, cpus=cpus)
    sys.stdout.write(run.console)
    print(f"vm: exit {run.rc} after {run.seconds:.1f} s", file=sys.stderr)
    return 1 if run.rc is None else run.rc


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
