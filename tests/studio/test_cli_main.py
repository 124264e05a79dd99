"""The ``studio`` command itself: help for every command, one-line errors, exit codes."""

import subprocess
import sys

import pytest

from studio.cli import CommandError, build_parser, main


def _subcommands():
    parser = build_parser()
    action = next(a for a in parser._actions if a.dest == "command")
    return sorted(action.choices)


def test_help_lists_the_commands(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    names = _subcommands()
    assert {"convert", "session"} <= set(names)
    for name in names:
        assert name in out


@pytest.mark.parametrize("name", _subcommands())
def test_every_command_has_help(name, capsys):
    with pytest.raises(SystemExit) as exc:
        main([name, "--help"])
    assert exc.value.code == 0
    assert f"usage: studio {name}" in capsys.readouterr().out


def test_no_command_prints_help_and_fails(capsys):
    assert main([]) == 2
    assert "usage: studio" in capsys.readouterr().out


def test_errors_are_one_line_with_nonzero_exit(tmp_path):
    missing = tmp_path / "nope.json"
    proc = subprocess.run(
        [sys.executable, "-m", "studio", "convert", str(missing), str(tmp_path / "out.toml")],
        capture_output=True, text=True, timeout=60,
    )
    assert proc.returncode == 1
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith("studio: error:") and "nope.json" in lines[0]
    assert "Traceback" not in proc.stderr


def test_debug_shows_the_traceback(tmp_path):
    proc = subprocess.run(
        [sys.executable, "-m", "studio", "--debug", "convert", str(tmp_path / "nope.json"),
         str(tmp_path / "out.toml")],
        capture_output=True, text=True, timeout=60,
    )
    assert proc.returncode != 0
    assert "Traceback" in proc.stderr


def test_command_error_carries_its_exit_code(monkeypatch, capsys):
    import studio.cli as cli

    def boom(args):
        raise CommandError("the rig has no camera named cam9", code=3)

    parser = cli.build_parser()
    monkeypatch.setattr(cli, "build_parser", lambda: parser)
    parser.set_defaults(func=boom)
    assert cli.main([]) == 3
    assert capsys.readouterr().err.strip() == "studio: error: the rig has no camera named cam9"
