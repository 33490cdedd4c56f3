"""A workaround for pythonfmu's exit-time double release on Linux (pythonfmu 0.7; upstream PythonFMU
issue #228 reports the abort, no release fixes it).

pythonfmu's linux64 binary keeps its Python state in a global `std::shared_ptr` and also registers a
library destructor, `finalizePythonInterpreter`, that assigns nullptr to it. glibc never unloads the
library (it has UNIQUE symbols), so at process exit the shared_ptr's static destructor runs first and
frees its control block, and then the library destructor decrements the count in that freed block:
a use-after-free that valgrind reports in every process that loaded such an FMU, and that glibc
sometimes catches as heap corruption ("corrupted double-linked list", exit code 134).

`without_exit_release(binary)` makes `finalizePythonInterpreter` return at once (its first instruction
after `endbr64`, `push rbp`, becomes `ret`), so the static destructor alone releases the state. It
patches only the exact instruction bytes it knows and refuses a binary whose function starts
otherwise (another pythonfmu build): the FMU builder then stops rather than ship an unchecked patch.
"""
from __future__ import annotations

import struct

SYMBOL = b"finalizePythonInterpreter"
KNOWN_PROLOGUE = bytes.fromhex("f30f1efa55")  # endbr64; push rbp
RET = 0xC3
SHT_DYNSYM = 11


class ExitPatchError(ValueError):
    """A pythonfmu binary whose exit function is not the one this workaround knows."""


def _symbol_offset(elf: bytes, name: bytes) -> int | None:
    """The file offset of the dynamic symbol `name` in a little-endian ELF64 file, or None."""
    if elf[:4] != b"\x7fELF" or elf[4] != 2 or elf[5] != 1:
        raise ExitPatchError("not a little-endian 64-bit ELF file")
    shoff, = struct.unpack_from("<Q", elf, 0x28)
    shentsize, shnum = struct.unpack_from("<HH", elf, 0x3A)
    sections = [struct.unpack_from("<IIQQQQIIQQ", elf, shoff + i * shentsize) for i in range(shnum)]
    for sh_type, sh_offset, sh_size, sh_link, sh_entsize in ((s[1], s[4], s[5], s[6], s[9]) for s in sections):
        if sh_type != SHT_DYNSYM or sh_entsize == 0:
            continue
        strings = sections[sh_link][4]
        for k in range(sh_size // sh_entsize):
            st_name, _, _, st_shndx, st_value, _ = struct.unpack_from("<IBBHQQ", elf, sh_offset + k * sh_entsize)
            end = elf.index(b"\0", strings + st_name)
            if elf[strings + st_name:end] == name and 0 < st_shndx < shnum:
                section = sections[st_shndx]
                return st_value - section[3] + section[4]
    return None


def without_exit_release(binary: bytes) -> bytes:
    """`binary` (a pythonfmu linux64 shared library) with finalizePythonInterpreter returning at once;
    unchanged where it has no such function. Raises ExitPatchError where the function does not
    start with the instructions this workaround knows."""
    offset = _symbol_offset(binary, SYMBOL)
    if offset is None:
        return binary
    if binary[offset:offset + len(KNOWN_PROLOGUE)] != KNOWN_PROLOGUE:
        raise ExitPatchError("pythonfmu's finalizePythonInterpreter is not the known build (pythonfmu 0.7): "
                             "its exit-time double release cannot be worked around")
    patched = bytearray(binary)
    patched[offset + len(KNOWN_PROLOGUE) - 1] = RET
    return bytes(patched)
