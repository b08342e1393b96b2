"""``--help`` of the commands (config.help_format) and the sweep's unknown-name error (issue 33)."""
import contextlib
import io
import re

import pytest

from biped_sim.cli import main
from biped_sim.config.scenes import NODE_ONLY, load_scene


def help_text(*argv):
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main([*argv, "--help"]) == 0
    return out.getvalue()


@pytest.mark.parametrize("command", ["sweep", "basin", "accuracy", "stability", "replay"])
def test_no_option_says_its_default_twice_or_shows_none(command):
    text = " ".join(help_text(command).split())
    assert "(default: None)" not in text
    assert not re.search(r"\(default: [^)]*\) \(default: ", text), text


def test_replay_help_keeps_its_examples_one_a_line():
    lines = help_text("replay").splitlines()
    assert "  biped-sim replay BAG --rate 0.5 --loop --topics /joint_states /impact" in lines, "\n".join(lines)


def test_every_basin_option_has_help():
    text = help_text("basin")
    backend = text[text.index("  --backend"):].split("\n  -")[0]
    assert "process" in backend and "Ray" in backend, backend


def test_an_unknown_sweep_name_says_the_closest_one_and_no_node_only_name():
    with pytest.raises(ValueError) as err:
        load_scene("walk", overrides={"kpp": 100.0})
    text = str(err.value)
    assert "did you mean 'kp'?" in text, text
    allowed = text.split("allowed: ", 1)[1]
    assert not [n for n in NODE_ONLY if re.search(rf"\b{n}\b", allowed)], allowed


COMMANDS = ["simulate", "accuracy", "stability", "gait", "sweep", "basin", "resim", "inspect", "recover", "replay",
            "animate"]


@pytest.mark.parametrize("command", [None, *COMMANDS])
def test_every_help_fits_an_80_column_terminal(command, monkeypatch):
    """simulate's description was one line of 242 characters, its usage listed the eight methods in
    one 110-character line, animate's description ran to 88 columns."""
    monkeypatch.setenv("COLUMNS", "80")
    lines = help_text(*([command] if command else [])).splitlines()
    assert [line for line in lines if len(line) > 80] == []


def test_stability_help_names_the_cases_and_replay_help_says_what_it_leaves_out():
    from biped_sim.analysis.stability import CASES
    text = " ".join(help_text("stability").split())
    assert all(case.__name__[5:] in text for case in CASES), text
    text = " ".join(help_text("replay").split())
    assert "/tf" in text and "left out" in text and "(default: [])" not in text, text
