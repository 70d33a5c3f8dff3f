"""``safelane replay``: the shield's open-loop verdicts on recorded lane changes → tables and an HTML report."""

from __future__ import annotations

from pathlib import Path

import typer

from . import app


def _files(paths: list[Path]) -> list[Path]:
    """Files as given, directories walked (sorted); a path that does not exist is an input error."""
    out = []
    for path in paths:
        if path.is_dir():
            out += sorted(p for p in path.rglob("*") if p.is_file())
        elif path.is_file():
            out.append(path)
        else:
            raise typer.BadParameter(f"{str(path)!r}: no such file or folder", param_hint="PATH")
    return out


def _shares(text: str) -> list[float]:
    try:
        shares = [float(s) for s in text.split(",") if s.strip()]
    except ValueError:
        shares = []
    if not shares or any(not 0.0 <= s <= 1.0 for s in shares):
        raise typer.BadParameter(f"expected shares in [0, 1] separated by commas (e.g. 0,0.5,1); got {text!r}",
                                 param_hint="--connected")  # fmt: skip
    return shares


@app.command()
def replay(
    paths: list[Path] = typer.Argument(
        None,
        help="CommonRoad scenario XML, NGSIM trajectory files (.csv/.txt), "
        "safelane .npz recordings, or folders of them (default: the shipped sample).",
    ),
    connected: str = typer.Option(
        "0,1",
        "--connected",
        help="Shares of connected vehicles to sweep, comma-separated "
        "(0: none, 1: all; each vehicle drawn with --seed).",
    ),
    preset: str = typer.Option("realistic", "--preset", help="The shield's preset (its Params and settings)."),
    variant: str = typer.Option("CV_all", "--variant", help="The shield's variant."),
    seed: int = typer.Option(0, "--seed", help="Seed of the connectivity draw."),
    out: Path = typer.Option(
        Path("results/replay"), "--out", "-o", help="Parent folder; the run goes to OUT/<run-id>/ (created)."
    ),
    progress: bool = typer.Option(True, "--progress/--no-progress", help="Show a progress bar."),
) -> None:
    """Replay recorded lane changes open loop: every 0.1 s the shield's verdict on what the human did next.

    Writes OUT/<run-id>/ with events.csv (one row per lane change and share), frames.csv (one row per 0.1 s),
    skipped.csv (files and lane changes not replayed, and why), report.html / report.md (summary table, a figure per
    lane change, the distributions) and run.json. Runs unattended on folders: files that are not scenarios,
    unreadable files and files without lane changes are skipped and listed.

    Example: safelane replay                                  (the shipped NGSIM US-101 sample)
    Example: safelane replay data/us101/ --connected 0,0.5,1 --seed 1
    """
    import pandas as pd

    from .._progress import track
    from ..errors import InputError
    from ..recorded.replay import ReplaySettings
    from ..recorded.replay import replay as run_replay
    from ..recorded.store import kind_of, load_recording, sample_paths
    from ..reporting.replay import SUMMARY_HEADER, summary_rows, write_report
    from ..sim.preset import load_preset
    from ._runs import check_out_dir, run_folder, say

    shares = _shares(connected)
    try:
        load_preset(preset)
        ReplaySettings(preset=preset, variant=variant)
        from ..shield import Shield

        Shield.from_preset(preset, variant=variant)
    except ValueError as exc:
        raise typer.BadParameter(str(exc), param_hint="--variant" if "variant" in str(exc) else "--preset") from exc
    files = _files(list(paths)) if paths else sample_paths()
    out = check_out_dir(out)
    settings = {"preset": preset, "variant": variant, "connected_shares": shares, "seed": seed}
    info = {"kind": "replay", "preset": preset, "planners": [variant, "RSS"], "samples": None, "assessment": None,
            "seed": seed, "settings": settings, "inputs": [str(p) for p in files]}  # fmt: skip
    events, rows, skipped, agree = [], [], [], [0, 0]
    with run_folder(out, f"replay-{len(files)}files", info) as (run_dir, info):
        items = track(files, "replaying", total=len(files)) if progress else files
        for path in items:
            if kind_of(path) is None:
                skipped.append((str(path), "not a scenario file (CommonRoad .xml, NGSIM .csv/.txt, .npz)"))
                continue
            try:
                recording = load_recording(path)
            except (InputError, ImportError) as exc:
                skipped.append((str(path), str(exc)))
                continue
            for share in shares:
                result = run_replay(recording, ReplaySettings(preset=preset, variant=variant, connected_share=share,
                                                              seed=seed))  # fmt: skip
                if share == shares[0]:
                    skipped += [(f"{path}: vehicle {e.vehicle_id} at t = {e.crossing_t:.1f} s", why)
                                for e, why in result.skipped]  # fmt: skip
                    if result.events.empty:
                        skipped.append((str(path), "no lane change with a target-lane vehicle" if result.skipped
                                        else "no lane change (a line crossed and held >= 1 s each side)"))  # fmt: skip
                if result.events.empty:
                    continue
                events.append(result.events)
                rows.append(result.rows)
                if result.adrss is not None:
                    agree = [agree[0] + result.adrss[0], agree[1] + result.adrss[1]]
        events_df = pd.concat(events, ignore_index=True) if events else pd.DataFrame()
        rows_df = pd.concat(rows, ignore_index=True) if rows else pd.DataFrame()
        events_df.to_csv(run_dir / "events.csv", index=False)
        rows_df.to_csv(run_dir / "frames.csv", index=False)
        pd.DataFrame(skipped, columns=["what", "why"]).to_csv(run_dir / "skipped.csv", index=False)
        _, page = write_report(run_dir, events_df, rows_df, skipped, settings, tuple(agree) if agree[1] else None)
        info["events"] = len(events_df)
        info["skipped"] = len(skipped)
    for what, why in skipped:
        say(f"skipped {what}: {why}")
    if len(events_df):
        from rich.console import Console
        from rich.table import Table

        table = Table(title=f"{len(events_df) // len(shares)} lane changes, open loop ({preset}, {variant})")
        for h in SUMMARY_HEADER:
            table.add_column(h)
        for row in summary_rows(events_df):
            table.add_row(*row)
        Console().print(table)
    typer.echo(f"Report: {page}")
