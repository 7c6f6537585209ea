"""Seed specifications: 0, 0-19, 1,5,9."""
import pytest

from benchmarks.cli import main
from benchmarks.seeds import format_seeds, parse_seeds
from dynamics.validation import InvalidParameterError


@pytest.mark.parametrize("text, seeds", [
    ("0", (0,)),
    ("0-19", tuple(range(20))),
    ("1,5,9", (1, 5, 9)),
    ("0-2,7,3", (0, 1, 2, 7, 3)),
    ("4,4,2-4", (4, 2, 3)),
    (" 1, 2 ", (1, 2)),
])
def test_parse(text, seeds):
    assert parse_seeds(text) == seeds


@pytest.mark.parametrize("text", ["", "a", "-1", "1-", "3-1", "1,,2", "1.5", "0-2-4", "1;2"])
def test_malformed_rejected_with_rule(text):
    with pytest.raises(InvalidParameterError, match=r"must be N, N-M or N,M"):
        parse_seeds(text)


def test_round_trip():
    for seeds in [(0,), (0, 1, 2, 3, 7), (5, 9, 10, 11)]:
        assert parse_seeds(format_seeds(seeds)) == seeds


@pytest.mark.parametrize("command", ["tune", "landscape"])
@pytest.mark.parametrize("spec", ["x", "5-2", "1,,2"])
def test_cli_rejects_malformed_seeds(tmp_path, capsys, command, spec):
    out = tmp_path / "out"
    assert main([command, "--seeds", spec, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("attitude-bench: error: argument --seeds: seeds = ")
    assert len(err.splitlines()) == 1 and not out.exists()
