"""Log lines dedupe on what went wrong, not on which frame it happened to (issue 21)."""

from __future__ import annotations

import logging

import pytest

from beyond_self.core.errors import InputError
from beyond_self.runtime.error_account import ErrorAccount, shape


def test_one_problem_repeated_over_many_frames_is_logged_once(
    caplog: pytest.LogCaptureFixture,
) -> None:
    account = ErrorAccount(logging.getLogger("beyond.test"), "test")
    with caplog.at_level(logging.WARNING, "beyond.test"):
        for frame in range(300, 666):  # the 366 lines one restart used to log
            stamp = 1_546_300_800_000_000_000 + frame * 33_333_333
            account.error(
                "beyond/robot/sensors/skeleton",
                InputError(
                    f"skeleton frame {frame} stamped {stamp} is not after the previous frame "
                    f"({stamp + 1}); valid: frames in increasing stamp order"
                ),
            )
        assert "frame 665" in account.last_error  # health still shows the latest
        account.error("beyond/robot/sensors/skeleton", InputError("frame 3 has no joint 'hand'"))
        account.error("beyond/robot/sensors/camera", InputError("frame 3 has no joint 'hand'"))
    logged = [r.fields["reason"] for r in caplog.records if r.name == "beyond.test"]
    assert len(logged) == 3, logged
    assert "frame 300 stamped" in logged[0]  # the first one, as it was
    assert account.errors == 368
    assert account.once.repeats == 365


def test_the_shape_of_a_reason_keeps_its_words_and_drops_its_numbers() -> None:
    assert shape("frame 12 at -3.5e-2 s (x=1.0)") == "frame # at # s (x=#)"
    assert shape("no joint 'hand'") != shape("no joint 'torso'")
