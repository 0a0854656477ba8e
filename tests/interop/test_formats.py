"""One table chooses the importer of every format (twolevel/interop/__init__.py): by suffix, and for
a suffix several formats share (``.xml``) by a marker in the file's first bytes; ``check`` and
``import`` both go through it."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from twolevel.cli import app
from twolevel.interop import FORMATS, Format, format_of

runner = CliRunner()


def test_the_suffix_and_the_marker_choose_the_format(tmp_path: Path) -> None:
    xodr = tmp_path / "town.XODR"
    xodr.write_text("<OpenDRIVE/>")
    cr = tmp_path / "ZAM_A-1_1_T-1.xml"
    cr.write_text('<?xml version="1.0"?>\n<commonRoad timeStepSize="0.1"/>\n')
    other = tmp_path / "pom.xml"
    other.write_text("<project/>")
    assert format_of(xodr).name == "OpenDRIVE"  # type: ignore[union-attr]
    assert format_of(cr).name == "CommonRoad"  # type: ignore[union-attr]
    assert format_of(other) is None
    assert format_of(tmp_path / "missing.xml") is None
    assert format_of(tmp_path / "map.yaml") is None


def test_a_longer_suffix_listed_first_wins(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A row for ``.net.xml`` before ``.xml`` reads ``x.net.xml``; ``x.xml`` still goes to the next row."""
    import twolevel.interop as interop

    net = Format(".net.xml", "twolevel.interop.sumo", "SUMO", b"<net")
    monkeypatch.setattr(interop, "FORMATS", (net, *FORMATS))
    sumo = tmp_path / "city.net.xml"
    sumo.write_text("<net version='1.9'/>")
    cr = tmp_path / "city.xml"
    cr.write_text("<commonRoad/>")
    assert interop.format_of(sumo) == net
    assert interop.format_of(cr).name == "CommonRoad"  # type: ignore[union-attr]


def test_check_and_import_refuse_what_no_importer_reads(tmp_path: Path) -> None:
    other = tmp_path / "pom.xml"
    other.write_text("<project/>")
    checked = runner.invoke(app, ["check", str(other), "-f", "concise"])
    assert checked.exit_code == 2 and "CLI002" in checked.output and "CommonRoad .xml" in checked.output
    imported = runner.invoke(app, ["import", str(other), "--out", str(tmp_path / "out")])
    assert imported.exit_code == 2 and "no importer reads" in imported.output
    assert not (tmp_path / "out").exists()


def test_an_option_of_another_format_is_refused(tmp_path: Path) -> None:
    cr = tmp_path / "s.xml"
    cr.write_text("<commonRoad/>")
    res = runner.invoke(app, ["import", str(cr), "--out", str(tmp_path / "out"), "--include", "shoulder"])
    assert res.exit_code == 2 and "applies to OpenDRIVE" in res.output
    xodr = tmp_path / "m.xodr"
    xodr.write_text("<OpenDRIVE/>")
    res = runner.invoke(app, ["import", str(xodr), "--out", str(tmp_path / "out"), "--rules", "r.stl"])
    assert res.exit_code == 2 and "applies to CommonRoad" in res.output
