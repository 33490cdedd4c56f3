"""The platforms an FMU's binaries are built for, their compilers, and how this machine runs them.

An FMU carries one binary per platform under binaries/<folder>/: FMI 2.0 names the folders linux64
and win64, FMI 3.0 uses platform tuples (x86_64-linux, x86_64-windows, aarch64-linux). There is no
FMI 2.0 name for 64-bit ARM Linux, so its FMI 2.0 folder is FMI 3.0's tuple, aarch64-linux.

The host platform (the one this machine runs natively) is built with `gcc`; the others with a cross
compiler when one is installed (Debian: gcc-mingw-w64-x86-64 for win64, gcc-aarch64-linux-gnu for
aarch64-linux), and run here through an emulator where one is installed (wine for win64, qemu-user
for aarch64-linux). `check_linkage` reads a binary's export and import tables (binutils' objdump of
the same toolchain): every FMI function exported, nothing imported beyond the C runtime.
"""
from __future__ import annotations

import os
import platform as host_info
import re
import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path


class PlatformError(ValueError):
    """A platform cannot be used as asked (unknown, no compiler, a binary that links wrongly); one line."""


@dataclass(frozen=True)
class Platform:
    name: str              # the FMI 2.0 binaries folder, and the name --platforms takes
    tuple: str             # the FMI 3.0 platform tuple (its binaries folder)
    compiler: str          # C compiler for this platform's binaries
    extension: str         # shared-library file extension
    shared_flags: tuple    # compiler flags for a shared library (and objects that go into one)
    program_flags: tuple   # compiler flags for a program (the cross-platform harness)
    program_libs: tuple    # libraries a program links (dlopen's)
    emulator: tuple        # command prefix that runs this platform's programs here; () natively
    package: str           # Debian package with the compiler
    emulator_package: str  # Debian package with the emulator
    allowed_imports: tuple  # libraries a binary may import (lower case)

    @property
    def toolchain_prefix(self) -> str:
        """The prefix of the compiler's binutils (x86_64-w64-mingw32-), empty for the host gcc."""
        return self.compiler[: -len("gcc")]

    def folder(self, fmi_version: int) -> str:
        """The binaries/ folder of this platform in an FMU of that FMI version."""
        return self.name if fmi_version == 2 else self.tuple

    def binary_path(self, model_name: str, fmi_version: int) -> str:
        """The binary's path inside an FMU (the modelIdentifier is its file name)."""
        return f"binaries/{self.folder(fmi_version)}/{model_name}{self.extension}"

    def compiler_found(self) -> bool:
        return shutil.which(self.compiler) is not None

    def runs_here(self) -> bool:
        """Whether this machine can run the platform's programs (natively or through its emulator)."""
        return not self.emulator or (shutil.which(self.emulator[0]) is not None and self.compiler_found())

    def run_environment(self) -> dict:
        """Environment for running this platform's programs: wine quiet, in its own prefix
        ($WINEPREFIX if set, else ~/.cache/opfmu/wine: the user's ~/.wine is left alone; wine makes
        the prefix on its first run, in a few seconds)."""
        env = dict(os.environ)
        if self.emulator[:1] == ("wine",):
            env.setdefault("WINEPREFIX", str(Path.home() / ".cache" / "opfmu" / "wine"))
            Path(env["WINEPREFIX"]).parent.mkdir(parents=True, exist_ok=True)
            env["WINEDEBUG"] = "-all"
            env.setdefault("WINEDLLOVERRIDES", "mscoree,mshtml=")  # no Mono/Gecko prompts when the prefix is made
        return env

    def native_path(self, path) -> str:
        """`path` as the platform's programs see it: wine maps / to drive Z:."""
        path = str(Path(path).resolve())
        return "Z:" + path.replace("/", "\\") if self.emulator[:1] == ("wine",) else path


