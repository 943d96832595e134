"""Print the docs/design/shaping.md table: V (%) of the discretised FIR, rounding vs splitting vs exact.

Run with ./run exec python scripts/discretisation_table.py
"""

from shaper_nodes.core.shaping import Mode, design, discretize, fir_impulses, percentage_vibration

for hz in (7.3, 12.0):
    m = Mode.from_hz(hz, 0.05)
    for fam in ("zv", "zvd", "ei"):
        s = design(fam, [m])
        cells = []
        for rate in (250.0, 500.0, 1000.0):
            v = [100 * float(percentage_vibration(*fir_impulses(discretize(s, rate, meth), rate), m.omega, m.zeta))
                 for meth in ("round", "split", "exact")]
            cells.append(f"{v[0]:.3f} / {v[1]:.4f} / {v[2]:.2g}")
        own = 100 * float(percentage_vibration(s.amplitudes, s.times, m.omega, m.zeta))
        print(f"| {hz:g} Hz | {fam} | {own:.3g} | " + " | ".join(cells) + " |")
