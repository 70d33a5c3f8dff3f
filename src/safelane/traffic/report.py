"""The report of ``safelane traffic``: the cells table, conflicts and throughput against the penetration rate
(``report.md`` and ``report.html`` through :mod:`safelane.reporting`)."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

SHOWN = (("p", "p", "{:g}"), ("demand_vph", "demand [veh/h]", "{:.0f}"), ("collisions", "collisions", "{:d}"),
         ("collisions_equipped_responsible", "equipped responsible", "{:d}"), ("ssm_conflicts", "SSM conflicts",
         "{:d}"), ("throughput_vph", "throughput [veh/h]", "{:.0f}"), ("mean_speed_mps", "mean speed [m/s]",
         "{:.2f}"), ("mean_travel_time_s", "travel time [s]", "{:.1f}"), ("lc_started", "shielded LC started",
         "{:d}"), ("lc_completed", "completed", "{:d}"), ("lc_aborted", "aborted", "{:d}"))  # fmt: skip


def rows(table: pd.DataFrame) -> list[list[str]]:
    out = []
    for _, r in table.iterrows():
        out.append([fmt.format(int(r[c]) if fmt == "{:d}" else float(r[c])) for c, _, fmt in SHOWN])
    return out


def figure(table: pd.DataFrame, out_dir: Path, stem: str = "traffic") -> list[Path]:
    from ..reporting.figures import _figure, _save

    fig, (a, b) = _figure(2, width=4.2, height=3.2)
    for q, part in table.groupby("demand_vph"):
        part = part.sort_values("p")
        a.plot(part["p"], part["ssm_conflicts"], "o-", label=f"{q:.0f} veh/h SSM conflicts")
        a.plot(part["p"], part["collisions"], "s--", label=f"{q:.0f} veh/h collisions")
        b.plot(part["p"], part["throughput_vph"], "o-", label=f"{q:.0f} veh/h")
    a.set_xlabel("penetration p of equipped vehicles")
    a.set_ylabel("count per run")
    a.legend(fontsize=7)
    b.set_xlabel("penetration p of equipped vehicles")
    b.set_ylabel("throughput [veh/h]")
    b.legend(fontsize=7)
    return _save(fig, out_dir, stem)


def write(run_dir: Path, table: pd.DataFrame, command: str) -> tuple[Path, Path]:
    from ..reporting.document import Document

    doc = Document("Traffic-level co-simulation in SUMO")
    doc.paragraph(f"Command: `{command}`. Network, demand, equipped behaviour and the measures: docs/traffic.md.")
    doc.table([label for _, label, _ in SHOWN], rows(table))
    paths = figure(table, Path(run_dir) / "figures")
    doc.image(paths[0], f"figures/{paths[0].name}", "SSM conflicts and collisions (SUMO's list), and throughput, "
              "against the penetration rate.")  # fmt: skip
    md, page = Path(run_dir) / "report.md", Path(run_dir) / "report.html"
    md.write_text(doc.to_markdown(), encoding="utf-8")
    page.write_text(doc.to_html(), encoding="utf-8")
    return md, page
