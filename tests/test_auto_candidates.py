"""``activebonds auto``'s search over candidate models (``auto/candidates/``) and its one rule
(``auto/judge.py``): a candidate defined here, registered from outside the package, runs
through ``auto.run``, is fitted, judged on the validation frames, shown in the table and kept
or not as the rule says; the rule itself on constructed scores; the package's modules small."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from activebonds import auto
from activebonds.auto.judge import Judged, better, compared
from activebonds.data.bundled import dataset
from activebonds.simulation import simulate_to_file

DAMPING = 20.0  # times the structure's fitted damping, held: a model that brakes the motion


class Damped:
    """The kept model with every damping raised :data:`DAMPING` times and held (the rest
    fitted again): it brakes a triangle that the truth lets swing, so it predicts the
    validation frames worse than the structure's fit."""

    def __init__(self, name: str = "damped", insist: bool = False):
        self.name, self.insist = name, insist

    def propose(self, ws, kept):
        from activebonds.identify.rundir import RunDir
        from activebonds.model import load_model, save_model

        spec = load_model(RunDir(kept.run).best_model_path).spec
        raised = [
            b.model_copy(update={"damping": DAMPING * float(b.damping.value)})
            if "damping" in type(b).model_fields and hasattr(b.damping, "value")
            else b
            for b in spec.bond
        ]
        path = ws.folder.path / f"{self.name}.toml"
        save_model(spec.model_copy(update={"bond": raised}), path)
        return auto.Proposal(
            run=f"run-{self.name}",
            model=path,
            settings=ws.one_step(),
            what=f"{kept.run.name}'s model, every damping {DAMPING:g} times, held",
            insist=self.insist,
        )


@pytest.fixture(scope="module")
def triangle(tmp_path_factory):
    """The triangle example simulated: 300 frames at 60 Hz (no gravity: a free body)."""
    path = tmp_path_factory.mktemp("candidates") / "triangle.csv"
    simulate_to_file(dataset("triangle.toml").path, 300, 60.0, path, None, 1, "euler")
    return path


OPTIONS = auto.Options(gravity=False, population=8, generations=5, ahead=5)


def test_a_candidate_registered_from_outside_is_fitted_judged_tabled_and_not_kept(
    triangle, tmp_path
):
    """The damped model is fitted (run-damped), judged on the validation frames 192:240 (the
    fitted frames' last 20 %), shown in the table beside the structure's fit, and not kept:
    as many markers worse than zero force or more, and a larger RMS 5 frames ahead."""
    said = []
    with auto.CANDIDATES.registered(Damped()):
        assert auto.CANDIDATES.names()[-1] == "damped"
        outcome = auto.run(triangle, tmp_path / "out", OPTIONS, say=said.append)
    assert "damped" not in auto.CANDIDATES.names()  # registered inside the block only
    state = outcome.state
    fit = state["steps"]["fit"]
    rows = {r["candidate"]: r for r in fit["candidates"]}
    assert list(rows) == ["structure", "damped"]  # no ground (no gravity), no noise, no flight
    assert state["validation_frames"] == [192, 240]
    assert (tmp_path / "out" / "run-damped" / "best_model.toml").is_file()
    plain, damped = rows["structure"], rows["damped"]
    for r in (plain, damped):
        assert r["frames"] == [192, 240] and r["horizon"] == 5 and r["markers"] == 3
        for key in ("one_step_mm", "zero_force_one_step_mm", "ahead_mm", "zero_force_ahead_mm"):
            assert isinstance(r[key], float) and r[key] > 0, (r["candidate"], key)
    # zero force is the same predictor on the same frames for both
    assert damped["zero_force_ahead_mm"] == pytest.approx(plain["zero_force_ahead_mm"])
    # the structure's fit of the truth's own family beats zero force at every marker; the
    # braked model does not predict better
    assert plain["worse"] == 0 and plain["ahead_mm"] < 0.5 * plain["zero_force_ahead_mm"]
    assert damped["ahead_mm"] > 2 * plain["ahead_mm"]
    assert fit["run"] == "run" and plain["kept"] and not damped["kept"]
    assert plain["why"] == "kept: the first" and damped["why"].startswith("not kept: ")
    # the judge's scores are those of evaluate on the validation frames
    j = auto.judge(_ws(outcome, triangle), tmp_path / "out" / "run-damped")
    assert j.ahead_mm == pytest.approx(damped["ahead_mm"]) and j.worse == damped["worse"]
    # one table, said after the fit step's line and in the report's "How this model was made"
    fit_line = next(i for i, line in enumerate(said) if line.startswith("[3/5] fit: kept run"))
    table = said[fit_line + 1 : fit_line + 5]
    assert table[0].strip().startswith("candidates on the validation frames 192:240")
    assert table[1].split()[:2] == ["candidate", "run"]
    assert table[2].split()[:2] == ["structure", "run"] and table[2].rstrip().endswith(
        "kept: the first"
    )
    assert table[3].split()[:2] == ["damped", "run-damped"]
    assert f"{damped['ahead_mm']:.4g}" in table[3] and "not kept" in table[3]
    report = (tmp_path / "out" / "report.html").read_text(encoding="utf-8")
    assert "run-damped" in report and "candidates on the validation frames" in report
    # evaluated: the kept run, from the fitted frames' first frame
    held = json.loads((tmp_path / "out" / "evaluation.json").read_text())["held_out"]
    assert held["frames"] == [240, 300]


