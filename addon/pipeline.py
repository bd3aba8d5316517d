"""The compute pipeline in three steps, so the middle one can run off Blender's main thread.

1. `prepare` (main thread, reads bpy): collect the scene into a `Job`;
2. `run` (any thread, no bpy): solve with the core, reporting progress and honouring cancel;
3. `finish` (main thread, writes bpy): replace previous results with the new ones.

Nothing in the scene changes before step 3, so an error or a cancel leaves it as it was.
"""

import time
from dataclasses import dataclass, field, replace

from . import bake, collect, core, outputs, results, solve

QUALITY_TOLERANCE = {"DRAFT": 1e-2, "NORMAL": 1e-3, "HIGH": 1e-4}
SOLVER_NAMES = {"pairs": "All Pairs", "hierarchical": "Hierarchical"}


class PipelineError(RuntimeError):
    """The scene cannot be computed; the message names the objects concerned."""


@dataclass
class Job:
    """Everything the solver needs, detached from bpy.

    Attributes
    ----------
    scene_name : str
    collected : Collected
    settings : solve.Settings
    relight : bool
    times : dict
        Seconds per pipeline stage ("collect", "solve", "write").
    solution : solve.Solution or None
    requests : bake.Requests
        Lightmaps and refined twins to make (`outputs`), filled by `run`.
    """

    scene_name: str
    collected: object
    settings: solve.Settings
    relight: bool = False
    times: dict = field(default_factory=dict)
    solution: object = None
    requests: object = field(default_factory=bake.Requests)


def settings_from_scene(scene):
    """`solve.Settings` from the scene's add-on settings (defaults if unregistered)."""
    props = getattr(scene, "curved_radiosity", None)
    if props is None:
        return solve.Settings()
    tol = props.tolerance if props.quality == "CUSTOM" else QUALITY_TOLERANCE[props.quality]
    return solve.Settings(
        tol=tol,
        occlusion=props.occlusion,
        max_bounces=props.max_bounces or None,
        method=props.method.lower(),
    )


def prepare(context, settings=None, relight=False):
    """Collect the scene of `context` into a Job.

    Raises
    ------
    PipelineError
        Nothing to light or no emitters (naming any objects that were skipped).
    """
    start = time.perf_counter()
    depsgraph = context.evaluated_depsgraph_get()
    collected = collect.collect(context.scene, context.view_layer, depsgraph)
    check_lit(collected)
    settings = settings or settings_from_scene(context.scene)
    try:
        requests = outputs.requests(context.scene, depsgraph, collected)
    except outputs.OutputError as error:
        raise PipelineError(f"cannot compute radiosity: {error}") from error
    settings = replace(settings, method=solve.chosen_method(settings.method, requests))
    job = Job(context.scene.name, collected, settings, relight, requests=requests)
    job.times["collect"] = time.perf_counter() - start
    return job


def check_lit(collected):
    """Raise PipelineError if `collected` has nothing to light or no emitters. Objects that
    cannot take part are skipped (warnings); the run is refused only when what remains cannot be
    lit, and the message then names the skipped objects too."""
    skipped = "".join(f"; {message}" for message in collected.skipped)
    if not collected.targets:
        raise PipelineError(
            "cannot compute radiosity: nothing to light: no visible mesh, curve, text, metaball or "
            "NURBS surface objects with faces" + skipped
        )
    if not collected.has_emitters():
        raise PipelineError(
            "cannot compute radiosity: no emitters: add a light with power, a material with "
            "emission to a rendered object, or a world background colour" + skipped
        )


def run(job, progress=None, cancel=None):
    """Solve the job (no bpy access; safe in a worker thread).

    Raises
    ------
    core.Cancelled
        If `cancel()` turned true.
    PipelineError
        If the core rejects an item (named in the message). Objects whose surfaces pass through
        themselves (or each other) are skipped instead, with warnings, and the rest solved again
        (once; `_skip_crossing`).
    """
    start = time.perf_counter()

    def solved():
        return solve.solve(job.collected, job.settings, progress, cancel, job.relight, job.scene_name)

    try:
        try:
            job.solution = solved()
        except core.CrossingSurfaceError as error:
            _skip_crossing(job, error)
            job.solution = solved()
    except ValueError as error:  # the core refused an item; the message names it
        raise PipelineError(f"cannot compute radiosity: {error}") from error
    job.times["solve"] = time.perf_counter() - start
    if job.requests:
        start = time.perf_counter()
        solution = job.solution
        bake.run(job.requests, solution.core, solution.handles, job.collected.surfaces, progress, cancel)
        job.times["bake"] = time.perf_counter() - start
    return job.solution


def _skip_crossing(job, error):
    """Leave out of `job` the objects `error` (core.CrossingSurfaceError) names, with warnings
    (`solve.skip_crossing`), and their lightmaps and refined twins."""
    job.collected = solve.skip_crossing(job.collected, error)
    check_lit(job.collected)
    kept = job.collected.targets
    job.requests.lightmaps = [r for r in job.requests.lightmaps if r.target in kept]
    job.requests.refined = [r for r in job.requests.refined if r.target in kept]


def finish(context, job):
    """Write the job's results into the scene (main thread)."""
    start = time.perf_counter()
    depsgraph = context.evaluated_depsgraph_get()
    try:
        results.write(context.scene, context.view_layer, depsgraph, job.collected, job.solution.radiance)
        outputs.write(context.scene, context.view_layer, job.requests)
    except results.ResultError as error:
        raise PipelineError(str(error)) from error
    job.times["write"] = time.perf_counter() - start
    return summary(job)


def compute(context, settings=None, relight=False, progress=None, cancel=None):
    """All three steps on the calling thread; returns the finished Job."""
    job = prepare(context, settings, relight)
    run(job, progress, cancel)
    finish(context, job)
    return job


def summary(job):
    """One line for the UI and the console."""
    n_surfaces = len(job.collected.surfaces)
    total = sum(job.times.values())
    mode = "relit" if job.solution is not None and job.solution.relit else "solved"
    return (
        f"Radiosity {mode}: {n_surfaces} surfaces, {len(job.collected.lights)} lights, "
        f"{len(job.collected.targets)} result meshes in {total:.2f} s ({SOLVER_NAMES[job.settings.method]})"
    )
