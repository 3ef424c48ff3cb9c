"""--duration of `ellipsled run`, `sim`, `fsw`, `batch` and `report`: a value that is not a
positive finite number of seconds is refused by the parser, with a message naming the
option, before any process, session or flight starts."""
from __future__ import annotations

import math

import pytest

from ellipsled import cli
from common.argtypes import positive_float

COMMANDS = [["run", "nominal"], ["sim", "nominal"], ["fsw", "nominal"], ["batch", "nominal", "--out", "/nonexistent"],
            ["report", "--out", "/nonexistent"]]
BAD = ["0", "-5", "nan", "inf", "-inf", "ten"]


@pytest.mark.parametrize("cmd", COMMANDS, ids=lambda c: c[0])
@pytest.mark.parametrize("value", BAD)
def test_a_bad_duration_is_refused_naming_the_option(cmd, value, capsys):
    with pytest.raises(SystemExit) as e:
        cli.main(cmd + [f"--duration={value}"])
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert "--duration" in err
    assert ("must be a number" in err) if value == "ten" else ("must be a finite number" in err)


def test_positive_finite_durations_pass_unchanged():
    assert positive_float("12.5") == 12.5
    assert positive_float("1e-3") == 1e-3
    assert math.isclose(positive_float("600"), 600.0)