def test_a_candidate_that_insists_is_kept_and_evaluated(triangle, tmp_path):
    """The same damped model, insisting (as --up/--gravity insist on the ground model): kept
    though the rule finds it worse, and it is the run evaluated on the held-out frames."""
    with auto.CANDIDATES.registered(Damped("insisted", insist=True)):
        outcome = auto.run(triangle, tmp_path / "out", OPTIONS, say=lambda line: None)
    fit = outcome.state["steps"]["fit"]
    rows = {r["candidate"]: r for r in fit["candidates"]}
    assert fit["run"] == "run-insisted" and rows["insisted"]["kept"]
    assert rows["insisted"]["why"].startswith("kept: --up or --gravity insists")
    assert not rows["structure"]["kept"] and "replaced by run-insisted" in rows["structure"]["why"]
    from activebonds.data import read_trajectory
    from activebonds.model import load_model
    from activebonds.report.evaluate import evaluate

    model = load_model(tmp_path / "out" / "run-insisted" / "best_model.toml")
    found = evaluate(model, read_trajectory(triangle), frames=(240, 300), horizon=5, origin=0)
    ahead = outcome.held_out.comparisons[1]
    assert ahead.model_mm == pytest.approx(found.comparisons[1].model_mm)


class Heavy(Damped):
    """The damped model with gravity, insisting (as --up/--gravity insist on gravity)."""

    def propose(self, ws, kept):
        from activebonds.model import load_model, save_model

        proposal = super().propose(ws, kept)
        spec = load_model(proposal.model).spec
        g = [0.0] * (spec.dimension - 1) + [-9.81]
        save_model(spec.model_copy(update={"gravity": g}), proposal.model)
        return proposal


class Plain:
    """The structure's model again, without gravity: better than the heavy one."""

    name = "plain"

    def propose(self, ws, kept):
        return auto.Proposal("run-plain", ws.folder.structure, ws.one_step(), "the structure")


@pytest.mark.slow  # a third auto run (37 s): with the slow tests, on every landing
def test_a_model_without_gravity_does_not_replace_one_gravity_was_insisted_on(triangle, tmp_path):
    """Once --up or --gravity has kept a model with gravity, a later candidate without gravity
    (the gait family has none) is not fitted, however it would score."""
    said = []
    with auto.CANDIDATES.registered(Heavy("heavy", insist=True)):
        with auto.CANDIDATES.registered(Plain()):
            outcome = auto.run(triangle, tmp_path / "out", OPTIONS, say=said.append)
    fit = outcome.state["steps"]["fit"]
    rows = {r["candidate"]: r for r in fit["candidates"]}
    assert fit["run"] == "run-heavy" and "plain" not in rows
    assert not (tmp_path / "out" / "run-plain").exists()
    assert any(line.strip().startswith("plain: not fitted: --up or --gravity insists")
               for line in said)  # fmt: skip


