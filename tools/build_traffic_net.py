"""Generate the traffic-level SUMO network of ``safelane.traffic``: a three-lane motorway with an on-ramp merge

(a parallel acceleration lane that ends: the mandatory lane change), written to ``safelane/integrations/data``.

    python tools/build_traffic_net.py [--out-dir src/safelane/integrations/data]

Writes ``merge3.net.xml`` (the 2.5 km network the sweeps run) and ``merge3_long.net.xml`` (the same merge with a
40 km downstream section, for ``benchmarks/bench_traffic.py`` to hold 5,000 vehicles at once). Needs
``netconvert`` (``pip install eclipse-sumo``, or a SUMO installation on ``PATH`` / under ``$SUMO_HOME/bin``); the
simulation itself needs only libsumo.

Geometry (x along the motorway, lanes to the right of the edge line ``y = 0``, SUMO's default spread, 3.5 m lanes):

* ``in``    A(0, 0) → B(1000, 0), 3 lanes, 33.33 m/s (120 km/h);
* ``ramp``  R(700, −60) → B, 1 lane, 22.22 m/s (80 km/h);
* ``merge`` B → C(1250, 0), 4 lanes: lane 0 is the acceleration lane (250 m) fed by the ramp, lanes 1–3 continue
  ``in``'s lanes 0–2; the acceleration lane has no successor — its vehicles must change left before C;
* ``out``   C → D(2500, 0) (D at 40 km for the long variant), 3 lanes.

Counted from the left, the mainline lanes keep their centres (``y = −1.75, −5.25, −8.75``) on every edge, and the
acceleration lane's centre is ``y = −12.25``.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from make_sumo_net import find_netconvert

DEFAULT_DIR = Path(__file__).resolve().parents[1] / "src" / "safelane" / "integrations" / "data"
MAIN_SPEED, RAMP_SPEED, WIDTH = 33.33, 22.22, 3.5


def plain_xml(end_x: float) -> tuple[str, str, str]:
    nodes = f"""<nodes>
    <node id="A" x="0" y="0"/>
    <node id="R" x="700" y="-60"/>
    <node id="B" x="1000" y="0" type="priority"/>
    <node id="C" x="1250" y="0" type="priority"/>
    <node id="D" x="{end_x:g}" y="0"/>
</nodes>
"""
    edges = f"""<edges>
    <edge id="in" from="A" to="B" numLanes="3" speed="{MAIN_SPEED}" width="{WIDTH}" priority="3"/>
    <edge id="ramp" from="R" to="B" numLanes="1" speed="{RAMP_SPEED}" width="{WIDTH}" priority="1"/>
    <edge id="merge" from="B" to="C" numLanes="4" speed="{MAIN_SPEED}" width="{WIDTH}" priority="3"/>
    <edge id="out" from="C" to="D" numLanes="3" speed="{MAIN_SPEED}" width="{WIDTH}" priority="3"/>
</edges>
"""
    connections = """<connections>
    <connection from="in" to="merge" fromLane="0" toLane="1"/>
    <connection from="in" to="merge" fromLane="1" toLane="2"/>
    <connection from="in" to="merge" fromLane="2" toLane="3"/>
    <connection from="ramp" to="merge" fromLane="0" toLane="0"/>
    <connection from="merge" to="out" fromLane="1" toLane="0"/>
    <connection from="merge" to="out" fromLane="2" toLane="1"/>
    <connection from="merge" to="out" fromLane="3" toLane="2"/>
</connections>
"""
    return nodes, edges, connections


def build(out: Path, end_x: float) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        files = [Path(tmp) / name for name in ("net.nod.xml", "net.edg.xml", "net.con.xml")]
        for path, text in zip(files, plain_xml(end_x), strict=True):
            path.write_text(text)
        cmd = [find_netconvert(), "--node-files", str(files[0]), "--edge-files", str(files[1]),
               "--connection-files", str(files[2]), "--output-file", str(out), "--no-turnarounds", "true",
               "--offset.disable-normalization", "true", "--output.street-names", "false", "--no-warnings", "true",
               "--junctions.corner-detail", "0", "--geometry.avoid-overlap", "false"]  # fmt: skip
        out.parent.mkdir(parents=True, exist_ok=True)
        subprocess.run(cmd, check=True, cwd=tmp)
    # netconvert writes its own command line and the temporary input paths into a comment: drop it (reproducible).
    text = out.read_text()
    start, end = text.find("<!--"), text.find("-->")
    if 0 <= start < end:
        text = text[:start] + text[end + 3 :].lstrip("\n")
    out.write_text(text)
    print(f"wrote {out}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out-dir", type=Path, default=DEFAULT_DIR)
    args = ap.parse_args(argv)
    build(args.out_dir / "merge3.net.xml", 2500.0)
    build(args.out_dir / "merge3_long.net.xml", 40000.0)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
