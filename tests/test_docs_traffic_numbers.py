"""docs/traffic.md's hour-long sweep table against the committed run's tables (docs/results/traffic/): each row's
collisions, equipped-responsible collisions, SSM conflicts, throughput, mean speed, travel time and lane changes are
the CSV's, so the docs cannot drift from the run they quote."""

from __future__ import annotations

import csv
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
RUN = REPO / "docs" / "results" / "traffic"


def _rows() -> dict[str, list[str]]:
    text = (REPO / "docs" / "traffic.md").read_text(encoding="utf-8")
    section = text.split("### The hour-long sweep", 1)[1].split("###", 1)[0]
    return {cells[0]: cells for line in section.splitlines() if line.startswith("| ") and line[2].isdigit()
            for cells in [[c.strip() for c in line.strip("|").split("|")]]}  # fmt: skip


def test_the_hour_long_sweep_table_is_the_committed_run():
    docs = _rows()
    with open(RUN / "cells.csv", newline="") as f:
        runs = list(csv.DictReader(f))
    assert len(runs) == 5 and len(docs) == 5
    for r in runs:
        p = f"{float(r['p']):g}"
        d = docs[p]
        assert d[1] == r["collisions"] and d[2] == r["collisions_equipped_responsible"], p
        assert d[3] == f"{r['ssm_conflicts']} ({r['ssm_ttc']} / {r['ssm_drac']} / {r['ssm_pet']})", p
        assert d[4] == f"{float(r['throughput_vph']):,.0f}", p
        assert d[5] == f"{float(r['mean_speed_mps']):.2f}" and d[6] == f"{float(r['mean_travel_time_s']):.1f}", p
        if float(r["p"]) > 0:
            lc = [f"{int(r[k]):,}" for k in ("lc_started", "lc_completed", "lc_aborted", "lc_gave_up")]
            assert d[7] == " / ".join(lc) and d[8] == r["lc_return_late"], p
    assert all(r["collisions_equipped_responsible"] == "0" for r in runs)  # the claim, on the committed run
    with open(RUN / "collisions.csv", newline="") as f:
        assert sum(1 for _ in csv.DictReader(f)) == sum(int(r["collisions"]) for r in runs)
