"""Running an FMU's binaries on every platform this machine can run, and comparing them number for
number.

The harness (c/fmu_harness.c, compiled for each platform) loads one FMU binary, runs a script of FMI
calls and writes each call's status and results, every double as the 16 hex digits of its bit
pattern, so no C runtime's printf or strtod stands between the binary and the comparison. Natively
for the host; under wine for win64, under qemu-user for aarch64-linux. `scenario_script` writes the
standard scenarios (rest, a dip of the first input, random held levels at variable step sizes,
input ramps where the FMU interpolates, directional derivatives, FMU state saved, restored and
serialized, bad values and calls); `compare` finds the largest difference between two runs.

Script grammar (one command per line; doubles as hex bit patterns):
    instantiate NAME GUID RESOURCE|-    debug 0|1    setup START    enter_init    exit_init
    set VR X [VR X ...]    setder VR X [...]    step T H    get VR...    getbool VR...
    dd NU VR... NK VR... SEED...    savestate K    loadstate K    freestate K    serialize K
    lasttime    terminate    reset    free
"""
from __future__ import annotations

import math
import struct
import subprocess
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .binaries import BuildError, compile_c
from .platforms import Platform, host
from .variables import Variable, fmi3_value_references

HARNESS = Path(__file__).parent / "c" / "fmu_harness.c"
# differences between platforms, relative to max(1, |value|): what the shipped FMUs are held to (the
# libm functions and the kernel's vector loops differ in the last bits between C runtimes and CPUs),
# and what stops a build: a binary that computes something else, not a rounding. A barely trained
# operator can amplify a last-bit difference a billionfold over a few hundred steps (3e-9 measured
# after 60 steps of 3 epochs' training), so the build runs short scenarios (BUILD_STEPS each) and
# stops above 1e-6
TOLERANCE = 1e-12
BUILD_TOLERANCE = 1e-6
BUILD_STEPS = 20
RUN_TIMEOUT_S = 300  # a harness run (wine makes its prefix on the first one: seconds)


def hex_double(value: float) -> str:
    """The 16 hex digits of a double's bit pattern (most significant first)."""
    return struct.pack(">d", float(value)).hex()


def double_of(text: str) -> float:
    return struct.unpack(">d", bytes.fromhex(text))[0]


def harness_program(target: Platform, workdir: Path) -> Path:
    """The harness compiled for `target` in workdir (compiled once per folder)."""
    program = workdir / f"fmu_harness-{target.name}{'.exe' if target.extension == '.dll' else ''}"
    if not program.exists():
        compile_c(program, [HARNESS], HARNESS.parent, kind="program", target=target)
    return program


def run_script(target: Platform, binary: Path, script: str, workdir: Path, version: int = 2) -> list[str]:
    """The harness's output lines for `script` on the `target` binary (run through the platform's
    emulator); BuildError when the harness cannot run it to the end."""
    workdir.mkdir(parents=True, exist_ok=True)
    program = harness_program(target, workdir)
    script_path, output = workdir / f"script-{target.name}.txt", workdir / f"output-{target.name}.txt"
    script_path.write_text(script)
    output.unlink(missing_ok=True)
    command = [*target.emulator, str(program), *(["-3"] if version == 3 else []),
               *(target.native_path(p) for p in (binary, script_path, output))]
    try:
        result = subprocess.run(command, capture_output=True, text=True, timeout=RUN_TIMEOUT_S,
                                env=target.run_environment())
    except (OSError, subprocess.TimeoutExpired) as exc:
        raise BuildError(f"cannot run the {target.name} harness ({exc})") from None
    lines = output.read_text().splitlines() if output.exists() else []
    if result.returncode != 0:
        detail = (result.stderr.strip().splitlines() or [f"exit code {result.returncode}"])[-1]
        raise BuildError(f"the {target.name} binary did not run the check script to the end after "
                         f"{len(lines)} lines: {detail[:200]}")
    return lines


@dataclass(frozen=True)
class Comparison:
    numbers: int            # doubles compared
    max_difference: float   # largest |a - b| / max(1, |a|)
    max_abs: float          # largest |a - b|
    differing: int          # doubles not bit-identical
    mismatch: str = ""      # the first line that differs in anything but its doubles (empty: none)

    def within(self, tolerance: float = TOLERANCE) -> bool:
        return not self.mismatch and self.max_difference <= tolerance


def _is_hex_double(token: str) -> bool:
    return len(token) == 16 and all(c in "0123456789abcdef" for c in token)


