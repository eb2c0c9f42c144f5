"""Run the numeric tests (`-m numeric`) as a machine with another CPU would: another OpenBLAS
kernel than the one this machine's main test run uses, and numpy's baseline SIMD only.

A figure's last digits depend on the BLAS kernel and the vector instructions that computed it,
so a test comparing figures bit for bit passes on the machine that wrote them and fails on the
next one. `make test` runs this before its main pytest run, so that such a test fails here.
The kernel is picked, not fixed: the first of `KERNELS` this CPU runs whose kernel differs from
the current one (`OPENBLAS_CORETYPE` may be set already). Prescott is OpenBLAS's generic x86-64
kernel; Nehalem needs only SSE4.2, which numpy's own baseline (x86-64-v2) needs too. Off
x86-64, or with a numpy not on OpenBLAS, it says why and runs them on the machine's own (the
main run leaves the numeric tests to this one).

    python tests/other_kernel.py [PYTEST ARGS...]
"""

from __future__ import annotations

import os
import platform
import subprocess
import sys
from pathlib import Path
from typing import NamedTuple

# (OPENBLAS_CORETYPE, the /proc/cpuinfo flag it needs)
KERNELS = (("Prescott", "pni"), ("Nehalem", "sse4_2"), ("Sandybridge", "avx"), ("Haswell", "avx2"))
PROBE = (
    "import numpy, threadpoolctl; "
    "print(' '.join(i['architecture'] for i in threadpoolctl.threadpool_info() "
    "if i['internal_api'] == 'openblas'))"
)
REPO = Path(__file__).resolve().parent.parent


def kernel(env: dict[str, str]) -> str:
    """The OpenBLAS kernel numpy runs under `env` ('' if it uses no OpenBLAS); scipy's own
    OpenBLAS reads the same variable."""
    probe = [sys.executable, "-c", PROBE]
    out = subprocess.run(probe, env=env, capture_output=True, text=True, check=True, timeout=60)
    names = set(out.stdout.split())
    return " ".join(sorted(names))


def cpu_flags() -> set[str]:
    for line in Path("/proc/cpuinfo").read_text(encoding="utf-8").splitlines():
        if line.startswith("flags"):
            return set(line.split(":", 1)[1].split())
    return set()


def simd_off() -> str:
    """NPY_DISABLE_CPU_FEATURES naming every SIMD extension numpy dispatches to on this CPU
    beyond its baseline (empty if numpy does not say)."""
    try:
        from numpy._core._multiarray_umath import (  # type: ignore[attr-defined]
            __cpu_dispatch__,
            __cpu_features__,
        )
    except ImportError:
        return ""
    return " ".join(f for f in __cpu_dispatch__ if __cpu_features__.get(f))


class Choice(NamedTuple):
    """The second run's environment, and what it differs in from the main run's."""

    env: dict[str, str]
    coretype: str
    kernel: str
    current: str
    simd_off: str


def choose(env: dict[str, str]) -> Choice | str:
    """The environment of the second run, or why there is none on this machine."""
    if platform.machine().lower() not in ("x86_64", "amd64"):
        return f"the kernels picked from are x86-64 ones; this is {platform.machine()}"
    current = kernel(env)
    if not current:
        return "numpy and scipy use no OpenBLAS here"
    flags = cpu_flags()
    for name, flag in KERNELS:
        if flag in flags:
            other = {**env, "OPENBLAS_CORETYPE": name}
            chosen = kernel(other)
            if chosen != current:
                off = simd_off()
                if off:
                    other["NPY_DISABLE_CPU_FEATURES"] = off
                return Choice(other, name, chosen, current, off)
    return f"no kernel of {[k for k, _ in KERNELS]} differs from {current}"


def main(pytest_args: list[str]) -> int:
    choice = choose(dict(os.environ))
    say = "numeric tests on another OpenBLAS kernel than this machine's:"
    command = [sys.executable, "-m", "pytest", "-m", "numeric", "-p", "no:cacheprovider"]
    if isinstance(choice, str):  # the main run leaves them to this one: they run here anyway
        print(f"{say} none, {choice}; they run on this machine's own", flush=True)
        return subprocess.run([*command, *pytest_args], cwd=REPO, check=False).returncode
    simd = f"numpy without {choice.simd_off}" if choice.simd_off else "numpy's SIMD as here"
    print(
        f"{say} {choice.kernel} (OPENBLAS_CORETYPE={choice.coretype}; the main run's: "
        f"{choice.current}), {simd}",
        flush=True,
    )
    done = subprocess.run([*command, *pytest_args], env=choice.env, cwd=REPO, check=False)
    return done.returncode


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
