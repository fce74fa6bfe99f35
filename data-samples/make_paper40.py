"""Make the study-like 40-fiber specimen in data-samples/paper-40/ (committed with its outputs).

Run from the repository root: ``python data-samples/make_paper40.py``. Deterministic (seed 0).
40 quasi-parallel fibers, Ø 0.5 mm, 15 mm long, along z, in a 3 mm wide cassette (x from −1.5 to
1.5 mm) at v_f0 = 37.7 % (height ≈ 6.94 mm along y, from 0), as in the study. Writes ``fibers.h5``
(the reference mid-lines) and ``specimen.json`` (box and volume fraction).
"""

import json
from pathlib import Path

from fiberpipe.artifacts import write_fibers
from fiberpipe.model.specimen import cassette_specimen

OUT = Path(__file__).resolve().parent / "paper-40"


def main():
    OUT.mkdir(parents=True, exist_ok=True)
    fibers, info = cassette_specimen(seed=0)
    write_fibers(OUT / "fibers.h5", fibers)
    (OUT / "specimen.json").write_text(json.dumps(info, indent=2) + "\n")
    print(f"wrote {OUT}/fibers.h5 ({fibers.n_fibers} fibers), box {info}")


if __name__ == "__main__":
    main()
