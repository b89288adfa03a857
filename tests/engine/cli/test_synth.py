"""``buildingparser synth``: every option documented, outputs written, mistakes are one-line errors (exit 2)."""
from __future__ import annotations

import re

import pytest

from engine.cli import build_parser, main


def test_help_explains_every_option(capsys):
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command").choices["synth"]
    for action in sub._actions:
        if action.option_strings and action.dest != "help":
            assert action.help and len(action.help) > 10, action.option_strings
    for name in ("--seed", "--area-m2", "--rooms", "--floors", "--density", "--yaw", "--offset", "--format", "--png",
                 "--overwrite"):
        assert name in sub.format_help()
    assert "points per m^2 of scanned surface" in sub.format_help()


def test_cli_writes_laz_gt_and_png(tmp_path, client, capsys):
    out = tmp_path / "b.laz"
    rc = main(["synth", str(out), "--rooms", "4", "--density", "80", "--seed", "3", "--png", str(tmp_path / "p.png"),
               "--scheduler", client.scheduler.address])
    assert rc == 0
    text = capsys.readouterr().out
    assert re.search(r"generated [\d,]+ points of 4 spaces .* points/s", text), text
    assert out.exists() and (tmp_path / "gt.json").exists() and (tmp_path / "p.png").exists()


def test_cli_mistakes_exit_2_with_one_line(tmp_path, capsys):
    assert main(["synth", str(tmp_path / "x.zarr"), "--floors", "0"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "floors must be at least 1" in err[0]


def test_cli_hard_adds_the_difficulties_asked_for(tmp_path, client, capsys):
    from tiles.store import open_store

    out = tmp_path / "h.zarr"
    assert main(["synth", str(out), "--rooms", "5", "--density", "60", "--hard", "glass,registration=0.5",
                 "--scheduler", client.scheduler.address]) == 0
    assert open_store(str(out)).doc("ground_truth")["building"]["hardness"] == {"glass": 1.0, "registration": 0.5}
    assert main(["synth", str(tmp_path / "all.zarr"), "--rooms", "5", "--density", "40", "--hard",
                 "--scheduler", client.scheduler.address]) == 0
    assert len(open_store(str(tmp_path / "all.zarr")).doc("ground_truth")["building"]["hardness"]) == 12
    assert main(["synth", str(tmp_path / "x.zarr"), "--hard", "glas"]) == 2
    assert "unknown difficulty" in capsys.readouterr().err


def test_cli_training_yaw_gives_the_building_train_generates(tmp_path, client, monkeypatch):
    """``--training-yaw`` (what ``make model`` uses for its stores) passes train's seeded yaw to the generator."""
    import engine.synth as synth
    from engine.training.synthetic import synthetic_yaw

    seen = []
    real = synth.generate

    def spy(out, **kw):
        seen.append(kw["yaw"])
        return real(out, **kw)

    monkeypatch.setattr(synth, "generate", spy)
    args = ["--rooms", "3", "--density", "40", "--seed", "1103", "--scheduler", client.scheduler.address]
    assert main(["synth", str(tmp_path / "t.zarr"), *args, "--training-yaw"]) == 0
    assert main(["synth", str(tmp_path / "y.zarr"), *args, "--yaw", "12.5"]) == 0
    assert seen == [synthetic_yaw(1103), 12.5] and synthetic_yaw(1103) not in (0.0, 12.5)
    with pytest.raises(SystemExit) as stop:  # one or the other: argparse's usage error
        main(["synth", str(tmp_path / "z.zarr"), "--yaw", "3", "--training-yaw"])
    assert stop.value.code == 2


def test_cli_styles_combine_families_in_one_order_and_refuse_unknown_ones(tmp_path, client, capsys):
    from tiles.store import open_store

    out = tmp_path / "s.zarr"
    assert main(["synth", str(out), "--rooms", "4", "--density", "60", "--styles", "windows, subsampled",
                 "--scheduler", client.scheduler.address]) == 0
    assert open_store(str(out)).meta.sources[0].info["styles"] == "subsampled,windows"
    with pytest.raises(SystemExit) as exit_:
        main(["synth", str(tmp_path / "x.zarr"), "--styles", "varied,baroque"])
    assert exit_.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert "combination of varied, subsampled, windows, doors, furniture, not 'varied,baroque'" in err[-1]
    assert not (tmp_path / "x.zarr").exists()
