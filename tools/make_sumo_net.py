"""Generate the SUMO network shipped with ``safelane.integrations.sumo``: a straight two-lane road.

    python tools/make_sumo_net.py [--out src/safelane/integrations/data/straight2.net.xml] [--length 3000]

Needs ``netconvert`` (``pip install eclipse-sumo``, or a SUMO installation on ``PATH`` / under ``$SUMO_HOME/bin``);
the runner itself needs only libsumo. The road runs along +x from ``(0, 0)``; lane 0 (the ego's original lane, the
rightmost) has its centre at ``y = -1.5 w``, lane 1 (the target lane) at ``y = -0.5 w`` (SUMO's default
``spreadType="right"`` puts the lanes to the right of the edge's line), ``w = 3.5`` m as ``Params.lane_width``.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

DEFAULT_OUT = Path(__file__).resolve().parents[1] / "src" / "safelane" / "integrations" / "data" / "straight2.net.xml"


def find_netconvert() -> str:
    """The netconvert binary: ``$SUMO_HOME/bin``, the ``eclipse-sumo`` wheel, then ``PATH``."""
    candidates = []
    if os.environ.get("SUMO_HOME"):
        candidates.append(Path(os.environ["SUMO_HOME"]) / "bin" / "netconvert")
    try:
        import sumo  # the eclipse-sumo wheel

        candidates.append(Path(sumo.SUMO_HOME) / "bin" / "netconvert")
    except (ImportError, AttributeError):
        pass
    for cand in candidates:
        if cand.is_file():
            return str(cand)
    found = shutil.which("netconvert")
    if found:
        return found
    sys.exit("netconvert not found: pip install eclipse-sumo (or set SUMO_HOME to a SUMO installation)")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=DEFAULT_OUT)
    ap.add_argument("--length", type=float, default=3000.0, help="road length [m]")
    ap.add_argument("--lane-width", type=float, default=3.5, help="lane width [m] (Params.lane_width)")
    ap.add_argument("--speed", type=float, default=50.0, help="speed limit [m/s] (above every scenario's speeds)")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        nod, edg = Path(tmp) / "road.nod.xml", Path(tmp) / "road.edg.xml"
        nod.write_text(f'<nodes>\n    <node id="start" x="0" y="0"/>\n    <node id="end" x="{args.length:g}" y="0"/>\n'
                       "</nodes>\n")  # fmt: skip
        edg.write_text(f'<edges>\n    <edge id="road" from="start" to="end" numLanes="2" speed="{args.speed:g}" '
                       f'width="{args.lane_width:g}"/>\n</edges>\n')  # fmt: skip
        cmd = [find_netconvert(), "--node-files", str(nod), "--edge-files", str(edg), "--output-file", str(args.out),
               "--no-turnarounds", "true", "--offset.disable-normalization", "true", "--output.street-names", "false",
               "--no-warnings", "true"]  # fmt: skip
        args.out.parent.mkdir(parents=True, exist_ok=True)
        subprocess.run(cmd, check=True, cwd=tmp)
    # netconvert writes its own command line and the temporary input paths into a comment: drop it (reproducible).
    text = args.out.read_text()
    start, end = text.find("<!--"), text.find("-->")
    if 0 <= start < end:
        text = text[:start] + text[end + 3 :].lstrip("\n")
    args.out.write_text(text)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