LINUX_IMPORTS = ("libc.so.6", "libm.so.6")
WINDOWS_IMPORTS = ("kernel32.dll", "msvcrt.dll")  # the C runtime MinGW-w64 links by default, and the kernel
# libgcc linked in (no libgcc_s DLL to ship); MinGW-w64's own C99 printf family, linked in, so that
# messages format numbers as glibc does (msvcrt's printf differs, e.g. for NaN); no debug sections
# (MinGW-w64's static libraries bring 200 kB of them)
WINDOWS_FLAGS = ("-static-libgcc", "-D__USE_MINGW_ANSI_STDIO=1", "-s")


def _platforms() -> dict[str, Platform]:
    """The platforms by name, with gcc for the one this machine is."""
    machine = host_info.machine().lower()
    x86 = "gcc" if machine in ("x86_64", "amd64") else "x86_64-linux-gnu-gcc"
    arm = "gcc" if machine in ("aarch64", "arm64") else "aarch64-linux-gnu-gcc"
    return {
        "linux64": Platform("linux64", "x86_64-linux", x86, ".so", ("-fPIC",), (), ("-ldl",),
                            () if x86 == "gcc" else ("qemu-x86_64", "-L", "/usr/x86_64-linux-gnu"),
                            "gcc" if x86 == "gcc" else "gcc-x86-64-linux-gnu", "qemu-user", LINUX_IMPORTS),
        "win64": Platform("win64", "x86_64-windows", "x86_64-w64-mingw32-gcc", ".dll", WINDOWS_FLAGS, WINDOWS_FLAGS, (),
                          ("wine",), "gcc-mingw-w64-x86-64", "wine64", WINDOWS_IMPORTS),
        "aarch64-linux": Platform("aarch64-linux", "aarch64-linux", arm, ".so", ("-fPIC",), (), ("-ldl",),
                                  () if arm == "gcc" else ("qemu-aarch64", "-L", "/usr/aarch64-linux-gnu"),
                                  "gcc" if arm == "gcc" else "gcc-aarch64-linux-gnu", "qemu-user", LINUX_IMPORTS),
    }


PLATFORMS = _platforms()
ALIASES = {"x86_64-linux": "linux64", "x86_64-windows": "win64", "linux-aarch64": "aarch64-linux"}


def host() -> Platform:
    """The platform this machine is (the one whose binaries are loaded here for the kernel check)."""
    if host_info.system() == "Linux":
        for p in PLATFORMS.values():
            if p.compiler == "gcc":
                return p
    raise PlatformError(f"opfmu builds FMUs on Linux x86_64 or aarch64, not on {host_info.system()} "
                        f"{host_info.machine()}")


def optional_tools() -> dict[str, str]:
    """{program: Debian package} of what the platforms other than this machine's need: their cross
    compilers and the emulators that run their binaries here."""
    tools = {}
    for p in PLATFORMS.values():
        if p != host():
            tools[p.compiler] = p.package
            if p.emulator:
                tools[p.emulator[0]] = p.emulator_package
    return tools


def by_name(name: str) -> Platform:
    """The platform of a name (an FMI 2.0 folder or FMI 3.0 tuple); PlatformError for an unknown one."""
    key = ALIASES.get(name.strip(), name.strip())
    if key not in PLATFORMS:
        raise PlatformError(f"unknown platform {name.strip()[:40]!r} (known: {', '.join(PLATFORMS)})")
    return PLATFORMS[key]


def select(spec=None) -> tuple[list[Platform], list[str]]:
    """(the platforms to build, one-line notes on those skipped). spec: None for every platform whose
    compiler is found (the others skipped with a note), or names (a comma-separated string or a
    sequence), each of which must have its compiler (PlatformError otherwise)."""
    if spec is None:
        chosen = [p for p in PLATFORMS.values() if p.compiler_found()]
        notes = [f"note: {p.name} skipped: no {p.compiler} found (Debian package {p.package})"
                 for p in PLATFORMS.values() if not p.compiler_found()]
        return chosen, notes
    names = spec.split(",") if isinstance(spec, str) else list(spec)
    chosen = []
    for name in names:
        p = by_name(name)
        if not p.compiler_found():
            raise PlatformError(f"cannot build for {p.name}: no {p.compiler} found (Debian package {p.package})")
        if p not in chosen:
            chosen.append(p)
    if not chosen:
        raise PlatformError("no platform given")
    return chosen, []


