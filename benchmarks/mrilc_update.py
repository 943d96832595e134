"""Time of one MRILC update (:meth:`shaper_nodes.core.learning.mrilc.learner.MrilcLearner.learn`) against a floor.

Data: one 10 s cycle at 1 kHz of 7 joints, each seed 000's loop (PID of eq. 13) around the
perturbed plant w = 5 rad/s, zeta = 0.15: the reference a ZVD-shaped unit step at 1 s and back
at 5 s, y and u simulated exactly (the sampled loop), u2 = 0 (the first iteration).

Methods:

``learn, law p``
    The paper's update: validation, y_m = G_m r_s (convolution with the sampled reference
    model's impulse response, by FFT), e, the RMS figures, the residual, the divergence guard
    and u2 + gamma e(k + 1).
``learn, law robust``
    The same with the minimax learning filter (zero-phase, applied by FFT).
``floor: fftconvolve``
    ``scipy.signal.fftconvolve`` of the same (10000, 7) array with a 10000-sample impulse
    response: the one convolution any reference-model comparison of the cycle must do, the
    baseline of the ratio.

Timing: the methods run round-robin ``repeats`` times; each one's best pass is reported, and
the median. The designs (discretisation, the check, the robust law's minimax) run once at
start-up and are timed once.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import control as ct
import numpy as np
from scipy.signal import fftconvolve

from shaper_nodes.core.learning.mrilc import MrilcLearner
from shaper_nodes.core.learning.mrilc import model as M


def run(*, rate: float = 1000.0, seconds: float = 10.0, joints: int = 7, repeats: int = 20,
        progress: Callable[[str], None] = lambda s: None) -> dict:
    period = 1.0 / rate
    designs, models = {}, {}
    for law in ("p", "robust"):
        begin = time.perf_counter()
        models[law] = M.MrilcModel(M.controller(), M.mck_plant(*M.PAPER_NOMINAL), M.paper_plant_set(), period,
                                   law=M.LawConfig(law=law), omega_min=2 * math.pi / seconds)
        designs[law] = time.perf_counter() - begin
    model = models["p"]
    n = int(round(seconds * rate))
    r = np.zeros(n)
    r[int(rate):int(5 * rate)] = 1.0
    mode = model.mode
    if mode is None:
        raise RuntimeError("the MRILC reference model has no lightly damped mode to shape")
    wd = mode.omega * math.sqrt(1 - mode.zeta**2)
    k = math.exp(-mode.zeta * math.pi / math.sqrt(1 - mode.zeta**2))
    r_s = sum(a * np.roll(r, int(round(t * rate))) for a, t in
              zip(np.array([1, 2 * k, k * k]) / (1 + k) ** 2, (0.0, math.pi / wd, 2 * math.pi / wd), strict=True))
    plant = M.mck_plant(5.0, 0.15)
    y = M.SampledFilter(M.zoh_sampled(M.learning_path(model.c, plant, "command"), period))(r_s)
    u = M.SampledFilter(M.zoh_sampled(ct.feedback(model.c, plant), period))(r_s)
    r_s, y, u = (np.repeat(x[:, None], joints, axis=1) for x in (r_s, y, u))
    h = model.reference_filter.impulse(n)

    timings: dict[str, list[float]] = {"learn, law p": [], "learn, law robust": [], "floor: fftconvolve": []}

    def learn(law: str) -> None:
        learner = MrilcLearner(models[law], joints)
        begin = time.perf_counter()
        learner.learn(r_s, y, u)
        timings[f"learn, law {law}"].append(time.perf_counter() - begin)

    def floor() -> None:
        begin = time.perf_counter()
        fftconvolve(r_s, h[:, None], axes=0)
        timings["floor: fftconvolve"].append(time.perf_counter() - begin)

    for warm_up in (lambda: learn("p"), lambda: learn("robust"), floor):  # caches: the impulse response, FFT plans
        warm_up()
    timings = {key: [] for key in timings}
    for i in range(repeats):
        progress(f"MRILC update: pass {i + 1}/{repeats}")
        learn("p")
        learn("robust")
        floor()
    best = {key: min(v) for key, v in timings.items()}
    return {"data": {"seconds": seconds, "rate_hz": rate, "joints": joints, "samples": n},
            "repeats": repeats, "design_s": designs,
            "methods": [{"method": key, "best_s": best[key], "median_s": float(np.median(v)),
                         "ratio_to_floor": best[key] / best["floor: fftconvolve"]} for key, v in timings.items()]}


def print_table(result: dict) -> None:
    d = result["data"]
    print(f"MRILC update: one {d['seconds']:g} s cycle at {d['rate_hz']:g} Hz, {d['joints']} joints"
          f" ({d['samples']} samples each), best of {result['repeats']}")
    head = f"  {'method':<30}{'best ms':>9}{'median ms':>11}{'vs floor':>10}"
    print(head)
    print("  " + "-" * (len(head) - 2))
    for m in result["methods"]:
        print(f"  {m['method']:<30}{1e3 * m['best_s']:>9.2f}{1e3 * m['median_s']:>11.2f}{m['ratio_to_floor']:>10.2f}")
    print("  design at start-up (discretisation, check; robust: minimax per frequency), once: "
          + ", ".join(f"{law} {1e3 * s:.0f} ms" for law, s in result["design_s"].items()))


if __name__ == "__main__":
    print_table(run())
