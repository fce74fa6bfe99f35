"""Write target.csv: the study's compaction curve as its text describes it (no data points are
published). Run from anywhere: ``python data-samples/paper-40-fit/make_target.py``.

- up to U = 0.55 mm the load stays within 2 % of its maximum: a straight line to 0.02 × 12 N;
- it then rises to 12 N at U = 1.15 mm: taken as a cubic in (U − 0.55 mm) (the shape is this
  file's assumption; only its end points are the study's);
- at U = 1.12 mm it dips by 9.8 % (one sample 9.8 % below the cubic).
"""

from pathlib import Path

import numpy as np

F_MAX_N, U_END_M, U_FLAT_M, DIP_U_M, DIP = 12.0, 1.15e-3, 0.55e-3, 1.12e-3, 0.098


def target() -> tuple[np.ndarray, np.ndarray]:
    U = np.unique(np.r_[np.arange(0.0, 1.10e-3 + 1e-12, 0.05e-3), [1.11e-3, DIP_U_M, 1.13e-3, 1.14e-3, U_END_M]].round(9))
    flat = 0.02 * F_MAX_N
    F = np.where(U <= U_FLAT_M, flat * U / U_FLAT_M,
                 flat + (F_MAX_N - flat) * ((U - U_FLAT_M) / (U_END_M - U_FLAT_M)) ** 3)
    F[np.isclose(U, DIP_U_M)] *= 1 - DIP
    return U, F


if __name__ == "__main__":
    U, F = target()
    out = Path(__file__).resolve().parent / "target.csv"
    out.write_text("U_m,load_N\n" + "".join(f"{u:.6g},{f:.6g}\n" for u, f in zip(U, F)))
    print(f"wrote {out}: {len(U)} samples, {F[-1]:.3g} N at U = {U[-1] * 1e3:.3g} mm")
