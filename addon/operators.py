"""Operators: compute (modal in the UI, synchronous from `execute`), clear, show."""

import bpy
from bpy.props import BoolProperty, EnumProperty

from . import console, core, jobs, pipeline, results


class CURVED_RADIOSITY_OT_compute(bpy.types.Operator):  # noqa: N801 (Blender requires PREFIX_OT_name)
    """Compute radiosity on curved patches for the current scene"""

    bl_idname = "curved_radiosity.compute"
    bl_label = "Compute Radiosity"
    bl_options = {"REGISTER", "UNDO"}

    relight: BoolProperty(
        name="Relight Only",
        description="Reuse the form factors of the last solution if only materials and lights changed",
        default=False,
    )

    _job = None
    _worker = None
    _timer = None

    def execute(self, context):
        """Run to completion on this thread (headless, scripts, F3 redo)."""
        wm = context.window_manager
        wm.progress_begin(0, 100)
        printer = console.ConsoleProgress() if bpy.app.background else None

        def progress(stage, fraction):
            wm.progress_update(int(100 * fraction))
            if printer is not None:
                printer(stage, fraction)

        try:
            job = pipeline.compute(context, relight=self.relight, progress=progress)
        except (pipeline.PipelineError, core.Cancelled) as error:
            self.report({"ERROR"}, str(error) or "cancelled")
            return {"CANCELLED"}
        finally:
            wm.progress_end()
            if printer is not None:
                printer.close()
        return self._done(context, job)

    def invoke(self, context, event):
        """In the UI: collect now, solve in a worker thread, poll it from timer events."""
        if bpy.app.background or context.window is None:
            return self.execute(context)
        try:
            job = pipeline.prepare(context, relight=self.relight)
        except pipeline.PipelineError as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        self._job = job
        self._worker = jobs.BackgroundSolve(
            lambda progress, cancel: pipeline.run(job, progress, cancel)
        ).start()
        wm = context.window_manager
        self._timer = wm.event_timer_add(0.1, window=context.window)
        wm.progress_begin(0, 100)
        wm.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        worker = self._worker
        if event.type == "ESC" and event.value == "PRESS":
            worker.cancel()
            worker.wait()
            self._stop(context)
            self.report({"WARNING"}, "Radiosity cancelled: scene unchanged")
            return {"CANCELLED"}
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        context.window_manager.progress_update(int(100 * worker.fraction))
        if context.workspace is not None:
            context.workspace.status_text_set(
                f"Radiosity: {worker.stage} {100 * worker.fraction:.0f}%   (Esc to cancel)"
            )
        if not worker.done:
            return {"RUNNING_MODAL"}
        self._stop(context)
        if worker.error is not None:
            cancelled = isinstance(worker.error, core.Cancelled)
            self.report(
                {"WARNING" if cancelled else "ERROR"},
                "Radiosity cancelled" if cancelled else str(worker.error),
            )
            return {"CANCELLED"}
        try:
            pipeline.finish(context, self._job)
        except pipeline.PipelineError as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        return self._done(context, self._job)

    def _stop(self, context):
        wm = context.window_manager
        wm.event_timer_remove(self._timer)
        wm.progress_end()
        if context.workspace is not None:
            context.workspace.status_text_set(None)

    def _done(self, context, job):
        text = pipeline.summary(job)
        props = getattr(context.scene, "curved_radiosity", None)
        if props is not None:
            props.last_report = text
        for warning in job.collected.warnings:
            self.report({"WARNING"}, warning)
        self.report({"INFO"}, text)
        return {"FINISHED"}


class CURVED_RADIOSITY_OT_clear(bpy.types.Operator):  # noqa: N801 (Blender requires PREFIX_OT_name)
    """Remove all radiosity results and restore the objects exactly as they were"""

    bl_idname = "curved_radiosity.clear"
    bl_label = "Clear Radiosity"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        count = results.clear(context.scene)
        props = getattr(context.scene, "curved_radiosity", None)
        if props is not None:
            props.last_report = ""
        self.report({"INFO"}, f"Radiosity cleared ({count} objects restored)")
        return {"FINISHED"}


class CURVED_RADIOSITY_OT_show(bpy.types.Operator):  # noqa: N801 (Blender requires PREFIX_OT_name)
    """Show the radiosity result, or the original materials, on result meshes"""

    bl_idname = "curved_radiosity.show"
    bl_label = "Show Radiosity"
    bl_options = {"REGISTER", "UNDO"}

    mode: EnumProperty(
        name="Show",
        items=[
            ("RESULT", "Result", "Emission-only view of the radiance"),
            ("ORIGINAL", "Original", "Materials"),
        ],
        default="RESULT",
    )

    def execute(self, context):
        results.show(self.mode)
        return {"FINISHED"}


CLASSES = (CURVED_RADIOSITY_OT_compute, CURVED_RADIOSITY_OT_clear, CURVED_RADIOSITY_OT_show)
