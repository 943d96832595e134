"""MRILC core (seed 000): reference model, convergence check, learning laws, the learner's guard;
the session's memory bound and implausible samples, and the state file checked fully."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from shaper_nodes.core.cycles import END, START
from shaper_nodes.core.learning.mrilc import model as M
from shaper_nodes.core.learning.mrilc.learner import HISTORY, MrilcLearner
from shaper_nodes.core.learning.mrilc.session import KEEP_BETWEEN, MrilcSession

RATE = 200.0
PERIOD = 1.0 / RATE


def _zvd_step_and_back(mode, samples: int) -> np.ndarray:
    """A unit step and back, shaped by the ZVD on ``mode`` (impulses split between samples)."""
    wd = mode.omega * math.sqrt(1 - mode.zeta**2)
    k = math.exp(-mode.zeta * math.pi / math.sqrt(1 - mode.zeta**2))
    amps = np.array([1, 2 * k, k * k]) / (1 + k) ** 2
    times = np.array([0, math.pi / wd, 2 * math.pi / wd])
    r = np.zeros(samples)
    r[: samples // 2] = 1.0
    out = np.zeros(samples)
    for a, t in zip(amps, times, strict=True):
        k0, f = int(t * RATE), t * RATE - int(t * RATE)
        out[k0:] += a * (1 - f) * r[: samples - k0]
        out[k0 + 1:] += a * f * r[: samples - k0 - 1]
    return out[:, None]


def _simulate(model, plant, learner, iterations: int, r_s) -> list:
    """The sampled loop (exact ZOH discretisation, as the sim plant integrates it) with u2 learned."""
    t_path = M.SampledFilter(M.zoh_sampled(M.learning_path(model.c, plant, "command"), PERIOD))
    h_path = M.SampledFilter(M.zoh_sampled(M.learning_path(model.c, plant, "effort"), PERIOD))
    u_r = M.SampledFilter(M.zoh_sampled(M.ct.feedback(model.c, plant), PERIOD))      # C / (1 + C P)
    u_u = M.SampledFilter(M.zoh_sampled(M.ct.feedback(1, model.c * plant), PERIOD))  # 1 / (1 + C P)
    out = []
    for _ in range(iterations):
        u2 = learner.profile_for(r_s.shape[0])
        y = t_path(r_s) + h_path(u2)
        out.append(learner.learn(r_s, y, effort=u_r(r_s) + u_u(u2)))
    return out


@pytest.fixture(scope="module")
def paper_model():
    return M.MrilcModel(M.controller(), M.mck_plant(*M.PAPER_NOMINAL), M.paper_plant_set(), PERIOD,
                        omega_min=2 * math.pi * 0.5)


def test_reference_model_mode_is_the_papers(paper_model):
    mode = paper_model.mode
    assert mode.omega == pytest.approx(81.7, abs=0.05)
    assert mode.zeta == pytest.approx(0.4154, abs=5e-5)
    assert len(M.modes(paper_model.g_m)) == 1  # one lightly damped mode, as the paper says


def test_paper_gain_passes_the_check_for_all_nine_plants(paper_model):
    report = paper_model.convergence
    assert report.ok and len(report.per_plant) == 10  # the nine and the nominal
    assert all(v < 1.0 for v in report.per_plant.values())
    paper_model.require_convergence()


def test_a_violating_gain_is_refused_naming_the_worst_plant(paper_model):
    bound = M.gain_bound(paper_model.paths_d, PERIOD, paper_model.omega_min)
    assert 10.0 < bound < 20.0
    model = M.MrilcModel(M.controller(), M.mck_plant(*M.PAPER_NOMINAL), M.paper_plant_set(), PERIOD,
                         law=M.LawConfig(gamma=1.5 * bound), omega_min=paper_model.omega_min)
    assert not model.convergence.ok
    with pytest.raises(M.MrilcError, match=r"w=5 zeta=0\.15 at [0-9.]+ rad/s.*largest P-type gamma"):
        model.require_convergence()


def test_command_injection_needs_a_much_smaller_gain_and_a_q_filter(paper_model):
    def model(**law):
        return M.MrilcModel(M.controller(), M.mck_plant(*M.PAPER_NOMINAL), M.paper_plant_set(), PERIOD,
                            injection="command", law=M.LawConfig(**law), omega_min=paper_model.omega_min)

    with pytest.raises(M.MrilcError, match="no P-type gamma passes without a Q filter"):
        model(gamma=10.0).require_convergence()
    assert model(gamma=0.5, q_cutoff_hz=5.0).convergence.ok
    assert not model(gamma=10.0, q_cutoff_hz=5.0).convergence.ok


def test_nominal_plant_follows_the_reference_model_exactly(paper_model):
    r_s = _zvd_step_and_back(paper_model.mode, 160)
    learner = MrilcLearner(paper_model, 1)
    update = _simulate(paper_model, M.mck_plant(*M.PAPER_NOMINAL), learner, 1, r_s)[0]
    assert update.rms_e < 1e-12


def test_p_type_on_the_perturbed_plant_reaches_two_percent_by_400(paper_model):
    r_s = _zvd_step_and_back(paper_model.mode, 160)
    rows = _simulate(paper_model, M.mck_plant(5.0, 0.15), MrilcLearner(paper_model, 1), 400, r_s)
    assert rows[399].rms_e <= 0.02 * rows[0].rms_e
    assert rows[-1].rms_u1 < rows[0].rms_u1 and rows[-1].rms_u2 > 0.1 * rows[-1].rms_u1  # u2 takes part of u1
    assert all(r.action == "learn" for r in rows)
    nominal = _simulate(paper_model, M.mck_plant(*M.PAPER_NOMINAL), MrilcLearner(paper_model, 1), 1, r_s)[0]
    assert abs(rows[-1].residual - nominal.residual) <= 0.2 * nominal.residual


def _iterations_to(rows, fraction):
    return next((r.iteration for r in rows if r.rms_e <= fraction * rows[0].rms_e), None)


def test_robust_law_converges_faster_on_every_plant(paper_model):
    robust = M.MrilcModel(M.controller(), M.mck_plant(*M.PAPER_NOMINAL), M.paper_plant_set(), PERIOD,
                          law=M.LawConfig(law="robust"), omega_min=paper_model.omega_min)
    assert robust.convergence.ok and robust.convergence.worst_value < paper_model.convergence.worst_value
    r_s = _zvd_step_and_back(paper_model.mode, 160)
    for name, plant in M.paper_plant_set().items():
        if name == "w=10 zeta=0.3":
            continue  # the nominal plant: e is 0 from the first iteration
        p_rows = _simulate(paper_model, plant, MrilcLearner(paper_model, 1), 250, r_s)
        r_rows = _simulate(robust, plant, MrilcLearner(robust, 1), 60, r_s)
        p_it, r_it = _iterations_to(p_rows, 0.02), _iterations_to(r_rows, 0.02)
        assert p_it is not None and r_it is not None, name
        assert r_it < p_it, (name, r_it, p_it)


def test_pd_and_q_filter_update_shapes(paper_model):
    law = M.LawConfig(law="pd", gamma=10.0, lam=2.0, q_cutoff_hz=30.0)
    f = M.design_learning_filter(law, PERIOD, [], 1.0)
    e = np.zeros((50, 2))
    e[10, 0] = 1.0
    out = f.update(np.zeros((50, 2)), e)
    assert out.shape == (50, 2) and np.all(out[:, 1] == 0)
    # zero-phase Q: the response is symmetric about the learned samples 9 and 10 (gamma z + lambda (z - 1))
    assert np.argmax(np.abs(out[:, 0])) in (9, 10)
    with pytest.raises(M.MrilcError, match="Nyquist"):
        M.design_learning_filter(M.LawConfig(q_cutoff_hz=RATE), PERIOD, [], 1.0)


@pytest.mark.parametrize("kwargs, match", [
    ({"law": "i"}, "law must be"), ({"gamma": -1.0}, "gamma"), ({"gamma": math.nan}, "gamma"),
    ({"law": "robust", "gain": 1.5}, "gain"), ({"gamma": 0.0}, "nothing would be learned")])
def test_invalid_laws_are_refused(kwargs, match):
    with pytest.raises(M.MrilcError, match=match):
        M.LawConfig(**kwargs)


def test_invalid_models_are_refused():
    with pytest.raises(M.MrilcError, match="proper"):
        M.controller([1.0, 2.0, 3.0], [1.0, 1.0])
    with pytest.raises(M.MrilcError, match="omega"):
        M.mck_plant(-1.0, 0.1)
    with pytest.raises(M.MrilcError, match="unstable"):
        M.reference_model(M.controller([-1000.0], [1.0]), M.mck_plant(10.0, 0.3))


def test_divergence_guard_rolls_back_to_the_best_profile(paper_model):
    learner = MrilcLearner(paper_model, 1, patience=3)
    r_s = _zvd_step_and_back(paper_model.mode, 40)
    y0 = paper_model.reference_response(r_s, rest=[0.0])
    actions, profiles = [], []
    for k in range(6):
        profiles.append(learner.profile_for(40).copy())
        y = y0 - 0.01 * (1 + k) ** 2  # an error that grows every cycle, whatever is learned
        actions.append(learner.learn(r_s, y).action)
    assert actions[:3] == ["learn"] * 3 and actions[3] == "rollback" and actions[4:] == ["hold", "hold"]
    assert np.array_equal(learner.profile, profiles[0])  # the first cycle had the smallest error
    learner.resume()
    assert learner.learn(r_s, y0).action == "learn"


def test_bad_cycles_are_refused_and_nothing_changes(paper_model):
    learner = MrilcLearner(paper_model, 1)
    r_s = _zvd_step_and_back(paper_model.mode, 40)
    y = paper_model.reference_response(r_s, rest=[0.0])
    bad = y.copy()
    bad[7] = np.nan
    with pytest.raises(M.MrilcError, match="non-finite value at sample 7"):
        learner.learn(r_s, bad)
    with pytest.raises(M.MrilcError, match="samples x 1 joints"):
        learner.learn(np.zeros((40, 2)), np.zeros((40, 2)))
    assert learner.iteration == 1 and learner.profile.size == 0
    learner.learn(r_s, y)
    with pytest.raises(M.MrilcError, match="task changed"):
        learner.learn(r_s[:30], y[:30])


def test_state_round_trip(paper_model):
    learner = MrilcLearner(paper_model, 1)
    r_s = _zvd_step_and_back(paper_model.mode, 40)
    learner.learn(r_s, 0.9 * paper_model.reference_response(r_s, rest=[0.0]))
    again = MrilcLearner.from_dict(paper_model, learner.to_dict())
    assert again.iteration == 2 and np.array_equal(again.profile, learner.profile)
    with pytest.raises(M.MrilcError, match="inconsistent"):
        MrilcLearner.from_dict(paper_model, {"joints": 1})


def test_session_builds_cycles_on_the_grid_and_skips_gaps(paper_model):
    session = MrilcSession(MrilcLearner(paper_model, 1), stale_after=0.05)
    r_s = _zvd_step_and_back(paper_model.mode, 40)
    y = paper_model.reference_response(r_s, rest=[0.0])
    t0 = 10.0

    def feed(skip=None):
        for k in range(40):
            if k != skip:
                session.on_joint_state(t0 + k * PERIOD, y[k], [0.0])
            session.on_reference(t0 + k * PERIOD, r_s[k])

    session.on_event(START, 0, t0)
    feed()
    done = session.on_event(END, 0, t0 + 39 * PERIOD)
    assert done.skipped == "" and done.update.rms_e < 1e-12
    t0 = 20.0
    session.on_event(START, 1, t0)
    feed(skip=17)
    done = session.on_event(END, 1, t0 + 39 * PERIOD)
    assert done.update is None and "1 of 40 joint state samples missing" in done.skipped
    session.profile_ready = False
    session.on_event(START, 2, 30.0)
    session.profile_ready = True
    assert "before the learner's profile was installed" in session.on_event(END, 2, 30.1).skipped


def test_model_from_params_builds_the_nodes_model_and_refuses_bad_values(paper_model):
    from shaper_nodes.core.learning.mrilc.params import DEFAULTS, model_from_params

    model, settings = model_from_params({"mrilc.check.min_frequency_hz": 0.5, "list.gain": 3})
    assert model.period == PERIOD and model.law == M.LawConfig()
    assert model.mode.omega == pytest.approx(paper_model.mode.omega, rel=1e-12)
    assert model.convergence.worst_value == pytest.approx(paper_model.convergence.worst_value, rel=1e-12)
    assert settings.patience == DEFAULTS["mrilc.patience"] and settings.joint_names == ()
    assert settings.topics["reference"] == "/sim_plant/reference"
    for params, message in (({"mrilc.gamma": -1.0}, r"mrilc\.gamma must be in \[0, 1e\+09\]"),
                            ({"mrilc.rate": float("nan")}, "mrilc.rate must be a finite number"),
                            ({"mrilc.q_order": 2.5}, "mrilc.q_order must be an integer"),
                            ({"mrilc.law": "pid"}, "mrilc.law must be one of p, pd, robust"),
                            ({"mrilc.check.omegas": []}, "mrilc.check.omegas must be a non-empty list"),
                            ({"mrilc.learn": "yes"}, "mrilc.learn must be true or false"),
                            ({"mrilc.rat": 100.0}, r"unknown MRILC parameter\(s\) mrilc\.rat"),
                            ({"mrilc.gamma": 25.0}, "learning refused.*largest P-type gamma")):
        with pytest.raises(M.MrilcError, match=message):
            model_from_params(params)
    assert not model_from_params({"mrilc.gamma": 25.0}, require_convergence=False)[0].convergence.ok


# --------------------------------------------------------------------------------------------
# Bounded memory, implausible samples, state files checked fully (issue 17)


def _cycle(session, cycle, t0, y, r_s, effort=None, blocks=False):
    """START, the samples of one cycle (one call a sample, or one block), END; the outcome."""
    session.on_event(START, cycle, t0)
    t = t0 + PERIOD * np.arange(y.shape[0])
    if blocks:
        session.on_joint_states(t, y, effort)
        session.on_references(t, r_s)
    else:
        for k in range(y.shape[0]):
            session.on_joint_state(t[k], y[k], None if effort is None else effort[k])
            session.on_reference(t[k], r_s[k])
    return session.on_event(END, cycle, t[-1])


def test_blocks_of_samples_give_the_same_update_as_samples_one_by_one(paper_model):
    r_s = _zvd_step_and_back(paper_model.mode, 40)
    y = 0.9 * paper_model.reference_response(r_s, rest=[0.0])
    a = _cycle(MrilcSession(MrilcLearner(paper_model, 1)), 0, 10.0, y, r_s, np.zeros((40, 1)))
    b = _cycle(MrilcSession(MrilcLearner(paper_model, 1)), 0, 10.0, y, r_s, np.zeros((40, 1)), blocks=True)
    assert a.update is not None and np.array_equal(a.update.next_profile, b.update.next_profile)
    assert a.update.rms_e == b.update.rms_e and a.update.rms_u1 == b.update.rms_u1


def test_without_a_start_nothing_grows(paper_model):
    session = MrilcSession(MrilcLearner(paper_model, 1))
    keep = int(2 * KEEP_BETWEEN * RATE) + 2  # within 2 KEEP_BETWEEN of the newest, per stream
    sizes = []
    for block in range(3600):  # an hour of joint states, reference and effort at 200 Hz, and no START
        t = block + PERIOD * np.arange(int(RATE))
        session.on_joint_states(t, np.zeros((t.size, 1)), np.zeros((t.size, 1)))
        session.on_references(t, np.zeros((t.size, 1)))
        sizes.append(session.buffered)
    assert max(sizes) <= 3 * keep and max(sizes[-600:]) == max(sizes[120:720])  # bounded, and flat
    assert session.buffered_bytes < 1_000_000  # three streams of 16 bytes a sample, 60 s at 200 Hz at most
    for k in range(2000):  # one sample at a time as well (the node's path)
        session.on_joint_state(3600.0 + k * PERIOD, [0.0], [0.0])
        session.on_reference(3600.0 + k * PERIOD, [0.0])
    assert session.buffered <= 3 * keep


def test_a_cycle_past_the_duration_limit_is_refused_and_its_samples_dropped_at_the_limit(paper_model):
    session = MrilcSession(MrilcLearner(paper_model, 1), max_cycle_duration=20.0)
    session.on_event(START, 0, 0.0)
    notices, peak = [], 0
    for k in range(int(60 * RATE)):
        t = k * PERIOD
        for notice in (session.on_joint_state(t, [0.0], [0.0]), session.on_reference(t, [0.0])):
            if notice:
                notices.append((t, notice))
        peak = max(peak, session.buffered)
    assert len(notices) == 1 and 20.0 < notices[0][0] <= 20.0 + 1.5 * PERIOD, notices
    assert "longer than max_cycle_duration 20 s" in notices[0][1]
    assert peak >= 3 * 20 * RATE  # the cycle's samples were kept up to the limit ...
    assert session.buffered <= 3 * (2 * KEEP_BETWEEN * RATE + 2)  # ... and dropped there
    done = session.on_event(END, 0, 60.0)
    assert done.update is None and done.refusal == "too_long" and "lasted 60.0 s" in done.skipped
    assert session.learner.iteration == 1 and session.learner.profile.size == 0


@pytest.mark.parametrize("stream, value, what", [
    ("y", 1e9, "joint state position"), ("y", -100.0, "joint state position"), ("r", 1e9, "reference position"),
    ("effort", 2e5, "effort")])
def test_an_implausible_sample_refuses_the_cycle_with_the_reason(paper_model, stream, value, what):
    session = MrilcSession(MrilcLearner(paper_model, 1))
    r_s = _zvd_step_and_back(paper_model.mode, 40)
    y = paper_model.reference_response(r_s, rest=[0.0])
    effort = np.zeros((40, 1))
    {"y": y, "r": r_s, "effort": effort}[stream][17, 0] = value
    done = _cycle(session, 0, 10.0, y, r_s, effort)
    assert done.update is None and done.refusal == "implausible", done
    assert f"1 of 40 {what} samples at or beyond the sensor's range" in done.skipped
    assert "first at sample 17" in done.skipped
    assert ("max_abs_effort" if stream == "effort" else "max_abs_position") in done.skipped
    assert session.learner.iteration == 1 and session.learner.profile.size == 0  # nothing learned


def test_the_history_is_bounded_and_the_state_stays_valid(paper_model):
    learner = MrilcLearner(paper_model, 1)
    r_s = _zvd_step_and_back(paper_model.mode, 20)
    y = 0.9 * paper_model.reference_response(r_s, rest=[0.0])
    for _ in range(HISTORY + 50):
        learner.learn(r_s, y, effort=np.zeros_like(y))
    assert len(learner.history) == HISTORY and learner.history[0][0] == 51
    again = MrilcLearner.from_dict(paper_model, json.loads(json.dumps(learner.to_dict())))
    assert again.to_dict() == learner.to_dict()
    assert again.iteration == HISTORY + 51 and np.array_equal(again.profile, learner.profile)


# --- the state file


def _state(paper_model, learned=True) -> dict:
    learner = MrilcLearner(paper_model, 1)
    r_s = _zvd_step_and_back(paper_model.mode, 40)
    if learned:
        for _ in range(3):
            learner.learn(r_s, 0.9 * paper_model.reference_response(r_s, rest=[0.0]))  # no effort: rms_u1 NaN
    return {"version": 1, "mode": "mrilc", "saved_at": 1.0, "joint_names": ["joint_1"], "sample_period": PERIOD,
            "injection": "effort", "learner": learner.to_dict()}


def _edited(paper_model, fn) -> str:
    doc = _state(paper_model)
    fn(doc)
    return json.dumps(doc)


def _set(path, value):
    def fn(doc):
        *keys, last = path
        for k in keys:
            doc = doc[k]
        doc[last] = value
    return fn


#: corrupt MRILC state files: (name, a function of the model giving the text, words of the problem)
MRILC_CORRUPT = [
    ("history entry [[]]", lambda m: _edited(m, _set(("learner", "history"), [[]])), "history entry 0"),
    ("history entry of the wrong length", lambda m: _edited(m, _set(("learner", "history", 0), [1, 0.1])),
     "history entry 0"),
    ("history entry with a text", lambda m: _edited(m, _set(("learner", "history", 0, 1), "0.1")),
     "history entry 0"),
    ("history not consecutive", lambda m: _edited(m, _set(("learner", "history", 1, 0), 7)), "consecutively"),
    ("NaN best profile", lambda m: _edited(m, _set(("learner", "best_profile", 3), [math.nan])), "non-finite"),
    ("infinite profile", lambda m: _edited(m, _set(("learner", "profile", 0), [math.inf])), "non-finite"),
    ("NaN best rms", lambda m: _edited(m, _set(("learner", "best_rms"), math.nan)), "best_rms must be finite"),
    ("best profile of another length", lambda m: _edited(m, _set(("learner", "best_profile"), [[0.0]] * 39)),
     "best_profile has shape"),
    ("ragged profile", lambda m: _edited(m, _set(("learner", "profile", 2), [0.0, 1.0])), "rows of 1 numbers"),
    ("profile of texts", lambda m: _edited(m, _set(("learner", "profile", 2), ["0.5"])), "numbers only"),
    ("profile a text", lambda m: _edited(m, _set(("learner", "profile"), "abc")), "rows of 1 numbers"),
    ("joints a text", lambda m: _edited(m, _set(("learner", "joints"), "1")), "joints must be an integer"),
    ("iteration a float", lambda m: _edited(m, _set(("learner", "iteration"), 4.0)), "iteration must be an integer"),
    ("holding a number", lambda m: _edited(m, _set(("learner", "holding"), 1)), "holding must be true or false"),
    ("an unknown learner entry", lambda m: _edited(m, _set(("learner", "extra"), 1)), "unknown ['extra']"),
    ("a missing learner entry", lambda m: _edited(m, lambda d: d["learner"].pop("grew")), "missing ['grew']"),
    ("history without a best profile", lambda m: _edited(m, _set(("learner", "best_profile"), None)),
     "exactly when there is history"),
    ("joint_names a text", lambda m: _edited(m, _set(("joint_names",), "joint_1")), "joint_names must be a list"),
    ("joints learned and named differ", lambda m: _edited(m, _set(("joint_names",), ["a", "b"])), "2 named"),
    ("another sample period", lambda m: _edited(m, _set(("sample_period",), 0.001)), "sample period of 0.001"),
    ("sample period a list", lambda m: _edited(m, _set(("sample_period",), [0.005])), "sample_period must be"),
    ("another injection", lambda m: _edited(m, _set(("injection",), "command")), "saved for injection 'command'"),
    ("nested 100k deep in the profile", lambda m: json.dumps(_state(m)).replace(
        '"profile": [', '"profile": [' + "[" * 100_000 + "]" * 100_000 + ", ", 1), "nested too deeply"),
    ("truncated JSON", lambda m: json.dumps(_state(m))[:200], "not valid JSON"),
    ("another mode", lambda m: _edited(m, _set(("mode",), "list")), "saved for mode 'list'"),
]


def _load(paper_model, path):
    from shaper_nodes.core.learning.mrilc import learner_from_state
    from shaper_nodes.core.learning.state_file import load_state

    return load_state(path, 1, lambda doc: learner_from_state(doc, paper_model, [], "effort"), "learner state",
                      {"mode": "mrilc"})


def test_a_saved_mrilc_state_with_unmeasured_effort_loads(paper_model, tmp_path):
    from shaper_nodes.core.learning.state_file import write_state

    path = tmp_path / "state.json"
    doc = _state(paper_model)
    assert math.isnan(doc["learner"]["history"][0][2])  # rms_u1 NaN: the effort was not measured
    write_state(path, doc)
    loaded = _load(paper_model, path)
    assert loaded.problem == "", loaded.problem
    learner, names = loaded.state
    assert names == ["joint_1"] and learner.iteration == 4
    assert json.dumps(learner.to_dict()) == json.dumps(doc["learner"])  # NaN compares equal as text
    write_state(path, _state(paper_model, learned=False))  # a fresh learner's state loads too
    assert _load(paper_model, path).problem == ""


@pytest.mark.parametrize("name, text, words", MRILC_CORRUPT, ids=[c[0] for c in MRILC_CORRUPT])
def test_a_corrupt_mrilc_state_is_reported_and_ignored_also_where_it_cannot_move(paper_model, tmp_path, name, text,
                                                                                 words):
    content = text(paper_model)
    path = tmp_path / "state.json"
    path.write_text(content)
    loaded = _load(paper_model, path)  # never raises
    assert loaded.state is None and words in loaded.problem, loaded.problem
    assert loaded.aside is not None and loaded.aside.read_text() == content
    # in a folder where it cannot be moved aside: reported at this start and the next, never raised
    folder = tmp_path / "read_only"
    folder.mkdir()
    (folder / "state.json.corrupt").mkdir()
    (folder / "state.json.corrupt" / "keep").write_text("")
    (folder / "state.json").write_text(content)
    folder.chmod(0o555)
    try:
        for _ in range(2):
            loaded = _load(paper_model, folder / "state.json")
            assert loaded.state is None and words in loaded.problem and "could not be moved aside" in loaded.problem
    finally:
        folder.chmod(0o755)


def test_a_sample_stamped_far_ahead_or_not_finite_does_not_wipe_the_streams(paper_model):
    session = MrilcSession(MrilcLearner(paper_model, 1))
    session.on_joint_state(1e6, [0.0])      # a garbage stamp, far in the future
    session.on_joint_state(math.nan, [0.0])  # and one that is not a number: dropped
    r_s = _zvd_step_and_back(paper_model.mode, 40)
    y = 0.9 * paper_model.reference_response(r_s, rest=[0.0])
    for k in range(int(100 * RATE)):  # 100 s of samples between cycles
        session.on_joint_state(k * PERIOD, [0.0])
        session.on_reference(k * PERIOD, [0.0])
    done = _cycle(session, 0, 100.0, y, r_s)
    assert done.update is not None, done.skipped  # the cycle's samples were kept
    assert session.y.dropped == 1
