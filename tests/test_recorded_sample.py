"""The shipped US-101 sample: its conversion equals commonroad-io's reading of the XML, its lane changes are all
replayed, and ``safelane replay`` runs unattended on a folder with things that are not scenarios."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from safelane.cli import app
from safelane.recorded import find_lane_changes
from safelane.recorded.store import load_npz, sample_paths

REALDATA = Path(__file__).resolve().parents[2] / "shared" / "realdata"


def test_the_sample_is_shipped_with_its_notice():
    names = [p.name for p in sample_paths()]
    assert names == ["USA_US101-3_3_T-1.npz", "USA_US101-4_1_T-1.npz", "USA_US101-5_1_T-1.npz"]
    notice = (sample_paths()[0].parent / "NOTICE").read_text()
    assert "NGSIM" in notice and "OpenStreetMap" in notice and notice.count("BSD 3-Clause License") == 2


@pytest.mark.parametrize("name", ["USA_US101-3_3_T-1", "USA_US101-4_1_T-1", "USA_US101-5_1_T-1"])
def test_the_conversion_equals_loading_the_xml(name):
    pytest.importorskip("commonroad", reason='commonroad-io is not installed: pip install "safelane[commonroad]"')
    if not (REALDATA / f"{name}.xml").is_file():
        pytest.skip(f"the source XML is not here ({REALDATA})")
    from safelane.recorded import load_commonroad

    xml = load_commonroad(REALDATA / f"{name}.xml")
    npz = load_npz(next(p for p in sample_paths() if p.stem == name))
    assert (xml.dt, xml.t0, xml.frame) == (npz.dt, npz.t0, npz.frame)
    for field in ("vehicle_ids", "x", "y", "speed", "accel", "lane", "length", "width", "valid"):
        assert np.array_equal(getattr(xml, field), getattr(npz, field), equal_nan=field not in ("lane", "valid",
                              "vehicle_ids")), field  # fmt: skip
    for field in ("ids", "y_right", "y_left", "left", "right", "x_start", "x_end"):
        assert np.array_equal(getattr(xml.lanes, field), getattr(npz.lanes, field)), field


def test_the_samples_lane_changes():
    found = {p.stem: [(e.vehicle_id, e.from_lane, e.to_lane) for e in find_lane_changes(load_npz(p))]
             for p in sample_paths()}  # fmt: skip
    assert found == {
        "USA_US101-3_3_T-1": [(394, 3, 2)],
        "USA_US101-4_1_T-1": [(389, 4, 5), (405, 1, 2), (400, 3, 4), (401, 2, 3), (389, 5, 6)],
        "USA_US101-5_1_T-1": [],
    }


def test_replay_on_a_folder_runs_unattended_and_says_what_it_skipped(tmp_path):
    data = tmp_path / "data"
    data.mkdir()
    for p in sample_paths():
        (data / p.name).write_bytes(p.read_bytes())
    (data / "README.txt").write_text("not a scenario\n")
    (data / "broken.xml").write_text("<commonRoad><lanelet></commonRoad>")
    result = CliRunner().invoke(app, ["replay", str(data), "--connected", "0", "--no-progress",
                                      "--out", str(tmp_path / "out")])  # fmt: skip
    assert result.exit_code == 0, result.output
    (run,) = (tmp_path / "out").iterdir()
    assert json.loads((run / "run.json").read_text())["status"] == "complete"
    skipped = (run / "skipped.csv").read_text()
    assert 'README.txt,"not a scenario file' in skipped
    assert "broken.xml" in skipped
    assert "USA_US101-5_1_T-1.npz,no lane change" in skipped
    assert "vehicle 389 at t = 4.1 s,no target-lane vehicle at the crossing" in skipped
    events = (run / "events.csv").read_text().splitlines()
    assert len(events) == 1 + 5  # every lane change with a target-lane vehicle
    html = (run / "report.html").read_text()
    assert html.count("<figure>") == 1 + 5 and "Closed" not in html
    assert "skipped" in result.output