def compare(reference: list[str], other: list[str]) -> Comparison:
    """Two harness outputs of one script: their doubles compared (NaN equals NaN), every other
    token exactly; log lines by status and category (the message text is not numbers)."""
    numbers = differing = 0
    worst = worst_abs = 0.0
    mismatch = "" if len(reference) == len(other) else f"{len(reference)} lines against {len(other)}"
    for i, (a, b) in enumerate(zip(reference, other)):
        ta, tb = a.split(" "), b.split(" ")
        if ta[0] == "log":
            ta, tb = ta[:3], tb[:3]
        if len(ta) != len(tb):
            mismatch = mismatch or f"line {i + 1}: {a[:80]!r} against {b[:80]!r}"
            continue
        for x, y in zip(ta, tb):
            if _is_hex_double(x) and _is_hex_double(y):
                numbers += 1
                if x == y:
                    continue
                differing += 1
                va, vb = double_of(x), double_of(y)
                if math.isnan(va) or math.isnan(vb):
                    mismatch = mismatch or f"line {i + 1}: NaN against a number"
                    continue
                worst_abs = max(worst_abs, abs(va - vb))
                worst = max(worst, abs(va - vb) / max(1.0, abs(va)))
            elif x != y:
                mismatch = mismatch or f"line {i + 1}: {a[:80]!r} against {b[:80]!r}"
    return Comparison(numbers, worst, worst_abs, differing, mismatch)


def column_differences(reference: list[str], other: list[str], command: str = "get") -> np.ndarray:
    """The largest |a - b| / max(1, |a|) of each value of a command's lines (`get`: each output in
    the order read) over two harness outputs of one script; lines that failed are left out."""
    worst = None
    for a, b in zip(reference, other):
        ta, tb = a.split(" "), b.split(" ")
        if ta[0] != command or ta[1] not in ("0", "1") or len(ta) != len(tb):
            continue
        x = np.array([double_of(t) for t in ta[2:]])
        y = np.array([double_of(t) for t in tb[2:]])
        gap = np.abs(x - y) / np.maximum(1.0, np.abs(x))
        worst = gap if worst is None else np.maximum(worst, gap)
    return np.zeros(0) if worst is None else worst


@dataclass(frozen=True)
class Refs:
    """The value references a script uses, in the FMI version's numbering."""

    inputs: list        # [(vr, start value)]
    outputs: list       # Real outputs' vrs
    derived: list       # outputs that depend directly on inputs and have directional derivatives
    booleans: list      # Boolean outputs' vrs

    @classmethod
    def of(cls, variables: list[Variable], version: int) -> "Refs":
        refs = fmi3_value_references(variables) if version == 3 else {v.name: v.vr for v in variables}
        real = [v for v in variables if v.kind == "Real"]
        return cls([(refs[v.name], float(v.start)) for v in real if v.causality == "input"],
                   [refs[v.name] for v in real if v.causality == "output"],
                   [refs[v.name] for v in real if v.causality == "output" and v.dependencies and v.derivative],
                   [refs[v.name] for v in variables if v.kind == "Boolean" and v.causality == "output"])


class _Script:
    """Builds a script: the FMU's time is tracked as the FMU adds it (t + h in double)."""

    def __init__(self, refs: Refs, guid: str):
        self.refs, self.guid, self.lines, self.t = refs, guid, [], 0.0

    def start(self, name: str) -> None:
        self.t = 0.0
        self.lines += [f"# {name}", f"instantiate {name} {self.guid} -", "debug 1", f"setup {hex_double(0.0)}",
                       "enter_init", "exit_init"]
        self.read()

    def set(self, values) -> None:
        self.lines.append("set " + " ".join(f"{vr} {hex_double(x)}" for (vr, _), x in zip(self.refs.inputs, values)))

    def step(self, h: float, read: bool = True) -> None:
        self.lines.append(f"step {hex_double(self.t)} {hex_double(h)}")
        self.t += h
        if read:
            self.read()

    def read(self) -> None:
        self.lines.append("get " + " ".join(map(str, self.refs.outputs)))
        if self.refs.booleans:
            self.lines.append("getbool " + " ".join(map(str, self.refs.booleans)))

    def derivatives(self) -> None:
        knowns = [vr for vr, _ in self.refs.inputs]
        if not self.refs.derived:  # no output depends directly on an input
            return
        for k in range(len(knowns)):
            seed = " ".join(hex_double(1.0 if j == k else 0.0) for j in range(len(knowns)))
            self.lines.append(f"dd {len(self.refs.derived)} {' '.join(map(str, self.refs.derived))} "
                              f"{len(knowns)} {' '.join(map(str, knowns))} {seed}")

    def end(self) -> None:
        self.lines += ["terminate", "free"]