FUNCTION = re.compile(r"FMI([23])_Export\s+(fmi[23]\w+)TYPE\s+(fmi[23]\w+)\s*;")
SECTION = re.compile(r"^(Common Functions|Functions for (?:FMI2 for )?(Model Exchange|Co-Simulation|Scheduled Execution))")


def fmi_functions(headers: Path, fmi_version: int, model_exchange: bool = False) -> list[str]:
    """The functions a co-simulation FMU of that version must export: those fmi2Functions.h or
    fmi3Functions.h declare outside their Model Exchange (and Scheduled Execution) sections; with
    model_exchange (an FMU that also offers Model Exchange) those of the Model Exchange section too."""
    kept = ("Common Functions", "Co-Simulation") + (("Model Exchange",) if model_exchange else ())
    names, section = [], "Common Functions"
    for line in (headers / f"fmi{fmi_version}Functions.h").read_text().splitlines():
        heading = SECTION.match(line.strip())
        if heading:
            section = heading.group(2) or heading.group(1)
        declared = FUNCTION.search(line)
        if declared and declared.group(1) == str(fmi_version) and section in kept:
            names.append(declared.group(3))
    if not names:
        raise PlatformError(f"no FMI {fmi_version} function declarations found in {headers}")
    return names


def _binutil(p: Platform, tool: str) -> str:
    path = shutil.which(p.toolchain_prefix + tool)
    if path is None:
        raise PlatformError(f"no {p.toolchain_prefix + tool} (binutils) to read the {p.name} binary")
    return path


def linkage(binary: Path, p: Platform) -> tuple[set[str], set[str]]:
    """(exported function names, imported libraries in lower case) of a binary, read with the
    platform's binutils (objdump -p; for ELF, nm -D for the exports)."""
    headers = subprocess.run([_binutil(p, "objdump"), "-p", str(binary)], capture_output=True, text=True).stdout
    if p.extension == ".dll":
        imports = {m.lower() for m in re.findall(r"DLL Name:\s*(\S+)", headers)}
        table = headers.partition("[Ordinal/Name Pointer] Table")[2].split("\n\n", 1)[0]
        exports = set(re.findall(r"\[\s*\d+\]\s+(\w+)", table))
    else:
        imports = {m.lower() for m in re.findall(r"NEEDED\s+(\S+)", headers)}
        symbols = subprocess.run([_binutil(p, "nm"), "-D", "--defined-only", str(binary)], capture_output=True,
                                 text=True).stdout
        exports = set(re.findall(r"^\S+\s+T\s+(\w+)$", symbols, re.M))
    return exports, imports


def check_linkage(binary: Path, p: Platform, headers: Path, fmi_version: int, model_exchange: bool = False) -> None:
    """PlatformError unless the binary exports every FMI function of its version (with
    model_exchange: its Model Exchange functions too) and imports only the platform's C runtime (and
    on Windows kernel32)."""
    exports, imports = linkage(binary, p)
    missing = [f for f in fmi_functions(headers, fmi_version, model_exchange) if f not in exports]
    if missing:
        raise PlatformError(f"the {p.name} binary does not export {len(missing)} FMI {fmi_version} functions "
                            f"({', '.join(missing[:4])}...)")
    extra = sorted(imports - set(p.allowed_imports))
    if extra:
        raise PlatformError(f"the {p.name} binary imports {', '.join(extra)} (only {', '.join(p.allowed_imports)} "
                            "may be imported)")
