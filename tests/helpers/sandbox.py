"""Run a command inside a piece of the service unit's sandbox, set up the way systemd
sets it up, without systemd: ``python tests/helpers/sandbox.py MODE ARGS...`` sets the
restriction, then replaces itself with ``python ARGS...``; exit 77 when this kernel
or machine cannot.

MemoryDenyWriteExecute=yes (no memory both writable and executable, none made
executable later), two ways, as systemd versions differ:

- ``prctl``: the kernel's own (PR_SET_MDWE, Linux 6.3), which systemd 254 and later use;
- ``seccomp``: the filter of earlier systemd versions (Debian 12 has 252), stricter: any
  mprotect adding PROT_EXEC is refused, even to memory that was never writable.

SystemCallFilter= with SystemCallErrorNumber=EPERM:

- ``syscalls=NAME,NAME,...``: every other system call fails with EPERM (the names are
  the unit's groups as ``systemd-analyze syscall-filter`` expands them, resolved to
  x86-64 numbers by the caller).

Each is a classic BPF program written out here (x86-64 system call numbers; another
architecture exits 77).
"""

from __future__ import annotations

import ctypes
import os
import platform
import struct
import sys

PR_SET_SECCOMP, PR_SET_NO_NEW_PRIVS, PR_SET_MDWE, PR_GET_MDWE = 22, 38, 65, 66
PR_MDWE_REFUSE_EXEC_GAIN = 1
SECCOMP_MODE_FILTER = 2
_LD, _JEQ, _JSET, _AND, _RET = 0x20, 0x15, 0x45, 0x54, 0x06  # BPF_LD|W|ABS, JMP|JEQ|K, JMP|JSET|K, ALU|AND|K, RET|K
_ALLOW, _EPERM = 0x7FFF0000, 0x00050000 | 1  # SECCOMP_RET_ALLOW, SECCOMP_RET_ERRNO | EPERM
_PROT_WRITE, _PROT_EXEC, _SHM_EXEC = 2, 4, 0o100000

#: (code, jump if true, jump if false, k); a jump skips that many instructions.
#: seccomp_data: nr at 0, arch at 4, the third argument's low word at 32.
_FILTER = [
    (_LD, 0, 0, 4), (_JEQ, 0, 13, 0xC000003E),  # 0-1: x86-64, else allow (15)
    (_LD, 0, 0, 0),  # 2: the system call
    (_JEQ, 4, 0, 9), (_JEQ, 6, 0, 10), (_JEQ, 5, 0, 329), (_JEQ, 6, 0, 30),  # 3-6: mmap, mprotect, pkey_mprotect, shmat
    (_RET, 0, 0, _ALLOW),  # 7
    (_LD, 0, 0, 32), (_AND, 0, 0, _PROT_WRITE | _PROT_EXEC), (_JEQ, 5, 4, _PROT_WRITE | _PROT_EXEC),  # 8-10: mmap
    (_LD, 0, 0, 32), (_JSET, 3, 2, _PROT_EXEC),  # 11-12: mprotect, pkey_mprotect
    (_LD, 0, 0, 32), (_JSET, 1, 0, _SHM_EXEC),  # 13-14: shmat
    (_RET, 0, 0, _ALLOW), (_RET, 0, 0, _EPERM),  # 15, 16
]


class _Fprog(ctypes.Structure):
    _fields_ = [("len", ctypes.c_ushort), ("filter", ctypes.c_void_p)]


def _allow_only(numbers: list[int]) -> list[tuple[int, int, int, int]]:
    """x86-64: these system calls pass, every other one fails with EPERM."""
    prog = [(_LD, 0, 0, 4), (_JEQ, 1, 0, 0xC000003E), (_RET, 0, 0, _EPERM), (_LD, 0, 0, 0)]
    for nr in sorted(set(numbers)):
        prog += [(_JEQ, 0, 1, nr), (_RET, 0, 0, _ALLOW)]
    return prog + [(_RET, 0, 0, _EPERM)]


def restrict(mode: str) -> bool:
    libc = ctypes.CDLL(None, use_errno=True)
    if mode == "prctl":
        return libc.prctl(PR_SET_MDWE, PR_MDWE_REFUSE_EXEC_GAIN, 0, 0, 0) == 0 and \
            libc.prctl(PR_GET_MDWE, 0, 0, 0, 0) == PR_MDWE_REFUSE_EXEC_GAIN
    if platform.machine() != "x86_64":
        return False
    if mode.startswith("syscalls="):
        program = _allow_only([int(n) for n in mode.partition("=")[2].split(",")])
    else:
        program = _FILTER
    code = ctypes.create_string_buffer(b"".join(struct.pack("HBBI", *ins) for ins in program))
    prog = _Fprog(len(program), ctypes.addressof(code))
    return libc.prctl(PR_SET_NO_NEW_PRIVS, 1, 0, 0, 0) == 0 and \
        libc.prctl(PR_SET_SECCOMP, SECCOMP_MODE_FILTER, ctypes.byref(prog), 0, 0) == 0


if __name__ == "__main__":
    if not restrict(sys.argv[1]):
        sys.exit(77)
    os.execv(sys.executable, [sys.executable, *sys.argv[2:]])