def _levels(starts: np.ndarray, rng, spread: float) -> np.ndarray:
    """Random input levels near the start values: relative for nonzero starts, absolute at zero."""
    scale = np.where(starts != 0.0, np.abs(starts), 1.0)
    return starts + spread * scale * rng.uniform(-1.0, 1.0, starts.size)


def scenario_script(variables: list[Variable], guid: str, version: int = 2, interpolates: bool = False,
                    seed: int = 0, steps: int = 60) -> str:
    """The standard check scenarios as one script (each its own instance, in turn): rest; a dip of
    the first input to 70 % and back; random held levels at variable step sizes (2-20 ms), with the
    outputs' directional derivatives; input ramps (fmi2SetRealInputDerivatives) where the FMU
    interpolates its inputs; an FMU state saved, run past, restored, run again and round-tripped
    through bytes; bad values and calls (a NaN input, h = 0, a wrong communication point)."""
    refs = Refs.of(variables, version)
    starts = np.array([x for _, x in refs.inputs])
    rng = np.random.default_rng(seed)
    s = _Script(refs, guid)
    s.start("rest")
    for _ in range(steps):
        s.step(0.01)
    s.end()

    s.start("dip")
    for k in range(steps):
        dipped = starts.copy()
        dipped[0] *= 0.7 if 10 <= k < 25 else 1.0
        s.set(dipped)
        s.step(0.01)
    s.end()

    s.start("levels")
    for k in range(steps):
        if k % 7 == 0:
            s.set(_levels(starts, rng, 0.03))
        s.step(float(rng.choice([0.002, 0.005, 0.01, 0.02])))
        if k % 15 == 0:
            s.derivatives()
    s.end()

    if interpolates:
        s.start("ramps")
        for k in range(steps // 2):
            s.set(_levels(starts, rng, 0.02))
            rates = 0.5 * np.where(starts != 0.0, np.abs(starts), 1.0) * rng.uniform(-1, 1, starts.size)
            s.lines.append("setder " + " ".join(f"{vr} {hex_double(r)}" for (vr, _), r in zip(refs.inputs, rates)))
            s.step(0.01)
        s.end()

    s.start("state")
    s.set(_levels(starts, rng, 0.03))
    for _ in range(10):
        s.step(0.01)
    s.lines.append("savestate 0")
    saved_t = s.t
    for _ in range(10):
        s.step(0.01)
    s.lines += ["loadstate 0", "serialize 0", "loadstate 0"]
    s.t = saved_t
    s.read()
    for _ in range(10):
        s.step(0.01)
    s.lines.append("freestate 0")
    s.end()

    s.start("bad")
    s.lines.append("set " + f"{refs.inputs[0][0]} {hex_double(math.nan)}")
    s.lines.append(f"step {hex_double(s.t)} {hex_double(0.0)}")
    s.lines.append(f"step {hex_double(s.t + 1.0)} {hex_double(0.01)}")
    s.step(0.01)
    s.end()
    return "\n".join(s.lines) + "\n"


def cross_check(binaries: dict[Platform, Path], variables: list[Variable], guid: str, version: int, workdir: Path,
                interpolates: bool = False, seed: int = 0) -> dict[str, str]:
    """Runs the standard scenarios (BUILD_STEPS steps each) on the host binary and on every other
    binary this machine can run; returns {platform name: what was found}. BuildError when a
    binary's results differ from the host's in anything but their doubles (a status, a line), or by
    more than BUILD_TOLERANCE."""
    found, runnable = {}, []
    for target in binaries:
        if target == host():
            continue
        if target.runs_here():
            runnable.append(target)
        else:
            found[target.name] = f"not run here (no {target.emulator[0]}: Debian package {target.emulator_package})"
    if not runnable:
        return found
    script = scenario_script(variables, guid, version, interpolates, seed, BUILD_STEPS)
    base = run_script(host(), binaries[host()], script, workdir, version)
    for target in runnable:
        binary = binaries[target]
        result = compare(base, run_script(target, binary, script, workdir, version))
        how = f"under {target.emulator[0]}"
        if not result.within(BUILD_TOLERANCE):
            raise BuildError(f"the {target.name} binary, run {how}, differs from the {host().name} one: "
                             f"{result.mismatch or f'by {result.max_difference:.1e} (> {BUILD_TOLERANCE:g})'}")
        found[target.name] = (f"ran {how}: {result.numbers} numbers, {result.differing} not bit-identical, "
                              f"largest difference {result.max_difference:.1e}")
    return found