def _ws(outcome, recording_path):
    """A workspace enough for :func:`auto.judge` on ``outcome``'s folder."""
    from types import SimpleNamespace

    from activebonds.data import read_trajectory

    recording = read_trajectory(recording_path)
    split = auto.windows(recording.n_frames, OPTIONS.frames, OPTIONS.held_out)
    return SimpleNamespace(
        recording=recording, split=split, options=OPTIONS, noise=SimpleNamespace(window=0)
    )


def judged(worse: int, ahead: float, one: float = 1.0, noisy: bool = False) -> Judged:
    return Judged((80, 100), 10, one, 2.0, worse, 7, ahead, 20.0, noisy)


def test_the_rule_counts_markers_worse_than_zero_force_first_then_the_error_ahead():
    assert better(judged(0, 9.0), judged(1, 5.0))  # fewer worse markers wins over ahead
    assert not better(judged(2, 1.0), judged(1, 5.0))
    assert better(judged(1, 4.9), judged(1, 5.0))  # as many: the lower RMS ahead
    assert not better(judged(1, 5.0), judged(1, 5.0))  # a tie keeps the kept one
    assert better(judged(1, 5.0, one=9.0), judged(1, 5.1, one=0.1))  # not the one-step RMS
    assert not better(judged(0, math.nan), judged(0, 50.0))  # no finite score: not better
    assert better(judged(0, 50.0), judged(0, math.inf))
    assert not better(judged(0, math.nan), judged(0, math.nan))
    assert compared(judged(2, 1.0), judged(1, 5.0), "run") == (
        "2 marker(s) worse than zero force one step, run 1"
    )
    assert compared(judged(1, 4.9), judged(1, 5.0), "run-ground") == (
        "10 ahead 4.9 mm, run-ground 5 mm"
    )
    assert judged(0, math.nan).record()["ahead_mm"] is None  # JSON has no NaN


def test_where_the_noise_dominates_one_step_the_error_ahead_comes_first():
    """A recording whose one-step score is its marker noise's (auto smooths it for the
    structure): a marker is worse than zero force one step by its noise, so the lower RMS
    ahead decides; the count of worse markers only breaks a tie ahead."""
    assert better(judged(15, 8.5, noisy=True), judged(0, 9.3, noisy=True))
    assert not better(judged(0, 9.3, noisy=True), judged(15, 8.5, noisy=True))
    assert better(judged(0, 9.3, noisy=True), judged(15, 9.3, noisy=True))  # a tie ahead
    assert not better(judged(0, math.nan, noisy=True), judged(9, 50.0, noisy=True))
    assert compared(judged(15, 8.5, noisy=True), judged(0, 9.3, noisy=True), "run") == (
        "10 ahead 8.5 mm, run 9.3 mm"
    )
    assert not better(judged(15, 8.5), judged(0, 9.3))  # not noisy: the markers first


def test_the_validation_frames_are_the_structure_step_s_tail():
    """The last 20 % of the fitted frames (structure_choice.TRAIN), at least 10."""
    assert auto.windows(300, (0, None), 0.2).validation == (192, 240)
    assert auto.windows(600, (0, None), 0.5).validation == (240, 300)
    assert auto.windows(40, (0, None), 0.25).validation == (20, 30)  # 30 fitted: 10 frames
    assert auto.windows(1200, (100, 200), 0.2).validation == (164, 180)


AUTO = Path(auto.__file__).parent


@pytest.mark.parametrize(
    "path", sorted(AUTO.rglob("*.py")), ids=lambda p: p.relative_to(AUTO).as_posix()
)
def test_no_module_of_auto_is_over_300_lines(path):
    assert len(path.read_text().splitlines()) <= 300, path
