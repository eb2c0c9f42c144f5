"""`make test` runs the numeric tests on a second OpenBLAS kernel, before its main run
(tests/other_kernel.py): the kernel it picks is really another one, and the step is there."""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest
from other_kernel import Choice, choose, kernel

REPO = Path(__file__).resolve().parent.parent


def test_the_second_run_uses_another_kernel_than_the_main_run() -> None:
    env = dict(os.environ)
    choice = choose(env)
    if isinstance(choice, str):
        pytest.skip(choice)  # off x86-64, or no OpenBLAS: nothing to choose from
    assert isinstance(choice, Choice)
    assert choice.kernel != choice.current
    assert kernel(choice.env) == choice.kernel  # what the pytest it starts runs under
    assert choice.env["OPENBLAS_CORETYPE"] == choice.coretype


def test_a_set_coretype_is_the_main_runs_and_is_not_picked_again() -> None:
    choice = choose({**os.environ, "OPENBLAS_CORETYPE": "Prescott"})
    if isinstance(choice, str):
        pytest.skip(choice)
    assert choice.coretype != "Prescott" and choice.kernel != choice.current


def make_targets(makefile: str, target: str) -> list[list[str]]:
    """The targets each `$(MAKE)` line of `target`'s recipe runs, in the recipe's order."""
    recipe = re.search(rf"^{target}:.*\n((?:\t.*\n)+)", makefile, re.M)
    assert recipe is not None, f"no recipe for {target}"
    return [
        [word for word in line.split()[1:] if not word.startswith(("-", "$("))]
        for line in recipe[1].splitlines()
        if line.strip().startswith("$(MAKE)")
    ]


def test_make_test_runs_the_numeric_tests_on_another_kernel_then_the_rest() -> None:
    makefile = (REPO / "Makefile").read_text(encoding="utf-8")
    steps = make_targets(makefile, "test")
    assert steps, "`make test` runs no step"
    order = [target for step in steps for target in step]
    assert order[-1] == "pytest"  # its summary line ends the output CI reads
    assert {"lint", "typecheck", "docs"} <= set(order)
    # the numeric run alone, before pytest (beside it, two cores ran both slower)
    assert ["numeric-other-kernel"] in steps
    assert order.index("numeric-other-kernel") < order.index("pytest")
    recipe = re.search(r"^numeric-other-kernel:.*\n\t(.*)$", makefile, re.M)
    assert recipe is not None and "tests/other_kernel.py" in recipe[1]
    # and the main run leaves them to it: each figure checked once, on another kernel
    main = re.search(r"^pytest:.*\n\t(.*)$", makefile, re.M)
    assert main is not None and "-m 'not numeric'" in main[1]


def test_the_numeric_tests_are_the_sciences_figures() -> None:
    marked = {
        p.name
        for p in (REPO / "tests").glob("test_*.py")
        if "pytest.mark.numeric" in p.read_text(encoding="utf-8")
    }
    assert {
        "test_reproduction.py",  # the article's experiments
        "test_docs_reference.py",  # the committed figures
        "test_bn_zero_columns.py",  # Table II
        "test_bn_learning.py",
        "test_bn_inference.py",
        "test_gesture_models.py",  # the HMMs' training
        "test_gesture_streaming.py",
    } <= marked


def test_with_no_other_kernel_the_numeric_tests_still_run(monkeypatch: pytest.MonkeyPatch) -> None:
    """The main run leaves the numeric tests to this one: where no other kernel can be picked
    (another CPU family, no OpenBLAS), they run on the machine's own rather than nowhere."""
    import other_kernel

    ran: list[list[str]] = []

    class Done:
        returncode = 3

    def run(command: list[str], **_: object) -> Done:
        ran.append(command)
        return Done()

    monkeypatch.setattr(other_kernel, "choose", lambda env: "no kernel differs here")
    monkeypatch.setattr(other_kernel.subprocess, "run", run)
    assert other_kernel.main(["-q"]) == 3  # its status is the run's
    (command,) = ran
    assert command[-4:] == ["numeric", "-p", "no:cacheprovider", "-q"]
