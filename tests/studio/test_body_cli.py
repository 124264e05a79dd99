"""`studio model info` and argument checks of `studio model build` (no torch needed)."""

from studio.cli import main


def test_model_info_lists_the_three_models(capsys):
    assert main(["model", "info"]) == 0
    out = capsys.readouterr().out
    for g in ("male", "female", "neutral"):
        assert g in out
    assert " m" in out and "kg" in out


def test_model_build_rejects_too_few_poses(capsys):
    assert main(["model", "build", "--poses", "10", "--out", "unused"]) == 1
    assert "--poses must be at least 80" in capsys.readouterr().err
    assert main(["model", "build", "--train", "5", "--out", "unused"]) == 1
    assert "--train must be at least 40" in capsys.readouterr().err
    assert main(["model", "build", "--wide-poses", "-1", "--out", "unused"]) == 1
    assert "--wide-poses must be 0 or more" in capsys.readouterr().err


def test_model_build_without_the_build_extra_says_what_to_install(monkeypatch, capsys):
    import sys

    monkeypatch.setitem(sys.modules, "fast_simplification", None)
    assert main(["model", "build", "--out", "unused"]) == 1
    assert "model-build extra" in capsys.readouterr().err
