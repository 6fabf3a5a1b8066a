"""What every step and candidate of ``activebonds auto`` works with: the output folder, the
recording (as recorded and as the structure sees it), the frames, the options, the marker
noise, where to say things, and the fits run into the folder."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from .folder import Folder, Options, Windows, fit_settings

WARNING = "uncertainty: warning: "


@dataclass
class Workspace:
    """One ``auto`` run's inputs and output folder. ``recording``: as recorded (what the
    fits and every score see); ``structural``: its fitted frames smoothed as ``noise`` says
    (what the structure is chosen on); ``state``: the folder's ``auto.json``, as it grows;
    ``notes``: what a step records beside its note (``steps.NAME.KEY``, :meth:`note`)."""

    folder: Folder
    recording_path: Path
    recording: object  # data.Trajectory
    structural: object  # data.Trajectory
    split: Windows
    options: Options
    noise: object  # data.smoothing.Noise
    say: Callable[[str], None]
    fit_progress: Callable | None
    state: dict
    scaffold: object = None  # the scaffold found before anything was written
    verbose: bool = True  # each fit's summary said; else one line and its warnings' count
    notes: dict[str, dict] = field(default_factory=dict)

    def settings(self):
        """The fit's settings (every fitted frame; the cost still to choose)."""
        return fit_settings(self.options, self.split)

    def one_step(self):
        """:meth:`settings` on the one-step cost (the cost the structure's exact optimum is
        the optimum of)."""
        return self.settings().model_copy(update={"cost": "restart", "horizon": (1,)})

    def note(self, step: str, key: str, value) -> None:
        """Record ``value`` as ``steps.STEP.KEY`` of ``auto.json`` once the step finishes."""
        self.notes.setdefault(step, {})[key] = value

    def step_record(self, step: str) -> dict:
        """What a finished step recorded in ``auto.json`` (empty where it has not run)."""
        return self.state["steps"].get(step, {})

    @property
    def kept_run(self) -> Path:
        """The fit step's kept run (``steps.fit.run``; ``OUT/run`` before it is known)."""
        return self.folder.path / self.step_record("fit").get("run", "run")

    def fit(self, run_name: str, model_path: Path, settings) -> float:
        """A fit of ``model_path`` in ``OUT/RUN_NAME``: resumed where it holds a checkpoint (a
        completed run resumes at once: its stages' records are kept, a missing one is run),
        else run anew; its summary lines said. Returns its best one-step RMS (mm)."""
        from contextlib import nullcontext

        from ..identify.driver import fit, resume
        from ..identify.rundir import RunDir

        run_path = self.folder.path / run_name
        run_dir = RunDir(run_path)
        progress = self.fit_progress or (lambda total, starting: nullcontext(None))
        status = run_dir.status().get("status") if run_dir.is_run() else None
        with progress(settings.generations, "compiling") as bar:
            hooks = {"progress": bar, "status": bar.status} if bar is not None else {}
            if status is not None and run_dir.newest_checkpoint() is not None:
                self.say(f"      resuming the fit in {run_path} ({status})")
                result = resume(run_path, **hooks)
            else:
                result = fit(
                    model_path, self.recording_path, settings, out=run_path, overwrite=True,
                    **hooks,
                )  # fmt: skip
        if result.status != "completed":
            raise RuntimeError(f"the fit ended {result.status}; see {run_path}")
        lines = printed_lines(result.lines())
        if not self.verbose:
            counted = [line for line in lines if line.startswith("uncertainty: ") and
                       "warning" in line and not line.startswith(WARNING)]  # fmt: skip
            lines = [f"{run_name}: one-step RMS {result.rms_mm:.4g} mm on the fitted frames "
                     "(--verbose: the fit's summary)", *counted]  # fmt: skip
        for line in lines:
            self.say(f"      {line}")
        return result.rms_mm


def printed_lines(lines: list[str]) -> list[str]:
    """A fit's summary as ``auto`` prints it: the uncertainty's warnings (long, some advising
    a refit ``auto`` decides itself) counted in one line, their words in the report."""
    warned = [line for line in lines if line.startswith(WARNING)]
    kept = [line for line in lines if not line.startswith(WARNING)]
    if warned:
        kept.append(
            f"uncertainty: {len(warned)} warning{'s' * (len(warned) > 1)} on these intervals, "
            "in the report's Uncertainty section"
        )
    return kept
