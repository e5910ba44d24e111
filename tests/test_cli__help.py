"""Help texts show what was written (issue #25 item 3): rich markup ate bracketed words
(``Write the  of a design``); every ``[...]`` of a command's docstring and option helps
appears in its ``--help``."""

from __future__ import annotations

import re

import pytest
from typer.main import get_command
from typer.testing import CliRunner

from flexarm.cli import app

runner = CliRunner()
GROUP = get_command(app)
BRACKETED = re.compile(r"\[[^\[\]]+\]")


def _flat(text: str) -> str:
    return " ".join(text.split())


def _bracketed(cmd) -> list[str]:
    texts = [cmd.help or ""] + [getattr(p, "help", None) or "" for p in cmd.params]
    return [m for t in texts for m in BRACKETED.findall(_flat(t))]


@pytest.mark.parametrize("name", sorted(GROUP.commands))
def test_help_shows_every_bracketed_word(name):
    r = runner.invoke(app, [name, "--help"], terminal_width=100)
    assert r.exit_code == 0, r.output
    shown = _flat(r.stdout)
    missing = [w for w in _bracketed(GROUP.commands[name]) if w not in shown]
    assert not missing, missing


def test_the_bracketed_words_are_there_to_be_lost():
    """The test above is not empty: the commands' texts hold bracketed words (units, TOML
    tables), and the one the issue found is shown."""
    words = {n: _bracketed(c) for n, c in GROUP.commands.items()}
    assert sum(map(len, words.values())) >= 3, words
    assert "[controller]" in words["export-c"]
    r = runner.invoke(app, ["export-c", "--help"], terminal_width=100)
    assert "Write the [controller] of a design" in _flat(r.stdout)


def test_top_level_help_lists_every_command_and_version():
    r = runner.invoke(app, ["--help"], terminal_width=100)
    assert r.exit_code == 0
    for name in GROUP.commands:
        assert name in r.stdout
    assert "--version" in r.stdout
