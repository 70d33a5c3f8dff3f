"""Convert the CommonRoad US-101 snippets of ../shared/realdata into the package's sample (lossless ``.npz``).

Usage: python tools/convert_realdata.py [SOURCE_DIR] (default: ../shared/realdata) → src/safelane/recorded/data/.
Needs commonroad-io (pip install "safelane[commonroad]"). tests/test_recorded_sample.py checks the result against
a fresh load of the XML.
"""

from __future__ import annotations

import sys
from pathlib import Path

from safelane.recorded.commonroad_reader import load_commonroad
from safelane.recorded.store import save_npz

ROOT = Path(__file__).resolve().parents[1]


def main(source: Path) -> None:
    out = ROOT / "src" / "safelane" / "recorded" / "data"
    out.mkdir(parents=True, exist_ok=True)
    for xml in sorted(source.glob("*.xml")):
        target = save_npz(load_commonroad(xml), out / f"{xml.stem}.npz")
        print(f"{xml.name} -> {target.relative_to(ROOT)} ({target.stat().st_size} bytes)")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT.parent / "shared" / "realdata")
