"""Radiosity from the command line, with bpy and no UI.

From the repository root (Blender as a Python module):

    python -m addon.headless SCENE.blend [--out LIT.blend] [--render IMAGE.png] [options]

or inside a Blender binary:

    blender -b SCENE.blend --python addon/run_in_blender.py -- [--out LIT.blend] [--render IMAGE.png] [...]

Prints a progress bar and the time of each stage, writes the lit .blend (results as colour
attributes with the emission-only "Radiosity View" material) and renders a PNG with Cycles on
the CPU. The view material is emission only, so a few samples and no light bounces suffice.
"""

import argparse
import os
import sys
import time

import bpy

from . import operators, pipeline, register, solve


def parse_args(argv, scene_required=True):
    parser = argparse.ArgumentParser(prog="python -m addon.headless", description=__doc__.splitlines()[0])
    parser.add_argument("scene", nargs=None if scene_required else "?", help="the .blend file to light")
    parser.add_argument("--out", help="write the lit scene to this .blend")
    parser.add_argument("--render", help="render the lit scene with Cycles (CPU) to this PNG")
    parser.add_argument("--quality", choices=sorted(pipeline.QUALITY_TOLERANCE), help="tolerance preset")
    parser.add_argument("--tol", type=float, help="relative solver tolerance (overrides --quality)")
    parser.add_argument("--max-bounces", type=int, help="stop after this many bounces (0: until converged)")
    parser.add_argument("--no-occlusion", action="store_true", help="ignore shadows between surfaces")
    parser.add_argument("--samples", type=int, default=8, help="Cycles samples for --render (default 8)")
    parser.add_argument("--resolution", type=int, nargs=2, metavar=("W", "H"), help="render size in pixels")
    return parser.parse_args(argv)


def settings(args, scene):
    """Solver settings: the scene's own, overridden by the command line."""
    base = pipeline.settings_from_scene(scene)
    tol = args.tol or (pipeline.QUALITY_TOLERANCE[args.quality] if args.quality else base.tol)
    bounces = base.max_bounces if args.max_bounces is None else (args.max_bounces or None)
    return solve.Settings(tol=tol, occlusion=base.occlusion and not args.no_occlusion, max_bounces=bounces)


def render(scene, path, samples, resolution):
    """Render `scene` with Cycles on the CPU to a PNG."""
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = samples
    scene.cycles.use_denoising = False
    scene.cycles.max_bounces = 0
    if resolution:
        scene.render.resolution_x, scene.render.resolution_y = resolution
        scene.render.resolution_percentage = 100
    scene.render.image_settings.file_format = "PNG"
    scene.render.filepath = str(path)
    bpy.ops.render.render(write_still=True)


def main(argv=None, scene_loaded=False):
    """Run the pipeline; returns the process exit code (0 on success)."""
    args = parse_args(sys.argv[1:] if argv is None else argv, scene_required=not scene_loaded)
    times = {}
    start = time.perf_counter()
    if args.scene:
        bpy.ops.wm.open_mainfile(filepath=args.scene)
    if not hasattr(bpy.types.Scene, "curved_radiosity"):
        register()
    times["load"] = time.perf_counter() - start
    scene = bpy.context.scene
    if args.render and scene.camera is None:
        print("error: --render needs a scene camera", file=sys.stderr)
        return 2
    print(f"Radiosity for {bpy.data.filepath or 'the current scene'}")
    try:
        job = pipeline.compute(bpy.context, settings(args, scene), progress=operators.console_progress)
    except pipeline.PipelineError as error:
        print(f"\nerror: {error}", file=sys.stderr)
        return 1
    for warning in job.collected.warnings:
        print(f"warning: {warning}")
    times.update(job.times)
    for path in (args.out, args.render):
        if path:  # output folders are created as needed
            os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    if args.out:
        start = time.perf_counter()
        bpy.ops.wm.save_as_mainfile(filepath=os.path.abspath(args.out), copy=True)
        times["save"] = time.perf_counter() - start
    if args.render:
        start = time.perf_counter()
        render(scene, args.render, args.samples, args.resolution)
        times["render"] = time.perf_counter() - start
    print(pipeline.summary(job))
    print("stage times (s):  " + "  ".join(f"{k} {v:.3f}" for k, v in times.items()))
    if job.solution.stats:
        print("solver stats:     " + "  ".join(f"{k} {_fmt(v)}" for k, v in job.solution.stats.items()))
    return 0


def _fmt(value):
    return f"{value:.3f}" if isinstance(value, float) else str(value)


if __name__ == "__main__":
    sys.exit(main())
